"""Every pluggy hook of monoplane, typed and documented.

A plugin is any module or object with functions marked ``@monoplane.hookimpl`` whose names
match the specs below. Built-in stages register through exactly these hooks (see
``monoplane.host.registry.DEFAULT_PLUGINS``); third-party packages are found through the
``monoplane`` entry-point group::

    [project.entry-points.monoplane]
    my_stages = "my_package.stages"

Registration hooks return a list of stage classes (subclasses of
:class:`monoplane.stages.base.Stage`); there is one per stage kind, generated from
:data:`monoplane.stages.base.KINDS` (``monoplane_register_samplers``, ...). Observation hooks
are called while a pipeline runs and must not change the data they see.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import pluggy

from monoplane.stages.base import KINDS, Stage, StageKind

if TYPE_CHECKING:
    from monoplane.datamodel import Reconstruction

PROJECT_NAME = "monoplane"

hookspec = pluggy.HookspecMarker(PROJECT_NAME)
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)


def _registration_spec(kind: StageKind) -> Callable[[], list[type[Stage]]]:
    """The registration hookspec of one stage kind, named ``kind.hook``."""

    def register() -> list[type[Stage]]:
        raise NotImplementedError  # a hookspec is never called; pluggy calls the impls

    register.__name__ = register.__qualname__ = kind.hook
    register.__module__ = __name__
    register.__doc__ = (f"{kind.summary}\n\nConfig table ``[{kind.name}]``. Contract: "
                        f":class:`{kind.base.__module__}.{kind.base.__qualname__}`.")
    return hookspec(register)


# One registration hook per stage kind, generated from the kinds list so that a new kind needs
# no spec of its own here (pluggy finds hookspecs by scanning this module's attributes).
for _kind in KINDS.values():
    globals()[_kind.hook] = _registration_spec(_kind)
del _kind


@hookspec
def monoplane_register_baselines() -> dict[str, Callable[..., Reconstruction]]:
    """External plane detectors to compare against, by method name (``--baseline NAME``).

    Each value is a callable ``baseline(frame, *, seed=0, **options) -> Reconstruction`` that
    takes a cue-filled frame and returns planes in its camera frame and depth units. It may
    record ``timings["baseline.call"]``: the seconds of its core call alone (data conversion
    excluded), which ``monoplane bench`` and ``monoplane eval`` compare against.

    The keyword ``options`` override fields of the baseline's settings (``monoplane eval
    --baseline-set NAME.FIELD=VALUE``); an unknown option or an ill-typed value raises a
    one-line :class:`~monoplane.errors.ConfigError` listing the valid ones
    (:func:`monoplane.evaluation.baselines.baseline_config` does this for a settings
    dataclass). A callable that exposes that dataclass as ``config_class`` has its options
    checked before the first frame. Used by :mod:`monoplane.evaluation.baselines`; names must be
    unique across plugins.
    """


@hookspec
def monoplane_stage_finished(kind: str, name: str, seconds: float, frame_name: str) -> None:
    """Observe a stage call finishing: its kind, plugin name, wall time and the frame name.

    Used by ``monoplane bench`` for per-stage timings; plugins may log or profile with it.
    """
