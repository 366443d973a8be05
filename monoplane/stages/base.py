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
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from monoplane.cues.network import CueNetwork
    from monoplane.datamodel import Frame, Reconstruction, Scene, SfmResult
    from monoplane.features import Correspondences, Keypoints, PairMatches
    from monoplane.geometry.alignment import ScaleAlignment
    from monoplane.geometry.cloud import PlaneCloud
    from monoplane.geometry.graph import NeighbourGraph

def param(default: Any, doc: str, **kwargs: Any) -> Any:
    """A config field with a default and a one-line description shown by ``monoplane plugins``.

    Mutable defaults (lists) are copied per instance.
    """
    if isinstance(default, (list, dict)):
        return field(default_factory=lambda: type(default)(default), metadata={"doc": doc},
                     **kwargs)
    return field(default=default, metadata={"doc": doc}, **kwargs)


def config_key(f: dataclasses.Field) -> str:
    """User-facing key of a config field: a Python keyword is spelled with a trailing
    underscore in the dataclass (``lambda_``) and without it in configs (``lambda``)."""
    return f.name[:-1] if f.name.endswith("_") else f.name


@dataclass
class ProximityAffinities:
    """The paper's proximity affinities between neighbouring points (§III-B, eq. of k_p, k_c,
    k_n): config fields shared by every stage that weighs graph edges with them (the
    ``proximity-graph-cut`` labeler, the ``graph-crf`` refiner). Positions are in unit-sphere
    units, colours RGB in [0, 1], normal angles in radians."""

    alpha_p2: float = param(0.005, "α_p², squared position bandwidth of k_p, k_c, k_n")
    alpha_c2: float = param(0.1, "α_c², squared colour bandwidth of k_c (RGB in [0, 1])")
    alpha_n2: float = param(5.0, "α_n², bandwidth of the normal angle (radians) in k_n")
    w_p: float = param(1.0, "weight of the position proximity term k_p")
    w_c: float = param(1.0, "weight of the colour proximity term k_c (dropped without colour)")
    w_n: float = param(1.0, "weight of the normal proximity term k_n")

    def affinities(self) -> tuple[float, float, float, float, float, float]:
        """``(alpha_p2, alpha_c2, alpha_n2, w_p, w_c, w_n)``, in the order
        :func:`monoplane.algorithm.graphcut.proximity_weights` takes them."""
        return (self.alpha_p2, self.alpha_c2, self.alpha_n2, self.w_p, self.w_c, self.w_n)


@dataclass
class NoConfig:
    """A stage without parameters."""


@dataclass(frozen=True)
class RansacParams:
    """Thresholds shared by every stage that uses them (sampler, scorer, labeler, refiner).

    Declared once, here: the host's ``[ransac]`` table takes its ``epsilon`` and
    ``epsilon_n_deg`` defaults from this class and hands the values to each of those stages,
    so ``--set ransac.epsilon=...`` moves all of them and no stage declares its own.

    Attributes
    ----------
    epsilon : float
        Point-to-plane inlier threshold ε in unit-sphere units (paper: 0.02).
    epsilon_n_deg : float
        Normal-angle threshold ε_n in degrees (paper: 10).
    """

    epsilon: float = 0.02
    epsilon_n_deg: float = 10.0

    @property
    def epsilon_n(self) -> float:
        """ε_n in radians."""
        return float(np.deg2rad(self.epsilon_n_deg))


@dataclass
class Labeling:
    """Result of labelling the remaining points for one plane hypothesis.

    Attributes
    ----------
    inliers : numpy.ndarray
        (M,) bool over the ``pool`` passed to the labeler.
    energy : float
        Value of the labeler's energy at this labelling (lower is better); the driver's local
        optimisation keeps a refit only while this decreases.
    """

    inliers: np.ndarray
    energy: float


class Stage:
    """Base of every stage. Subclasses set ``kind``, ``name`` and usually ``Config``."""

    kind: ClassVar[str] = ""
    name: ClassVar[str] = ""
    Config: ClassVar[type] = NoConfig

    def __init__(self, config: Any | None = None) -> None:
        self.config = self.Config() if config is None else config

    @classmethod
    def parameters(cls) -> list[tuple[str, str, Any, str]]:
        """``(key, type, default, doc)`` for each config field, for listings and docs.

        ``key`` is what a config or ``--set`` names (see :func:`config_key`).
        """
        rows = []
        for f in dataclasses.fields(cls.Config):
            if f.default is not dataclasses.MISSING:
                default = f.default
            elif f.default_factory is not dataclasses.MISSING:
                default = f.default_factory()
            else:
                default = None
            type_name = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
            rows.append((config_key(f), type_name, default, f.metadata.get("doc", "")))
        return rows


class CueProvider(Stage):
    """Fills depth, normals (and possibly intrinsics) of a frame.

    The pipeline calls :meth:`provide` only for frames that :meth:`needs_cues`; a frame that
    already has depth and normals (RGB-D with normals, precomputed cues, synthetic scenes) goes
    through :func:`monoplane.cues.given.use_given_cues` instead, whatever provider the config
    names, so host code never has to switch providers for such frames.
    """

    kind = "cues"

    def needs_cues(self, frame: Frame) -> bool:
        """Whether this provider has work to do on the frame (default: depth or normals
        missing). Override to also process complete frames (e.g. to recompute normals)."""
        return frame.depth is None or frame.normals is None

    def catalogue_model(self, missing_depth: bool, missing_normals: bool) -> str | None:
        """Name of the model-catalogue entry this provider would load for a frame that lacks
        the given cues, or None when it would load none (default). The CLI uses it to check
        the cache, or fetch on request, before any image is read."""
        return None

    @classmethod
    def catalogue_config(cls, model: str) -> dict[str, Any] | None:
        """The keys of this provider's ``[cues]`` table that make it use the model-catalogue
        entry ``model`` (``monoplane run --cues NAME``), or None when it takes no catalogue
        model (default).

        The host never names a provider's keys: it merges what this returns into the
        ``[cues]`` table (before the user's ``--set`` overrides), and the provider's ``Config``
        checks the name as it checks any value.

        Parameters
        ----------
        model : str
            A catalogue name, as ``monoplane models list`` shows them.
        """
        return None

    def provide(self, frame: Frame) -> Frame:
        """Return a frame with ``depth`` and ``normals`` set.

        Parameters
        ----------
        frame : Frame
            Input frame; ``rgb`` and ``K`` are set, ``depth``/``normals`` may already be set
            (given by the user).
        """
        raise NotImplementedError


class NetworkCues(CueProvider):
    """Base of cue providers that run a :class:`~monoplane.cues.CueNetwork`.

    A subclass says how to build its network from its config (:meth:`build_network`, called
    once, at construction); :meth:`provide` runs it on each frame. Third-party cue plugins that
    wrap an ONNX profile subclass this too. It lives with the contracts, not with the built-in
    cue providers, because plugins subclass it and no module outside ``stages`` may import a
    concrete stage module.
    """

    def __init__(self, config: Any | None = None) -> None:
        super().__init__(config)
        self.network = self.build_network(self.config)

    def build_network(self, config: Any) -> CueNetwork:
        """The network this provider runs, from its config (an instance of ``Config``)."""
        raise NotImplementedError

    def provide(self, frame: Frame) -> Frame:
        """Predict the frame's missing depth and normals (see :meth:`CueNetwork.provide`)."""
        return self.network.provide(frame)


class TripletDraws(NamedTuple):
    """How a sampler draws a batch, when it draws as :func:`monoplane.geometry.hypotheses.
    draw_triplets` does (see :meth:`Sampler.triplet_draws`)."""

    first: int
    """Candidate samples drawn first."""
    budget: int
    """Candidates drawn at most: when fewer than wanted passed, the other ``budget - first``
    are drawn in one more round."""
    cos_min: float | None
    """A candidate passes when its three normals' pairwise dot products all reach this; None
    passes every candidate."""


class BinnedPoints(NamedTuple):
    """Points a scorer scores on, grouped by normal direction, when it scores as
    :func:`monoplane.geometry.hypotheses.binned_costs` does (see :meth:`Scorer.binned_points`).
    """

    coords: np.ndarray
    """(6, K) float64 x, y, z, nx, ny, nz of the points, ordered by cell."""
    start: np.ndarray
    """(C + 1,) int64 start of each cell's run in ``coords``."""
    centres: np.ndarray
    """(C, 3) float64 unit centre direction of each cell."""
    cos_reach: np.ndarray
    """(C,) float64 cosine of each cell's angular radius plus ε_n (plus a margin)."""


class Sampler(Stage):
    """Draws minimal samples (3 points) for plane hypotheses."""

    kind = "sampler"

    def triplet_draws(self, count: int, params: RansacParams) -> TripletDraws | None:
        """How a batch of ``count`` samples is drawn, if the way of
        :func:`monoplane.geometry.hypotheses.draw_triplets` (uniform, optionally normal-
        checked): then, with a scorer that answers :meth:`Scorer.binned_points`, the RANSAC
        driver runs a whole plane search in one compiled call
        (:func:`~monoplane.geometry.hypotheses.search_batches`) instead of calling
        :meth:`sample` and :meth:`Scorer.score` batch by batch. The answer must describe
        exactly what :meth:`sample` draws. The default, None, is always safe.
        """
        return None

    def sample(self, cloud: PlaneCloud, pool: np.ndarray, count: int,
               rng: np.random.Generator, params: RansacParams) -> np.ndarray:
        """Draw up to ``count`` minimal samples from the points in ``pool``.

        Parameters
        ----------
        cloud : PlaneCloud
            The frame's normalised oriented point cloud (N points).
        pool : numpy.ndarray
            (M,) int64 indices into the cloud of the points still unassigned.
        count : int
            Number of samples wanted.
        rng : numpy.random.Generator
            The driver's seeded generator; the only source of randomness allowed.
        params : RansacParams
            Shared thresholds.

        Returns
        -------
        numpy.ndarray
            (S, 3) int64 indices into the cloud, ``S <= count``; rejected samples are dropped.
        """
        raise NotImplementedError


class Scorer(Stage):
    """Scores plane hypotheses on the remaining points; lower cost is better."""

    kind = "scorer"

    def binned_points(self, cloud: PlaneCloud, pool: np.ndarray, params: RansacParams
                      ) -> BinnedPoints | None:
        """The pool's points binned as :func:`monoplane.geometry.hypotheses.binned_costs`
        scores them, if :meth:`score` is that cost (MSAC plus the normal term): see
        :meth:`Sampler.triplet_draws`. The default, None, is always safe.
        """
        return None

    def score(self, cloud: PlaneCloud, pool: np.ndarray, planes: np.ndarray,
              model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        """Cost of each hypothesis.

        Parameters
        ----------
        cloud : PlaneCloud
            Normalised point cloud.
        pool : numpy.ndarray
            (M,) int64 indices of the points to score on.
        planes : numpy.ndarray
            (H, 4) hypotheses ``(n, d)`` in the cloud's normalised frame, unit normals.
        model_normals : numpy.ndarray
            (H, 3) model normal θ_n of each hypothesis: the mean predicted normal of its sample.
        params : RansacParams
            Shared thresholds.

        Returns
        -------
        numpy.ndarray
            (H,) float64 costs, lower is better.
        """
        raise NotImplementedError


class LabelingContext:
    """A labeler's working memory for one frame (one run of the sequential RANSAC).

    The driver asks the labeler for one (:meth:`Labeler.new_context`) at the start of a
    frame, hands it to every :meth:`Labeler.prepare_pool` and :meth:`Labeler.label` call of
    that frame and drops it at the end. Whatever a labeler reuses between those calls (a pool's
    subgraph terms, per-edge weights, the last max-flow) lives here, not on the labeler, so one
    labeler instance can label several frames at once and nothing of one frame reaches the
    next. The base holds nothing; a labeler subclasses it for what it keeps.
    """


class Labeler(Stage):
    """Labels the remaining points as inliers/outliers of one plane."""

    kind = "labeler"

    def new_context(self) -> LabelingContext:
        """A fresh :class:`LabelingContext` for one frame (the default keeps nothing)."""
        return LabelingContext()

    def label(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
              plane: np.ndarray, model_normal: np.ndarray, params: RansacParams,
              context: LabelingContext | None = None) -> Labeling:
        """Binary labelling of ``pool`` for the plane ``plane``.

        Parameters
        ----------
        cloud : PlaneCloud
            Normalised point cloud.
        graph : NeighbourGraph
            kNN graph over the whole cloud, built once per frame; use only edges whose both
            ends are in ``pool``.
        pool : numpy.ndarray
            (M,) int64 indices of the points still unassigned.
        plane : numpy.ndarray
            (4,) hypothesis in the normalised frame, unit normal.
        model_normal : numpy.ndarray
            (3,) unit model normal θ_n.
        params : RansacParams
            Shared thresholds.
        context : LabelingContext, optional
            The frame's context (:meth:`new_context`), the same for every call of one frame;
            without one the call starts from nothing and keeps nothing.
        """
        raise NotImplementedError

    def prepare_pool(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
                     context: LabelingContext) -> None:
        """Compute what :meth:`label` needs of a pool whatever the hypothesis.

        The RANSAC driver calls this on a background thread as soon as a plane's inliers
        leave the pool, while the next plane's hypotheses are searched, and waits for it
        before the first :meth:`label` call on that pool; per-pool results should be kept in
        ``context``, where :meth:`label` finds them again (the default builds the pool's
        subgraph, which :meth:`NeighbourGraph.subgraph
        <monoplane.geometry.graph.NeighbourGraph.subgraph>` keeps). It must not change what
        :meth:`label` returns.
        """
        graph.subgraph(pool)


class Refiner(Stage):
    """Refines the multi-plane labelling.

    A refiner that works on the pixel grid (``needs_pixels = True``, the default) only has
    :meth:`refine`; a refiner that needs no image sets ``needs_pixels = False`` and also
    implements :meth:`refine_cloud`, which is what :func:`monoplane.detect_planes` calls on
    point clouds. The host rejects a pixel refiner on a cloud with a clear error.
    """

    kind = "refiner"
    #: True when the refiner works on the image grid and so cannot refine a bare point cloud.
    needs_pixels: ClassVar[bool] = True

    def prepare(self, frame: Frame) -> None:
        """Start the work of :meth:`refine` that depends on the frame alone, not on its labels.

        The pipeline calls this while RANSAC runs on the frame, once the RANSAC's own
        background work is under way; a refiner may start such work with
        :func:`monoplane.jit.in_background` (it queues behind the RANSAC's) and pick it up in
        :meth:`refine` when that gets the same frame. The default does nothing. The result of
        :meth:`refine` must not depend on whether this was called.
        """

    def refine(self, rec: Reconstruction, params: RansacParams) -> Reconstruction:
        """Return a refined reconstruction (labels, and params refit on the final masks).

        ``params`` are the pipeline's shared thresholds (``[ransac]``): a refiner that weighs
        distances or normal angles against ε or ε_n reads them there, so it always agrees with
        the RANSAC that produced ``rec``.
        """
        raise NotImplementedError

    def refine_cloud(self, cloud: PlaneCloud, graph: NeighbourGraph, labels: np.ndarray,
                     planes: np.ndarray, params: RansacParams) -> tuple[np.ndarray, np.ndarray]:
        """Refine per-point labels of a normalised cloud (refiners with ``needs_pixels=False``).

        Parameters
        ----------
        cloud : PlaneCloud
            Normalised oriented cloud (N points, unit sphere).
        graph : NeighbourGraph
            kNN graph over ``cloud.points``.
        labels : numpy.ndarray
            (N,) int32 RANSAC labels, 0 = non-planar, ``i`` = ``planes[i - 1]``.
        planes : numpy.ndarray
            (P, 4) unit-normal planes in the normalised frame.
        params : RansacParams
            The pipeline's shared thresholds (see :meth:`refine`).

        Returns
        -------
        labels, planes : numpy.ndarray
            Refined (N,) int32 labels 0..P' and (P', 4) planes, same frame.
        """
        raise NotImplementedError(f"refiner '{self.name}' works on images only")


class FeatureMatcher(Stage):
    """Keypoints and correspondences between images, for SfM, the registrar and fusion.

    Two shapes plug in here. A **local feature** (SIFT, XFeat, ALIKED, ...) describes each image
    on its own: implement :meth:`detect` and :meth:`match`. A **pairwise network** (LoFTR,
    LightGlue run on two images, ...) sees both images at once: set ``pairwise = True`` and
    implement :meth:`match_pair`; the host gathers its matched pixels into one keypoint list
    per view (:class:`monoplane.features.Correspondences`), so either shape feeds COLMAP's
    database, the registrar and plane matching alike.
    """

    kind = "features"
    #: True for networks that match two images at once (:meth:`match_pair`).
    pairwise: ClassVar[bool] = False
    #: Names an SfM matcher's own implementation of the same features (``"sift"``: COLMAP's
    #: SIFT extraction, matching and verification), which such a matcher runs instead of
    #: importing these correspondences; None when there is none.
    sfm_native: ClassVar[str | None] = None

    def detect(self, frame: Frame) -> Keypoints | None:
        """Keypoints and descriptors of one frame (None for a pairwise network).

        Parameters
        ----------
        frame : Frame
            A frame with ``rgb`` (H, W, 3) uint8.

        Returns
        -------
        Keypoints or None
            Pixels ``(u, v)`` at the frame's native resolution, pixel centres at integers.
        """
        return None

    def match(self, a: Keypoints, b: Keypoints) -> PairMatches:
        """Matches of two images' keypoints (``index`` set), for stages that :meth:`detect`."""
        raise NotImplementedError(f"features stage '{self.name}' does not match descriptors")

    def match_pair(self, frame_i: Frame, frame_j: Frame) -> PairMatches:
        """Matched pixels of two frames (``pixels_i``, ``pixels_j`` set): pairwise networks."""
        raise NotImplementedError(f"features stage '{self.name}' does not match image pairs")


class Matcher(Stage):
    """Structure from motion over several frames."""

    kind = "matcher"
    #: True when :meth:`match` takes the ``[features]`` stage's correspondences.
    uses_correspondences: ClassVar[bool] = False

    def match(self, frames: list[Frame], correspondences: Correspondences | None = None
              ) -> SfmResult:
        """Cameras, sparse points and pairwise keypoint matches for ``frames``.

        A matcher that cannot register every frame may mark those frames ``{"method": "none"}``
        in the result's ``registration`` (their cameras are then placeholders); the registrar
        stage then tries to place them. A matcher that declares ``uses_correspondences`` is
        handed the ``[features]`` stage's keypoints and matches (computed on demand) and builds
        its model on them; the host passes nothing to the others.
        """
        raise NotImplementedError

    @classmethod
    def fixed_intrinsics_config(cls, config: Any) -> Any | None:
        """This matcher's config changed to hold every frame's ``K`` fixed, or None.

        The host calls it when the user gives calibrated intrinsics. The default says the
        matcher cannot hold intrinsics fixed (None); a matcher that can returns a copy of
        ``config`` with that option set, leaving ``config`` itself unchanged.
        """
        return None


class Registrar(Stage):
    """Places the views the matcher left unregistered, from what every view already has.

    The host calls it on every multi-view run, also when the matcher placed every view, so a
    registrar may check (and replace) weakly supported placements too."""

    kind = "registrar"

    def register(self, views: list[Reconstruction], sfm: SfmResult,
                 alignments: list[ScaleAlignment | None]
                 ) -> tuple[SfmResult, list[ScaleAlignment | None]]:
        """Give a pose and a depth scale to every view it can place.

        Parameters
        ----------
        views : list of Reconstruction
            Every input view, segmented: ``rec.frame`` holds its image, its depth in its own
            (unaligned) units, its normals and ``K``; labels and planes are in that frame.
        sfm : SfmResult
            The matcher's model. ``sfm.registration[v]["method"]`` is ``"none"`` for a view
            to place; the others' cameras are world-to-camera poses in the model's frame.
            ``sfm.matches`` may hold keypoint matches between any two views, placed or not
            (a learned matcher puts its correspondences there).
        alignments : list of ScaleAlignment or None
            Per view, the factor bringing its depth into the model's units; None for the
            views to place.

        Returns
        -------
        (SfmResult, list of ScaleAlignment or None)
            The model with the placed views' cameras and their ``registration`` entries
            (``method`` naming how, plus its evidence), and their alignments. A view that
            cannot be placed keeps ``{"method": "none", "reason": ...}``. A view whose SfM
            pose it replaced says so (``"replaced": "sfm"``) and observes no model point.
        """
        raise NotImplementedError


class Fuser(Stage):
    """Matches per-view planes and fuses them into global planes."""

    kind = "fuser"

    def fuse(self, views: list[Reconstruction], sfm: SfmResult) -> Scene:
        """Fuse scale-aligned per-view reconstructions into a
        :class:`~monoplane.datamodel.Scene`."""
        raise NotImplementedError

    def fuse_with_matches(self, views: list[Reconstruction],
                          sfm: SfmResult) -> tuple[Scene, list[Any]]:
        """:meth:`fuse`, also returning the plane correspondences it accepted.

        The host calls this one. Each correspondence has attributes ``view_i``, ``plane_i``,
        ``view_j``, ``plane_j`` (1-based local ids) and ``criterion`` (a short string); they are
        written to ``scene.json``. The default returns no correspondences.
        """
        return self.fuse(views, sfm), []


class Adjuster(Stage):
    """Jointly refines the cameras, per-view depth scales and global planes of a fused scene."""

    kind = "adjuster"

    def adjust(self, scene: Scene, sfm: SfmResult) -> tuple[Scene, SfmResult, dict[str, Any]]:
        """Refine a fused scene.

        Parameters
        ----------
        scene : Scene
            Fused scene: cameras (world-to-camera), per-view reconstructions whose ``frame``
            holds the scale-aligned depth, global planes and the view-to-global links.
        sfm : SfmResult
            The sparse model the scene was built on (same cameras, world frame and units).

        Returns
        -------
        (Scene, SfmResult, dict)
            The refined scene (cameras, view depths and plane parameters rescaled by the
            refined per-view scales, global planes), the SfM result with the refined cameras
            and points, and a JSON-serialisable report (at least ``"before"`` and ``"after"``
            residual summaries; empty when nothing was done).
        """
        raise NotImplementedError


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
