"""The public API for plugin authors: everything a stage, cue network or baseline needs.

Third-party packages import from this module only::

    from monoplane.plugin import Sampler, hookimpl, param

so that monoplane can move its internals without breaking them: a name listed in ``__all__``
keeps working from here whatever module defines it (``CHANGELOG.md`` lists any move behind
it). ``tests/test_layers.py`` checks that the packages in ``plugins/`` import nothing else of
monoplane's (their tests may also use :mod:`monoplane.testing`, the pytest plugin).

What it holds, by use:

* Hooks: :data:`hookimpl`; every hook is documented in :mod:`monoplane.hookspecs`.
* Stage contracts: :class:`Stage` and the base class of each kind (:data:`KINDS` lists them
  with their registration hooks), :class:`NetworkCues` for cue providers that run a
  :class:`CueNetwork`, :func:`param` for config fields, :class:`RansacParams` (the shared
  thresholds, and their defaults), :class:`Labeling`, :class:`LabelingContext`,
  :class:`ProximityAffinities`.
* Data: :class:`Frame`, :class:`Reconstruction`, :class:`Camera`, :class:`Scene`,
  :class:`SfmResult`, :func:`default_intrinsics`; the RANSAC stages' :class:`PlaneCloud` and
  :class:`NeighbourGraph`, the registrar's :class:`ScaleAlignment`, :func:`fit_plane`.
* Cue networks: :class:`CueNetwork`, :class:`ModelSpec`, :class:`OnnxProfile`,
  :data:`IMAGENET_MEAN`, :data:`IMAGENET_STD`, :func:`plan_letterbox`.
* Baselines: :data:`Baseline`, :func:`baseline_config`, :class:`RansacBaselineSettings`,
  :data:`CALL_TIMING`; by name, :func:`baseline_names`, :func:`get_baseline`,
  :func:`run_baseline`.
* Registry: :func:`get_plugin_manager`, :func:`get_registry` (e.g. to check in a test that a
  stage registers).
* Output formats: :class:`Exporter`, returned by the ``monoplane_register_exporters`` hook
  (a frame's, a cloud's or a multi-view result's files; see docs/plugins.md); results are a
  :class:`Reconstruction`, a :class:`CloudResult` or a multi-view result, told apart by their
  ``result_kind``.
* Errors: :class:`ConfigError`, :class:`InvalidInput`, :class:`MonoplaneError`,
  :class:`PluginError`, :class:`StageError`.
"""

from __future__ import annotations

from monoplane.contracts import (
    KINDS,
    STAGE_KINDS,
    Adjuster,
    BinnedPoints,
    CueProvider,
    FeatureMatcher,
    Fuser,
    Labeler,
    Labeling,
    LabelingContext,
    Matcher,
    NetworkCues,
    NoConfig,
    ProximityAffinities,
    RansacParams,
    Refiner,
    Registrar,
    Sampler,
    Scorer,
    Stage,
    StageKind,
    TripletDraws,
    param,
)
from monoplane.contracts.exporter import Exporter
from monoplane.cues import (
    IMAGENET_MEAN,
    IMAGENET_STD,
    CueNetwork,
    ModelSpec,
    OnnxProfile,
    plan_letterbox,
)
from monoplane.datamodel import (
    Camera,
    CloudResult,
    Frame,
    Reconstruction,
    Scene,
    SfmResult,
    default_intrinsics,
)
from monoplane.errors import ConfigError, InvalidInput, MonoplaneError, PluginError, StageError
from monoplane.evaluation.baselines import (
    CALL_TIMING,
    Baseline,
    RansacBaselineSettings,
    baseline_config,
    baseline_names,
    get_baseline,
    run_baseline,
)
from monoplane.features import Correspondences, Keypoints, PairMatches
from monoplane.geometry.alignment import ScaleAlignment
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.graph import NeighbourGraph
from monoplane.geometry.planes import fit_plane
from monoplane.hookspecs import hookimpl
from monoplane.host.registry import get_plugin_manager, get_registry

__all__ = [
    "CALL_TIMING", "IMAGENET_MEAN", "IMAGENET_STD", "KINDS", "STAGE_KINDS", "Adjuster",
    "Baseline", "BinnedPoints", "Camera", "ConfigError", "Correspondences", "CueNetwork",
    "CueProvider", "FeatureMatcher", "Frame", "Fuser", "Keypoints", "InvalidInput", "Labeler",
    "Labeling", "LabelingContext", "Matcher", "ModelSpec", "MonoplaneError", "NeighbourGraph",
    "NetworkCues", "NoConfig", "OnnxProfile", "PairMatches", "PlaneCloud", "PluginError",
    "ProximityAffinities", "RansacBaselineSettings", "RansacParams", "Reconstruction",
    "Refiner", "Registrar", "Sampler", "ScaleAlignment", "Scene", "Scorer", "SfmResult",
    "Stage", "StageError", "StageKind", "TripletDraws", "baseline_config", "baseline_names",
    "default_intrinsics", "fit_plane", "get_baseline", "get_plugin_manager", "get_registry",
    "hookimpl", "param", "plan_letterbox", "run_baseline",
    "CloudResult", "Exporter",
]
