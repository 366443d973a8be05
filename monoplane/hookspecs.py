"""Every pluggy hook of monoplane, typed and documented, one by one.

A plugin is any module or object with functions marked ``@monoplane.hookimpl`` whose names
match the specs below. Built-in stages register through exactly these hooks (see
``monoplane.host.registry.DEFAULT_PLUGINS``); third-party packages are found through the
``monoplane`` entry-point group::

    [project.entry-points.monoplane]
    my_stages = "my_package.stages"

Registration hooks return a list of stage classes; there is one per stage kind of
:data:`monoplane.contracts.KINDS`, named by its ``hook`` (``tests/test_plugin_manager.py``
checks that each kind has its spec here). Each class subclasses the kind's contract, has a
unique ``name`` (what a config's ``plugin = "..."`` selects) and a ``Config`` dataclass (the
kind's config table). Observation hooks are called while a pipeline runs and must not change
the data they see.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import pluggy

if TYPE_CHECKING:
    from monoplane.contracts import (
        Adjuster,
        CueProvider,
        FeatureMatcher,
        Fuser,
        Labeler,
        Matcher,
        Refiner,
        Registrar,
        Sampler,
        Scorer,
    )
    from monoplane.contracts.exporter import Exporter
    from monoplane.datamodel import Reconstruction

PROJECT_NAME = "monoplane"

hookspec = pluggy.HookspecMarker(PROJECT_NAME)
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)


# --- stage registration, one hook per stage kind, in pipeline order ---------------------------


@hookspec
def monoplane_register_cue_providers() -> list[type[CueProvider]]:
    """Cue providers: fill a frame's depth, normals and intrinsics.

    Config table ``[cues]``. Contract: :class:`monoplane.contracts.CueProvider` (or
    :class:`~monoplane.contracts.NetworkCues` for one that runs a cue network).
    """


@hookspec
def monoplane_register_samplers() -> list[type[Sampler]]:
    """Minimal-sample generators for plane RANSAC (3 point indices per sample).

    Config table ``[sampler]``. Contract: :class:`monoplane.contracts.Sampler`.
    """


@hookspec
def monoplane_register_scorers() -> list[type[Scorer]]:
    """Hypothesis scorers (lower cost is better), vectorised over many planes.

    Config table ``[scorer]``. Contract: :class:`monoplane.contracts.Scorer`.
    """


@hookspec
def monoplane_register_labelers() -> list[type[Labeler]]:
    """Binary inlier labelers for one plane hypothesis (threshold, graph cuts).

    Config table ``[labeler]``. Contract: :class:`monoplane.contracts.Labeler`.
    """


@hookspec
def monoplane_register_refiners() -> list[type[Refiner]]:
    """Refiners of the multi-plane labelling (dense CRF on images, graph CRF).

    Config table ``[refiner]``. Contract: :class:`monoplane.contracts.Refiner`.
    """


@hookspec
def monoplane_register_feature_matchers() -> list[type[FeatureMatcher]]:
    """Feature matchers: keypoints and correspondences between images (local features or
    pairwise networks).

    Config table ``[features]``. Contract: :class:`monoplane.contracts.FeatureMatcher`.
    """


@hookspec
def monoplane_register_matchers() -> list[type[Matcher]]:
    """Multi-view matchers giving cameras, sparse points and keypoint matches (SfM).

    Config table ``[matcher]``. Contract: :class:`monoplane.contracts.Matcher`.
    """


@hookspec
def monoplane_register_registrars() -> list[type[Registrar]]:
    """Registrars placing the views the matcher left out (from planes, normals, depth,
    matches).

    Config table ``[registrar]``. Contract: :class:`monoplane.contracts.Registrar`.
    """


@hookspec
def monoplane_register_fusers() -> list[type[Fuser]]:
    """Fusers of per-view planes into a global planar scene.

    Config table ``[fuser]``. Contract: :class:`monoplane.contracts.Fuser`.
    """


@hookspec
def monoplane_register_adjusters() -> list[type[Adjuster]]:
    """Joint refiners of a fused scene's cameras, per-view depth scales and global planes.

    Config table ``[adjuster]``. Contract: :class:`monoplane.contracts.Adjuster`.
    """


# --- baselines for ``monoplane eval`` and ``monoplane bench`` ---------------------------------


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
    checked before the first frame. Used by :mod:`monoplane.evaluation.baselines`, which also
    registers the built-in ``open3d-ransac``; names must be unique across plugins.
    """


# --- observation ------------------------------------------------------------------------------


@hookspec
def monoplane_stage_finished(kind: str, name: str, seconds: float, frame_name: str) -> None:
    """Observe a stage call finishing: its kind, plugin name, wall time and the frame name.

    Used by ``monoplane bench`` for per-stage timings; plugins may log or profile with it.
    """


# --- output formats -------------------------------------------------------------------------


@hookspec
def monoplane_register_exporters() -> list[Exporter]:
    """Output formats: what :func:`monoplane.export.save` (and so ``monoplane run``, ``batch``,
    ``cloud`` and ``multiview``) can write into a result's folder.

    Return a list of :class:`monoplane.plugin.Exporter`, one per format, each stating:

    * ``name``: unique across plugins, lower-case words joined by ``-``; ``monoplane plugins``
      lists it and ``save(..., formats=[...])`` selects by it;
    * ``files``: per result kind it applies to (``"frame"``: a
      :class:`~monoplane.datamodel.Reconstruction`; ``"cloud"``: a
      :class:`~monoplane.datamodel.CloudResult`; ``"multiview"``: a
      :class:`~monoplane.multiview.MultiviewResult`), the paths it writes, relative to the
      folder. ``monoplane batch`` derives its completeness check from the ``"frame"`` files of
      the formats on by default, so they must be exactly what ``write`` writes;
    * ``write(result, folder, shared)``: writes those files into ``folder``, an existing
      temporary folder that becomes the output only when every format has succeeded (raise to
      abandon it). It tells result kinds apart by ``result.result_kind``, never by type.
      ``shared`` (:class:`monoplane.export.shared.SharedWork`) hands out what several formats
      need, e.g. ``shared.mesh(result)``, the plane meshes, computed once. The views of a
      multi-view result are written with the ``"frame"`` formats into their own folders
      (``view_000``, ...) before the ``"multiview"`` formats run;
    * ``default``: written unless the caller names the formats it wants;
    * ``summary``: one line for ``monoplane plugins``.

    The built-in formats (``labels``, ``ply``, ``gltf``, ``depth``, ``config``, ``rerun``) are
    modules of :mod:`monoplane.export` registered through this hook, as a third-party package's
    are through the ``monoplane`` entry-point group. A malformed statement or a name registered
    twice raises :class:`~monoplane.errors.PluginError` naming the plugin.
    """
