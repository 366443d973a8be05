"""What a baseline is, for the modules that provide one: the settings every RANSAC-type
baseline shares with the pipeline and the check of a baseline's keyword options.

A *baseline* is a callable ``baseline(frame, *, seed=0, **options) -> Reconstruction``: it
receives the same cue-filled :class:`~monoplane.datamodel.Frame` (depth, normals, intrinsics; OpenCV
camera axes) the pipeline presets get and returns planes in the frame's camera frame and depth
units. It may record in ``Reconstruction.timings["baseline.call"]`` the seconds of the method's
own call alone, without converting data in and out; ``eval`` and ``bench`` compare against that.

Keyword ``options`` override the fields of the baseline's settings (``monoplane eval
--baseline-set NAME.FIELD=VALUE``), so that a peer is compared at its tuned settings rather than
its defaults. An unknown option or an ill-typed value raises a one-line
:class:`~monoplane.errors.ConfigError` that lists the valid options; :func:`baseline_config`
does that for a settings dataclass. A baseline that exposes that dataclass as its
``config_class`` attribute gets its options checked before the first frame is run.

This module loads no plugin (:mod:`monoplane.evaluation.baselines`, the registry, does), so a
baseline plugin can import it while the registry loads that plugin.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

from monoplane.algorithm.ransac import RansacConfig
from monoplane.contracts.config_fields import build_dataclass
from monoplane.datamodel import Reconstruction
from monoplane.errors import ConfigError

#: Type of a baseline: a frame with cues in, planes out.
Baseline = Callable[..., Reconstruction]

#: Timing key a baseline records for its core call alone (data conversion excluded).
CALL_TIMING = "baseline.call"

_RANSAC = RansacConfig()

_Config = TypeVar("_Config")


def baseline_config(cls: type[_Config], options: Mapping[str, Any], name: str) -> _Config:
    """A baseline's settings: the dataclass ``cls``'s defaults overridden by ``options``.

    Parameters
    ----------
    cls : type
        Settings dataclass of the baseline (flat fields of bool, int, float or str).
    options : mapping
        Field name -> value, as passed to the baseline as keyword options. Integers are
        accepted for float fields; nothing else is converted.
    name : str
        Baseline name, for the error message.

    Raises
    ------
    ConfigError
        One line naming the unknown option or the ill-typed (or out-of-range) value and
        listing the valid options.
    """
    valid = sorted(f.name for f in dataclasses.fields(cls))  # type: ignore[arg-type]
    listing = ", ".join(valid)
    unknown = sorted(set(options) - set(valid))
    if unknown:
        raise ConfigError(f"baseline '{name}' has no option '{unknown[0]}'; valid options: "
                          f"{listing}")
    try:
        return build_dataclass(cls, dict(options), name)
    except ConfigError as exc:
        raise ConfigError(f"{exc}; valid options of baseline '{name}': {listing}") from None


@dataclass(frozen=True)
class RansacBaselineSettings:
    """Settings every RANSAC-type baseline shares with the pipeline, in unit-sphere units.

    The defaults are read from :class:`~monoplane.algorithm.ransac.RansacConfig`, so a
    baseline and the presets are compared at the same thresholds unless a user overrides them
    (``--baseline-set NAME.FIELD=VALUE``). Baselines subclass it with their own fields.

    Attributes
    ----------
    epsilon : float
        Inlier point-to-plane distance (paper's ε = 0.02).
    min_support : float
        Smallest plane as a fraction of the valid points (the pipeline's
        ``ransac.min_support``: the paper's 300 px at 256×192).
    min_support_points : int
        Smallest plane in points, whatever the fraction.
    """

    epsilon: float = _RANSAC.epsilon
    min_support: float = _RANSAC.min_support
    min_support_points: int = _RANSAC.min_support_points

    def __post_init__(self) -> None:
        if not self.epsilon > 0:
            raise ValueError(f"epsilon must be positive, got {self.epsilon}")
        if not 0 <= self.min_support < 1 or self.min_support_points < 0:
            raise ValueError("min_support must lie in [0, 1) and min_support_points be >= 0")
