"""External plane-detection baselines for ``monoplane eval`` and ``monoplane bench``.

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

Baselines register through the pluggy hook ``monoplane_register_baselines`` (see
:mod:`monoplane.hookspecs`), like every other extension point: a plugin returns a dict from
method name (what users pass to ``--baseline``) to callable. This module is itself the
plugin of the built-in one. Use :func:`run_baseline` to run one by name::

    from monoplane.evaluation.baselines import run_baseline
    rec = run_baseline("open3d-ransac", frame, seed=0, options={"epsilon": 0.01})

Built-in baseline
-----------------
``open3d-ransac``: Open3D's ``PointCloud.segment_plane`` applied sequentially. The cloud is the
frame's valid pixels normalised into the unit sphere exactly as the pipeline does it
(:class:`~monoplane.geometry.cloud.PlaneCloud`), so the paper's ε = 0.02 means the same thing
for both. Each round takes the best plane of the remaining points and removes its inliers,
until the best plane has fewer inliers than the pipeline's minimum plane size (0.6 % of the
valid pixels, the paper's 300 px at 256×192) or 20 planes were found (the pipeline's limit).
Each round runs at most 1000 iterations (the pipeline's limit too) with Open3D's own early
termination at its default confidence; every valid pixel is used (no subsampling). These
shared values are read from :class:`~monoplane.ransac.RansacConfig`'s defaults. Normals are not
used (``segment_plane`` has no normal test) and there is no spatial coherence: that is what the
baseline stands for, plain sequential RANSAC from a widely used library.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any, TypeVar

import numpy as np
import pluggy

from monoplane.config import build_dataclass, parse_override
from monoplane.datamodel import Frame, Reconstruction
from monoplane.errors import ConfigError, PluginError
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.planes import fit_plane
from monoplane.hookspecs import hookimpl
from monoplane.ransac import RansacConfig

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
class Open3DRansacConfig:
    """Settings of the ``open3d-ransac`` baseline.

    Attributes
    ----------
    epsilon : float
        Inlier distance in unit-sphere units (paper: 0.02).
    num_iterations : int
        Maximum RANSAC iterations per plane.
    probability : float
        Confidence at which Open3D stops early (its default).
    max_planes : int
        Stop after this many planes (as the pipeline's ``ransac.max_planes``).
    min_support : float
        Stop when the best plane has fewer inliers than this fraction of the valid pixels (as
        the pipeline's ``ransac.min_support``: the paper's 300 px at 256×192).
    min_support_points : int
        ... and never accept a plane with fewer inliers than this.
    """

    epsilon: float = _RANSAC.epsilon
    num_iterations: int = _RANSAC.max_iterations
    probability: float = 0.99999999
    max_planes: int = _RANSAC.max_planes
    min_support: float = _RANSAC.min_support
    min_support_points: int = _RANSAC.min_support_points

    def __post_init__(self) -> None:
        if not self.epsilon > 0:
            raise ValueError(f"epsilon must be positive, got {self.epsilon}")
        if self.num_iterations < 1 or self.max_planes < 1:
            raise ValueError("num_iterations and max_planes must be at least 1")
        if not 0 < self.probability <= 1:
            raise ValueError(f"probability must lie in (0, 1], got {self.probability}")
        if not 0 <= self.min_support < 1 or self.min_support_points < 0:
            raise ValueError("min_support must lie in [0, 1) and min_support_points be >= 0")


def open3d_ransac(frame: Frame, *, seed: int = 0, **options: Any) -> Reconstruction:
    """Sequential Open3D ``segment_plane`` on the frame's normalised point cloud.

    Parameters
    ----------
    frame : Frame
        Frame with ``depth`` (normals, when present, only decide which pixels are valid).
    seed : int
        Seed of Open3D's global random generator. Open3D 0.19 runs the RANSAC iterations in
        parallel threads with early termination, so two runs with the same seed can still
        differ slightly on hard frames.
    **options
        Fields of :class:`Open3DRansacConfig` to override (defaults as documented in the
        module docstring), e.g. ``min_support=0.001``.

    Returns
    -------
    Reconstruction
        Labels 1..P in detection order; planes in the camera frame (OpenCV axes) and depth
        units; ``rmse`` in depth units; ``support`` = inlier count.

    Raises
    ------
    ConfigError
        On an unknown option or an ill-typed value (the message lists the valid options).
    """
    import open3d as o3d

    cfg = baseline_config(Open3DRansacConfig, options, "open3d-ransac")
    cloud = PlaneCloud.from_frame(frame)
    min_support = max(3, cfg.min_support_points,
                      int(np.ceil(cfg.min_support * cloud.all_points.shape[0])))
    o3d.utility.random.seed(int(seed))
    remaining = np.arange(cloud.all_points.shape[0])
    flat = np.zeros(frame.height * frame.width, dtype=np.int32)
    planes: list[np.ndarray] = []
    rmses: list[float] = []
    supports: list[int] = []
    call = 0.0
    while len(planes) < cfg.max_planes and remaining.size >= min_support:
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.all_points[remaining]))
        start = time.perf_counter()
        _, inliers = pcd.segment_plane(distance_threshold=cfg.epsilon, ransac_n=3,
                                       num_iterations=cfg.num_iterations,
                                       probability=cfg.probability)
        call += time.perf_counter() - start
        if len(inliers) < min_support:
            break
        chosen = remaining[np.asarray(inliers, dtype=np.int64)]
        # Report the least-squares plane of the inliers (as every method's planes are), in
        # the camera frame; the labels stay Open3D's.
        plane, rmse = fit_plane(cloud.all_points[chosen])
        planes.append(cloud.plane_to_camera(plane))
        rmses.append(rmse * cloud.scale)
        supports.append(chosen.size)
        flat[cloud.all_pixels[chosen]] = len(planes)
        remaining = np.setdiff1d(remaining, chosen, assume_unique=True)
    return Reconstruction(frame=frame, labels=flat.reshape(frame.shape),
                          params=np.asarray(planes, dtype=np.float64).reshape(-1, 4),
                          rmse=np.asarray(rmses, dtype=np.float64),
                          support=np.asarray(supports, dtype=np.int64),
                          config={"baseline": "open3d-ransac", **asdict(cfg)},
                          timings={CALL_TIMING: call})


# Lets the host check --baseline-set options before the first frame.
open3d_ransac.config_class = Open3DRansacConfig  # type: ignore[attr-defined]


@hookimpl
def monoplane_register_baselines() -> dict[str, Baseline]:
    """Register the built-in baseline."""
    return {"open3d-ransac": open3d_ransac}


def registered_baselines(pm: pluggy.PluginManager | None = None) -> dict[str, Baseline]:
    """Every baseline the plugin manager knows, by name.

    Parameters
    ----------
    pm : pluggy.PluginManager, optional
        Defaults to :func:`monoplane.plugin_manager.get_plugin_manager` (built-ins, plus
        installed plugins unless autoloading is disabled).

    Raises
    ------
    PluginError
        When a plugin returns something else than a name -> callable dict, or two plugins
        register the same name.
    """
    from monoplane.plugin_manager import get_plugin_manager

    pm = pm or get_plugin_manager()
    found: dict[str, Baseline] = {}
    for impl in pm.hook.monoplane_register_baselines.get_hookimpls():
        table = impl.function() or {}
        if not isinstance(table, dict):
            raise PluginError(f"plugin '{impl.plugin_name}': monoplane_register_baselines must "
                              f"return a dict of name -> callable, got {type(table).__name__}")
        for name, fn in table.items():
            if not callable(fn):
                raise PluginError(f"plugin '{impl.plugin_name}': baseline '{name}' is not "
                                  "callable")
            if name in found:
                raise PluginError(f"plugin '{impl.plugin_name}' registers baseline '{name}', "
                                  "which another plugin registered already")
            found[name] = fn
    return found


def baseline_names(pm: pluggy.PluginManager | None = None) -> list[str]:
    """Names of every available baseline, sorted."""
    return sorted(registered_baselines(pm))


def get_baseline(name: str, pm: pluggy.PluginManager | None = None) -> Baseline:
    """The baseline registered as ``name``.

    Raises
    ------
    ConfigError
        When no baseline has that name (the message lists the valid ones).
    """
    table = registered_baselines(pm)
    if name not in table:
        raise ConfigError(f"unknown baseline '{name}'; valid choices: "
                          f"{', '.join(sorted(table)) or '(none)'}")
    return table[name]


def parse_baseline_options(exprs: Sequence[str], names: Sequence[str]
                           ) -> dict[str, dict[str, Any]]:
    """Parse ``--baseline-set NAME.FIELD=VALUE`` expressions into options per baseline.

    Parameters
    ----------
    exprs : sequence of str
        Expressions; the value is read as a TOML value (``0.001``, ``true``, ``"text"``).
    names : sequence of str
        The baselines being run: every expression must name one of them.

    Returns
    -------
    dict
        Baseline name -> {field: value}; later expressions win.

    Raises
    ------
    ConfigError
        On a malformed expression or one naming a baseline that is not being run.
    """
    out: dict[str, dict[str, Any]] = {}
    for expr in exprs:
        try:
            name, key, value = parse_override(expr)
        except ConfigError:
            raise ConfigError(f"--baseline-set {expr!r} must look like NAME.FIELD=VALUE, e.g. "
                              "cgal.min_support=0.001") from None
        if name not in names:
            raise ConfigError(f"--baseline-set {expr!r}: '{name}' is not a baseline of this "
                              f"run; baselines run: {', '.join(names) or '(none)'}")
        out.setdefault(name, {})[key] = value
    return out


def bind_baseline(name: str, options: Mapping[str, Any] | None = None,
                  pm: pluggy.PluginManager | None = None) -> Baseline:
    """The baseline ``name`` with its keyword ``options`` fixed.

    When the baseline exposes its settings dataclass as ``config_class``, the options are
    checked now (:func:`baseline_config`), not on the first frame.

    Returns
    -------
    callable
        ``fn(frame, *, seed=0) -> Reconstruction``.

    Raises
    ------
    ConfigError
        Unknown baseline name, or (with ``config_class``) an unknown or ill-typed option.
    """
    fn = get_baseline(name, pm)
    if not options:
        return fn
    config_class = getattr(fn, "config_class", None)
    if config_class is not None:
        baseline_config(config_class, options, name)
    return functools.partial(fn, **options)


def run_baseline(name: str, frame: Frame, seed: int = 0,
                 pm: pluggy.PluginManager | None = None,
                 options: Mapping[str, Any] | None = None) -> Reconstruction:
    """Run the baseline ``name`` on a cue-filled frame.

    Parameters
    ----------
    options : mapping, optional
        Keyword options of the baseline (fields of its settings to override).

    Returns
    -------
    Reconstruction
        The baseline's planes; ``timings["total"]`` holds the wall time of the whole call and
        ``timings["baseline.call"]`` (when the baseline reports it) its core call alone.
    """
    fn = bind_baseline(name, options, pm)
    start = time.perf_counter()
    rec = fn(frame, seed=seed)
    rec.timings.setdefault("total", time.perf_counter() - start)
    return rec
