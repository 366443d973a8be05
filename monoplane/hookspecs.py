"""Every pluggy hook of monoplane, typed and documented.

A plugin is any module or object with functions marked ``@monoplane.hookimpl`` whose names
match the specs below. Built-in stages register through exactly these hooks (see
``monoplane.plugin_manager.DEFAULT_PLUGINS``); third-party packages are found through the
``monoplane`` entry-point group::

    [project.entry-points.monoplane]
    my_stages = "my_package.stages"

Registration hooks return a list of stage classes (subclasses of
:class:`monoplane.stages.base.Stage`). Observation hooks are called while a pipeline runs and
must not change the data they see.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:
    from collections.abc import Callable

    from monoplane.datamodel import Reconstruction
    from monoplane.stages.base import Stage

PROJECT_NAME = "monoplane"

hookspec = pluggy.HookspecMarker(PROJECT_NAME)
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)


@hookspec
def monoplane_register_cue_providers() -> list[type[Stage]]:
    """Cue providers: fill a :class:`~monoplane.datamodel.Frame`'s depth, normals and intrinsics.

    Config table ``[cues]``. Contract: :class:`monoplane.stages.base.CueProvider`.
    """


@hookspec
def monoplane_register_samplers() -> list[type[Stage]]:
    """Minimal-sample generators for plane RANSAC (3 point indices per sample).

    Config table ``[sampler]``. Contract: :class:`monoplane.stages.base.Sampler`.
    """


@hookspec
def monoplane_register_scorers() -> list[type[Stage]]:
    """Hypothesis scorers (lower cost is better), vectorised over many planes.

    Config table ``[scorer]``. Contract: :class:`monoplane.stages.base.Scorer`.
    """


@hookspec
def monoplane_register_labelers() -> list[type[Stage]]:
    """Binary inlier labelers for one plane hypothesis (threshold, graph cuts).

    Config table ``[labeler]``. Contract: :class:`monoplane.stages.base.Labeler`.
    """


@hookspec
def monoplane_register_refiners() -> list[type[Stage]]:
    """Image-level refiners of the multi-plane label map (e.g. dense CRF).

    Config table ``[refiner]``. Contract: :class:`monoplane.stages.base.Refiner`.
    """


@hookspec
def monoplane_register_matchers() -> list[type[Stage]]:
    """Multi-view matchers giving cameras, sparse points and keypoint matches (SfM).

    Config table ``[matcher]``. Contract: :class:`monoplane.stages.base.Matcher`.
    """


@hookspec
def monoplane_register_registrars() -> list[type[Stage]]:
    """Registrars placing the views the matcher left out (from planes, normals, depth, matches).

    Config table ``[registrar]``. Contract: :class:`monoplane.stages.base.Registrar`.
    """


@hookspec
def monoplane_register_fusers() -> list[type[Stage]]:
    """Fusers of per-view planes into a global planar :class:`~monoplane.datamodel.Scene`.

    Config table ``[fuser]``. Contract: :class:`monoplane.stages.base.Fuser`.
    """


@hookspec
def monoplane_register_adjusters() -> list[type[Stage]]:
    """Joint refiners of a fused scene's cameras, per-view depth scales and global planes.

    Config table ``[adjuster]``. Contract: :class:`monoplane.stages.base.Adjuster`.
    """


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
