"""Contracts of the stages that work on one frame: the cue provider, the RANSAC stages (sampler,
scorer, labeler) with the data they exchange, and the refiner.

The RANSAC stages work on a :class:`~monoplane.geometry.cloud.PlaneCloud`, an oriented point
cloud normalised into the unit sphere, so thresholds are in unit-sphere units as in the paper.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, NamedTuple

import numpy as np

from monoplane.contracts.stage import Stage, param
from monoplane.errors import PluginError

# Re-exported: the public plugin API lists it.
from monoplane.geometry.normal_bins import BinnedPoints  # noqa: F401

if TYPE_CHECKING:
    from monoplane.cues.network import CueNetwork
    from monoplane.datamodel import Frame, Reconstruction
    from monoplane.geometry.cloud import PlaneCloud
    from monoplane.geometry.graph import NeighbourGraph


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


class Labeling:
    """Result of labelling the remaining points for one plane hypothesis.

    Parameters
    ----------
    inliers : numpy.ndarray
        (M,) bool over the ``pool`` passed to the labeler.
    energy : float or callable
        Value of the labeler's energy at this labelling (lower is better), or a function of
        no arguments that returns it, called when :attr:`energy` is first read: the driver
        reads it only to compare local-optimisation rounds, and a labeler whose energy costs
        a pass over its points and edges need not sum it for a search without them.

    Attributes
    ----------
    inliers : numpy.ndarray
        As given.
    energy : float
        The energy (see above); the driver's local optimisation keeps a refit only while it
        decreases.
    """

    __slots__ = ("_energy", "inliers")

    def __init__(self, inliers: np.ndarray, energy: float | Callable[[], float]) -> None:
        self.inliers = inliers
        self._energy = energy

    @property
    def energy(self) -> float:
        """The labelling's energy (see the class), summed on first read when given lazily."""
        if callable(self._energy):
            self._energy = float(self._energy())
        return self._energy

    def __repr__(self) -> str:
        energy = "(not summed yet)" if callable(self._energy) else self._energy
        return f"Labeling({self.inliers.sum()} of {self.inliers.size} inliers, energy={energy})"


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

    def lacks_depth_model(self) -> bool:
        """True when a frame without depth would find no network here to predict it, and a
        catalogue model (``cues.model``, ``monoplane run --cues NAME``) is what would give
        one. The host then asks for a model or a depth file before reading any image
        (:func:`monoplane.host.cue_models.require_depth_source`).

        Default False: a provider that takes no catalogue model, or needs none, reports what
        it lacks itself when it runs.
        """
        return False

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


#: The draws a sampler can state (:attr:`Sampler.draws`); the host runs each in its compiled
#: search (:func:`monoplane.geometry.hypotheses.search_batches`):
#:
#: * ``"uniform"``: three distinct pool points, uniformly, ``count`` candidates all kept;
#: * ``"normal-consistent"``: uniform candidates kept when their three normals' pairwise dot
#:   products all reach cos ε_n; ``2 count`` candidates first and, when fewer than ``count``
#:   passed, the rest of :meth:`Sampler.draw_budget` in one more round.
#:
#: Both draw as :func:`monoplane.geometry.hypotheses.draw_triplets` does, from the driver's
#: generator.
SAMPLER_DRAWS: tuple[str, ...] = ("uniform", "normal-consistent")
#: The costs a scorer can state (:attr:`Scorer.scores`), lower is better: ``"inliers"`` (minus
#: the points within ε), ``"msac"`` (Σ min(φ²/ε², 1)) and ``"msac-normal"`` (Σ min(φ²/ε² +
#: g(1, p), 1), :func:`monoplane.geometry.hypotheses.hypothesis_costs`). The compiled search
#: scores ``"msac-normal"``.
SCORER_COSTS: tuple[str, ...] = ("inliers", "msac", "msac-normal")


def _own_statement(cls: type, method: str, attr: str, choices: tuple[str, ...]) -> None:
    """Hold a stage class's statement about ``method`` to the class that defines the method.

    A class that defines ``method`` without stating ``attr`` itself states nothing (None),
    whatever its base stated: the statement described the base's method, not this one. A
    stated value must be one of ``choices``.
    """
    if method in cls.__dict__ and attr not in cls.__dict__:
        setattr(cls, attr, None)
    value = getattr(cls, attr)
    if value is not None and value not in choices:
        raise PluginError(f"{cls.__module__}.{cls.__qualname__}.{attr} = {value!r}: state one "
                          f"of {', '.join(map(repr, choices))}, or None")


class TripletDraws(NamedTuple):
    """The rounds of one batch of a stated draw (:data:`SAMPLER_DRAWS`), as
    :func:`monoplane.geometry.hypotheses.draw_triplets` takes them."""

    first: int
    """Candidate samples drawn first."""
    budget: int
    """Candidates drawn at most: when fewer than wanted passed, the other ``budget - first``
    are drawn in one more round."""
    cos_min: float | None
    """A candidate passes when its three normals' pairwise dot products all reach this; None
    passes every candidate."""

    @classmethod
    def stated(cls, draws: str, count: int, budget: int, epsilon_n: float) -> TripletDraws:
        """The rounds of a batch of ``count`` samples under the draw ``draws``.

        Parameters
        ----------
        draws : str
            One of :data:`SAMPLER_DRAWS`.
        count : int
            Samples wanted.
        budget : int
            Candidates drawn at most (:meth:`Sampler.draw_budget`); a uniform draw ignores it.
        epsilon_n : float
            Normal threshold ε_n in radians.
        """
        if draws == "uniform":
            return cls(count, count, None)
        return cls(min(2 * count, budget), budget, float(np.cos(epsilon_n)))


class Sampler(Stage):
    """Draws minimal samples (3 points) for plane hypotheses.

    A sampler whose :meth:`sample` draws one of :data:`SAMPLER_DRAWS` says so in
    :attr:`draws`; with a scorer that states ``scores = "msac-normal"``, the RANSAC driver
    then runs each plane search in one compiled call instead of calling :meth:`sample` and
    :meth:`Scorer.score` batch by batch, with the same samples, hypotheses and generator
    state. The statement belongs to the class that defines :meth:`sample`: a subclass that
    overrides :meth:`sample` states nothing until it states :attr:`draws` again, and is
    called batch by batch.
    """

    kind = "sampler"
    #: What :meth:`sample` draws, one of :data:`SAMPLER_DRAWS`; None (the default): something
    #: else, and the driver calls :meth:`sample` for every batch.
    draws: ClassVar[str | None] = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        _own_statement(cls, "sample", "draws", SAMPLER_DRAWS)

    def draw_budget(self, count: int) -> int:
        """Candidates a ``"normal-consistent"`` draw of ``count`` samples draws at most (the
        default, ``count``: one round). A uniform draw does not ask."""
        return count

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
    """Scores plane hypotheses on the remaining points; lower cost is better.

    A scorer whose :meth:`score` is one of :data:`SCORER_COSTS` says so in :attr:`scores`
    (see :class:`Sampler` for what the driver does with it).
    """

    kind = "scorer"

    #: What :meth:`score` costs, one of :data:`SCORER_COSTS`; None (the default): something
    #: else. The statement belongs to the class that defines :meth:`score`, as
    #: :attr:`Sampler.draws` does to :meth:`Sampler.sample`.
    scores: ClassVar[str | None] = None

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        _own_statement(cls, "score", "scores", SCORER_COSTS)

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

        The RANSAC driver calls this on a background thread for the first pool and as soon
        as a plane's inliers leave the pool, while the next plane's hypotheses are searched,
        and waits for it before the first :meth:`label` call on that pool; per-pool results
        should be kept in ``context``, where :meth:`label` finds them again (the default
        builds the pool's subgraph, which :meth:`NeighbourGraph.subgraph
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
