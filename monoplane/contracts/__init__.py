"""Stage contracts: one small base class per stage kind.

A stage is a class with

* ``kind``: which slot of the pipeline it fills (one of :data:`STAGE_KINDS`), set by the base
  class of its kind;
* ``name``: the plugin name users write in configs (``plugin = "msac-normal"``);
* ``Config``: a dataclass of its parameters, each with a default and a ``doc`` in its field
  metadata (use :func:`param`);
* one method that takes and returns typed data objects.

Stages never import one another; they only see the objects the driver hands them. The RANSAC
stages (sampler, scorer, labeler) work on a :class:`~monoplane.geometry.cloud.PlaneCloud`, an
oriented point cloud normalised into the unit sphere, so thresholds are in unit-sphere units as
in the paper.

:data:`KINDS` is the one list of stage kinds: the registration hooks
(:mod:`monoplane.hookspecs`), the registry, the config tables and the plugin guide's tables all
derive from it, so a new kind is one base class and one entry there.

The contracts live in :mod:`monoplane.contracts.stage` (:class:`Stage`, :func:`param`),
:mod:`monoplane.contracts.frame_stages` (cue provider, sampler, scorer, labeler, refiner) and
:mod:`monoplane.contracts.scene_stages` (features, matcher, registrar, fuser, adjuster); every
name is importable from here, which is where plugins import them from (or
:mod:`monoplane.plugin`).
"""

from __future__ import annotations

from dataclasses import dataclass

from monoplane.contracts.frame_stages import (  # noqa: F401
    SAMPLER_DRAWS,
    SCORER_COSTS,
    BinnedPoints,
    CueProvider,
    Labeler,
    Labeling,
    LabelingContext,
    NetworkCues,
    ProximityAffinities,
    RansacParams,
    Refiner,
    Sampler,
    Scorer,
    TripletDraws,
)
from monoplane.contracts.frame_work import WorkAhead  # noqa: F401
from monoplane.contracts.scene_stages import (  # noqa: F401
    Adjuster,
    FeatureMatcher,
    Fuser,
    Matcher,
    Registrar,
)

# Every contract, importable from here as before the contracts were split by kind.
from monoplane.contracts.stage import (  # noqa: F401
    NoConfig,
    Stage,
    config_key,
    param,
    run_stage,
)


@dataclass(frozen=True)
class StageKind:
    """One stage kind: its base class and the pluggy hook that registers its stages.

    Attributes
    ----------
    base : type
        The contract every stage of the kind subclasses; its ``kind`` attribute is the kind's
        name and config table.
    hook : str
        Name of the registration hook (its spec is written out in :mod:`monoplane.hookspecs`).
    summary : str
        What the hook registers, one sentence (the hook's docstring and the plugin guide).
    """

    base: type[Stage]
    hook: str
    summary: str

    @property
    def name(self) -> str:
        """The kind's name, which is also its config table (``"sampler"``)."""
        return self.base.kind


#: Every stage kind in pipeline order, by name: the single source of the kinds.
KINDS: dict[str, StageKind] = {k.name: k for k in (
    StageKind(CueProvider, "monoplane_register_cue_providers",
              "Cue providers: fill a frame's depth, normals and intrinsics."),
    StageKind(Sampler, "monoplane_register_samplers",
              "Minimal-sample generators for plane RANSAC (3 point indices per sample)."),
    StageKind(Scorer, "monoplane_register_scorers",
              "Hypothesis scorers (lower cost is better), vectorised over many planes."),
    StageKind(Labeler, "monoplane_register_labelers",
              "Binary inlier labelers for one plane hypothesis (threshold, graph cuts)."),
    StageKind(Refiner, "monoplane_register_refiners",
              "Refiners of the multi-plane labelling (dense CRF on images, graph CRF)."),
    StageKind(FeatureMatcher, "monoplane_register_feature_matchers",
              "Feature matchers: keypoints and correspondences between images (local features "
              "or pairwise networks)."),
    StageKind(Matcher, "monoplane_register_matchers",
              "Multi-view matchers giving cameras, sparse points and keypoint matches (SfM)."),
    StageKind(Registrar, "monoplane_register_registrars",
              "Registrars placing the views the matcher left out (from planes, normals, depth, "
              "matches)."),
    StageKind(Fuser, "monoplane_register_fusers",
              "Fusers of per-view planes into a global planar scene."),
    StageKind(Adjuster, "monoplane_register_adjusters",
              "Joint refiners of a fused scene's cameras, per-view depth scales and global "
              "planes."),
)}

#: Stage kind names, in pipeline order; each is also the name of its config table.
STAGE_KINDS: tuple[str, ...] = tuple(KINDS)
