"""Sequential multi-plane RANSAC driver (paper §III-A/B): the host side of the RANSAC stages.

One plane at a time, on the points not yet assigned (the *pool*):

1. the sampler draws minimal samples in batches and the scorer scores the exact 3-point planes
   on the pool, vectorised; the number of batches adapts to the best inlier ratio w so far,
   ``log(1 - confidence) / log(1 - w³)``, between ``min_iterations`` and ``max_iterations``
   (when the sampler and scorer state what they draw and score, ``Sampler.draws`` and
   ``Scorer.scores``, the whole search is one compiled call,
   :func:`monoplane.geometry.hypotheses.search_batches`, with the same result);
2. the labeler labels the pool for the best hypothesis (threshold or graph cut on the kNN
   subgraph of the pool);
3. local optimisation: least-squares refit on the inliers (model normal θ_n = mean predicted
   normal of the inliers), relabel, and keep the refit while the labeler's energy decreases;
4. with ``split_components``, only the largest connected component (in the neighbourhood graph;
   on a lattice also across thin occluders, ``lattice_split_reach``) of the inliers is kept;
   the other components return to the pool and can become planes of their own later (two
   table tops at the same height are two planes);
5. the plane is accepted if its support reaches ``min_support``, otherwise the search stops;
   its inliers leave the pool. With ``max_rejections`` > 0 a too-small plane (its labelled
   points leave the pool as non-planar), or a search that found no hypothesis, is passed over
   that many times before the search stops (on a lattice, ``lattice_fragments`` more times
   for a plane whose parts each fall below ``min_support``).

Steps 1-5 form the cloud-level core, :meth:`SequentialRansac.run_cloud`, which needs no pixel
grid (a cloud and its kNN graph). :meth:`SequentialRansac.run` wraps it for a frame: the cloud
and its neighbour graph are built once per frame, and afterwards labels are carried to
every valid pixel (:meth:`PlaneCloud.propagate`), each plane is refit by least squares on all
its pixels in the camera frame and the depth's units, and normals are turned towards the
camera. With ``noise_factor`` > 0, :meth:`SequentialRansac.run` measures the depth noise on
the planes of the first search and, when it is well below ε, searches again with ε set by it
(:mod:`monoplane.geometry.sensor_noise`); the later stages get those thresholds
(``params_used``). All randomness comes from one generator seeded with ``seed``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple, TypeVar

import numpy as np

from monoplane.algorithm.plane_refit import refit_and_renumber
from monoplane.contracts import (
    SAMPLER_DRAWS,
    Labeler,
    Labeling,
    LabelingContext,
    RansacParams,
    Sampler,
    Scorer,
    Stage,
    TripletDraws,
    param,
    run_stage,
)
from monoplane.datamodel import Frame, Reconstruction, orient_towards_camera
from monoplane.errors import InvalidInput, check_config
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.components import lattice_largest_component
from monoplane.geometry.graph import NeighbourGraph
from monoplane.geometry.hypotheses import (
    SearchRule,
    inlier_ratio,
    needed_samples,
    refit_hypothesis,
    sample_hypotheses,
    search_batches,
)
from monoplane.geometry.normal_bins import NORMAL_CELLS, bin_points, normal_cells
from monoplane.geometry.planes import fit_planes_per_label
from monoplane.geometry.sensor_noise import noise_limited_epsilon, plane_residual_sigma
from monoplane.jit import in_background

T = TypeVar("T")

#: The search is repeated with the noise-limited ε only when it is below this fraction of ε:
#: a threshold barely tighter would find the same planes at twice the cost.
RESEARCH_BELOW = 0.6
#: How a frame's pixels may be subsampled (``RansacConfig.sampling``).
SAMPLINGS = ("auto", "random", "grid")
#: Lattice neighbours farther apart than this fraction of their distance from the camera
#: are not linked (``sampling = "grid"``): a slanted plane 80 degrees from the view at 4 px
#: lattice steps and f = 525 px spaces its samples 0.044 apart, a depth edge far more.
LATTICE_MAX_JUMP = 0.05


class CloudPlanes(NamedTuple):
    """Result of :meth:`SequentialRansac.run_cloud` (unpacks as ``labels, planes, timings``)."""

    labels: np.ndarray
    """(N,) int32 plane of each point, 0 = non-planar, ``i`` = ``planes[i - 1]``."""
    planes: np.ndarray
    """(P, 4) float64 unit-normal planes in the cloud's normalised frame, detection order."""
    timings: dict[str, float]
    """Seconds per sub-step: ``ransac.search`` and ``ransac.label``."""


@dataclass
class RansacConfig:
    """Parameters of the sequential RANSAC driver (config table ``[ransac]``).

    Distances are in unit-sphere units of the normalised cloud (paper §III-A).
    """

    # The shared thresholds' defaults are RansacParams's: declared once, for every stage.
    epsilon: float = param(RansacParams.epsilon, "inlier distance threshold ε, unit-sphere "
                           "units; every stage that weighs distances uses it")
    epsilon_n_deg: float = param(RansacParams.epsilon_n_deg, "normal angle threshold ε_n in "
                                 "degrees; every stage that weighs normal angles uses it")
    confidence: float = param(0.99, "RANSAC confidence for the adaptive number of samples")
    max_iterations: int = param(1000, "most minimal samples drawn per plane")
    min_iterations: int = param(100, "fewest minimal samples drawn per plane")
    batch_size: int = param(100, "minimal samples drawn and scored together")
    min_support: float = param(
        0.006, "smallest plane, as a fraction of the cloud's points (paper: 300 px at 256x192)")
    min_support_points: int = param(30, "smallest plane in points, whatever the fraction")
    max_planes: int = param(20, "most planes extracted from one frame")
    knn: int = param(8, "neighbours per point in the graph-cut neighbourhood graph")
    max_points: int = param(20000, "subsample the valid pixels to at most this many points")
    sampling: str = param(
        "auto", "how a frame's valid pixels are subsampled: 'random' (a uniform draw; the "
        "graph is the kNN graph), 'grid' (a regular pixel lattice; the graph is its "
        "8-neighbourhood cut at depth jumps, no kNN query) or 'auto' ('grid' on frames whose "
        "normals come from a sensor's depth, else 'random'). Point clouds always use 'random'")
    lattice_max_turn_deg: float = param(
        180.0, "on the lattice (sampling 'grid', or 'auto' on a sensor frame), neighbours "
        "whose normals differ by more than this angle in degrees are not linked either "
        "(180: no such cut)")
    lattice_turn_deg: float = param(
        10.0, "on the lattice (sampling 'grid', or 'auto' on a sensor frame), the proximity "
        "labeler's affinity of two lattice neighbours (their cut cost above its 0.5 floor) is "
        "scaled by exp(-t²/2σ²), t the angle between their normals: this σ in degrees (0: not "
        "scaled)")
    lattice_split_reach: int = param(
        6, "on the lattice (sampling 'grid', or 'auto' on a sensor frame) with "
        "split_components, a plane's inliers also connect across up to this many lattice steps "
        "along a lattice line when every sample between them lies in front of them or has no "
        "depth (a thin occluder such as a table leg); 1: the lattice graph's links only")
    lattice_fragments: int = param(
        0, "on the lattice (sampling 'grid', or 'auto' on a sensor frame) with "
        "split_components, a plane whose labelled inliers reach min_support but fall apart "
        "into parts each below it is set aside (its points leave the pool as non-planar) "
        "without stopping the search, up to this many times a search (a surface seen edge-on: "
        "the lattice's jump test parts what the kNN graph links)")
    lo_iterations: int = param(1, "local optimisation rounds (refit + relabel) per plane")
    split_components: bool = param(
        False, "keep only the largest graph-connected component of each plane's inliers")
    score_points: int = param(
        5000, "score hypotheses on a random subset of at most this many pool points (0 = all)")
    seed: int = param(0, "seed of the random generator; equal seeds give equal results")
    max_rejections: int = param(
        0, "a search that finds no hypothesis, or a plane below min_support (its points are "
        "then set aside as non-planar), is passed over up to this many times before the "
        "search stops (0: it stops at the first)")
    noise_factor: float = param(
        0.0, "if > 0, a frame whose planes show depth noise σ well below ε is searched again "
        "with ε = noise_factor × σ (a depth sensor; monoplane.geometry.sensor_noise)")
    noise_planes: int = param(
        0, "with noise_factor > 0, the first search, which only measures the noise, stops "
        "after this many planes (0: max_planes); the largest planes show it already")

    def __post_init__(self) -> None:
        # No table name: the config loader says which table (and a direct caller knows which
        # object it built).
        check_config([
            (self.epsilon > 0, "epsilon must be positive"),
            (0 < self.epsilon_n_deg <= 180, "epsilon_n_deg must lie in (0, 180]"),
            (0 < self.confidence < 1, "confidence must lie in (0, 1)"),
            (self.batch_size >= 1, "batch_size must be at least 1"),
            (1 <= self.min_iterations <= self.max_iterations,
             "need 1 <= min_iterations <= max_iterations"),
            (0 <= self.min_support < 1, "min_support must lie in [0, 1)"),
            (self.min_support_points >= 3, "min_support_points must be at least 3"),
            (self.max_planes >= 1, "max_planes must be at least 1"),
            (self.knn >= 1, "knn must be at least 1"),
            (self.max_points >= 3, "max_points must be at least 3"),
            (self.sampling in SAMPLINGS,
             f"sampling must be one of {', '.join(SAMPLINGS)}, got {self.sampling!r}"),
            (0 < self.lattice_max_turn_deg <= 180, "lattice_max_turn_deg must lie in (0, 180]"),
            (self.lattice_turn_deg >= 0, "lattice_turn_deg must be non-negative"),
            (self.lattice_split_reach >= 1, "lattice_split_reach must be at least 1"),
            (self.lattice_fragments >= 0, "lattice_fragments must be non-negative"),
            (self.lo_iterations >= 0, "lo_iterations must be non-negative"),
            (self.noise_factor >= 0, "noise_factor must be non-negative"),
            (self.noise_planes >= 0, "noise_planes must be non-negative"),
            (self.max_rejections >= 0, "max_rejections must be non-negative"),
            (self.score_points == 0 or self.score_points >= 3,
             "score_points must be 0 (all) or at least 3"),
        ])

    @property
    def params(self) -> RansacParams:
        """The thresholds shared with the sampler, scorer and labeler."""
        return RansacParams(epsilon=self.epsilon, epsilon_n_deg=self.epsilon_n_deg)


def _call(stage: Stage, fn: Callable[..., T], *args: Any) -> T:
    """Run one stage method; a failure names the stage's kind and plugin (:func:`run_stage`)."""
    return run_stage(stage.kind, stage.name, fn, *args)


class SequentialRansac:
    """Sequential plane RANSAC with pluggable sampler, scorer and labeler.

    Parameters
    ----------
    sampler, scorer, labeler : Stage
        The RANSAC stages (see :mod:`monoplane.contracts`).
    config : RansacConfig, optional
        Driver parameters; defaults to the paper's.
    """

    def __init__(self, sampler: Sampler, scorer: Scorer, labeler: Labeler,
                 config: RansacConfig | None = None) -> None:
        self.sampler = sampler
        self.scorer = scorer
        self.labeler = labeler
        self.config = RansacConfig() if config is None else config
        #: Each plane search runs in one compiled call (:func:`search_batches`) when the
        #: sampler states a draw it runs and the scorer states the cost it scores; else the
        #: sampler and scorer are called batch by batch.
        self.compiled_search = (sampler.draws in SAMPLER_DRAWS
                                and scorer.scores == "msac-normal")
        #: The thresholds the last :meth:`run` labelled with: the configured ones, or ε lowered
        #: to the frame's depth noise (``noise_factor``); later stages use these.
        self.params_used = self.config.params

    def run(self, frame: Frame, meanwhile: Callable[[], None] | None = None) -> Reconstruction:
        """Detect planes in a frame.

        Parameters
        ----------
        frame : Frame
            With ``depth`` and ``normals`` (camera frame); colour optional.
        meanwhile : callable, optional
            Called once the neighbour graph is being built in the background, e.g. to queue
            label-independent work of a later stage behind it (see
            :meth:`monoplane.contracts.Refiner.prepare`): the background thread is idle
            while the planes are searched and labelled one by one.

        Returns
        -------
        Reconstruction
            ``labels`` (H, W) int32 (0 = non-planar, planes in detection order), ``params``
            (P, 4) camera-frame planes in the depth's units facing the camera, ``rmse`` (P,)
            in depth units over each plane's pixels, ``support`` (P,) pixel counts, and
            ``timings`` in seconds per sub-step (keys ``ransac.*``).
        """
        cfg = self.config
        rng = np.random.default_rng(cfg.seed)
        t = time.perf_counter()
        grid = cfg.sampling == "grid" or (cfg.sampling == "auto"
                                          and frame.normals_from_sensor_depth)
        cloud = PlaneCloud.from_frame(frame, cfg.max_points, rng, grid=grid, fractional=True)
        t_cloud = time.perf_counter() - t
        t_graph = 0.0

        turn = None if cfg.lattice_max_turn_deg >= 180 else cfg.lattice_max_turn_deg

        def build_graph() -> NeighbourGraph:
            nonlocal t_graph
            t = time.perf_counter()
            if cloud.lattice is None:
                graph = cloud.neighbour_graph(cfg.knn)
            else:
                graph = NeighbourGraph.from_lattice(cloud.points, cloud.lattice,
                                                    cloud.center / cloud.scale,
                                                    LATTICE_MAX_JUMP, cloud.normals, turn,
                                                    cfg.lattice_turn_deg or None)
            t_graph = time.perf_counter() - t
            return graph

        # The first plane's hypothesis search needs the cloud only, so the graph is built
        # meanwhile on another thread (when the thread budget has one); the results are those
        # of building it first.
        graph = in_background(build_graph)
        # Only the finaliser needs the graph's adjacency lists and, when the cloud is
        # subsampled, the image-nearest samples: they are built after the graph on the same
        # thread, off the path to the first label, while this one labels planes.
        in_background(lambda: graph().adjacency())
        if cloud.subsampled:
            in_background(lambda: cloud.image_nearest_sample)
        if meanwhile is not None:
            meanwhile()
        if cfg.noise_factor > 0:
            result, params = self._noise_limited(cloud, graph, rng)
            if params.epsilon < cfg.epsilon:
                sigma = params.epsilon / cfg.noise_factor * cloud.scale
                frame.notes.append(f"ransac: depth noise {sigma:.3g} {frame.depth_units} on the "
                                   f"planes, searched again with epsilon {params.epsilon:.3g}")
        else:
            result, params = self._run(cloud, graph, rng), cfg.params
        self.params_used = params

        t = time.perf_counter()
        # Pixels within ε/4 of their nearest sample's plane keep its label outright.
        labels, valid = cloud.propagate_pixels(result.labels, result.planes,
                                               tolerance=0.25 * params.epsilon, graph=graph())
        rec = self._finalize(frame, cloud, labels, valid, len(result.planes))
        t_final = time.perf_counter() - t
        rec.timings.update({"ransac.cloud": t_cloud, "ransac.graph": t_graph,
                            **result.timings, "ransac.finalize": t_final})
        return rec

    def run_cloud(self, cloud: PlaneCloud, graph: NeighbourGraph,
                  rng: np.random.Generator | None = None) -> CloudPlanes:
        """Detect planes in a normalised oriented cloud; needs no pixel grid.

        This is the sequential search itself (steps 1-5 of the module docstring); :meth:`run`
        wraps it with the cloud and graph construction of a frame and the per-pixel finaliser.

        Parameters
        ----------
        cloud : PlaneCloud
            The normalised cloud (unit sphere); only ``points``, ``normals``, ``colors`` and
            ``size`` are used here.
        graph : NeighbourGraph
            The kNN graph over ``cloud.points`` (e.g. ``NeighbourGraph.build(cloud.points,
            config.knn)``).
        rng : numpy.random.Generator, optional
            Source of all randomness; a fresh generator seeded with ``config.seed`` when
            omitted. Equal generators give equal results.

        Returns
        -------
        CloudPlanes
            ``labels`` (N,) int32 per point (0 = non-planar, ``i`` = ``planes[i - 1]``),
            ``planes`` (P, 4) float64 unit-normal planes ``n · x + d = 0`` in the normalised
            frame in detection order, and ``timings`` in seconds (``ransac.search``,
            ``ransac.label``).
        """
        if rng is None:
            rng = np.random.default_rng(self.config.seed)
        if graph.num_nodes != cloud.size:
            raise InvalidInput(f"graph has {graph.num_nodes} nodes for a cloud of "
                               f"{cloud.size} points")
        return self._run(cloud, lambda: graph, rng)

    def _noise_limited(self, cloud: PlaneCloud, get_graph: Callable[[], NeighbourGraph],
                       rng: np.random.Generator) -> tuple[CloudPlanes, RansacParams]:
        """A first search, then the search again with ε = ``noise_factor`` × the noise its
        planes show when that is below :data:`RESEARCH_BELOW` × ε
        (:mod:`monoplane.geometry.sensor_noise`); else the first search's result and the
        configured thresholds (searched again when ``noise_planes`` cut the first search
        short). The search time of both passes is counted."""
        cfg = self.config
        # Both searches label the same frame's graph: what the labeler keeps of it (the cut
        # costs of every edge, ...) serves the second too, whatever ε.
        context = self.labeler.new_context()
        found = self._run(cloud, get_graph, rng, max_planes=cfg.noise_planes or None,
                          context=context)
        # Depth along the optical axis of the normalised points (the cloud is centred).
        depth = cloud.points[:, 2] * cloud.scale + cloud.center[2]
        # Least-squares planes of the labels: the search's own planes are fitted to its
        # inlier bands, which a loose ε tilts towards the objects it let in.
        planes = fit_planes_per_label(cloud.points, found.labels, len(found.planes))[0]
        sigma = plane_residual_sigma(cloud.points, depth, found.labels, planes)
        epsilon = noise_limited_epsilon(cfg.epsilon, sigma, cfg.noise_factor)
        params = RansacParams(epsilon=epsilon, epsilon_n_deg=cfg.epsilon_n_deg)
        if not epsilon < RESEARCH_BELOW * cfg.epsilon:
            if not cfg.noise_planes:
                return found, cfg.params
            params = cfg.params
        again = self._run(cloud, get_graph, rng, params, context=context)
        timings = {k: found.timings[k] + again.timings[k] for k in found.timings}
        return again._replace(timings=timings), params

    def _run(self, cloud: PlaneCloud, get_graph: Callable[[], NeighbourGraph],
             rng: np.random.Generator, params: RansacParams | None = None,
             max_planes: int | None = None, context: LabelingContext | None = None
             ) -> CloudPlanes:
        """:meth:`run_cloud` with the graph asked for only when the first plane is labelled
        (``get_graph`` may wait for it to be built); ``params`` replace the configured
        thresholds, ``max_planes`` the configured cap on the planes, and ``context`` is the
        labeler's memory of this frame when an earlier search of it made one."""
        cfg = self.config
        params = cfg.params if params is None else params
        max_planes = cfg.max_planes if max_planes is None else max_planes
        timings = {"ransac.search": 0.0, "ransac.label": 0.0}
        min_support = max(cfg.min_support_points, math.ceil(cfg.min_support * cloud.size))
        point_labels = np.zeros(cloud.size, dtype=np.int32)
        pool = np.arange(cloud.size, dtype=np.int64)
        found: list[np.ndarray] = []
        if context is None:
            context = self.labeler.new_context()  # the labeler's memory of this frame
        labeler = self.labeler

        def prepare(pool: np.ndarray) -> Callable[[], None]:
            """The pool's hypothesis-independent labelling work (its subgraph, ...), started
            on the second core while this thread searches the pool's next plane."""
            return in_background(lambda: _call(labeler, labeler.prepare_pool, cloud,
                                               get_graph(), pool, context), role="pool")

        # The first pool's too (for the built-in labelers, the cut costs of the frame's whole
        # graph): it waits there for the graph, not here.
        prepared = prepare(pool)
        # Each point's normal cell, for the compiled search's grouping of every pool.
        cells = normal_cells(cloud.normals, NORMAL_CELLS) if self.compiled_search else None
        rejections = 0
        fragments = 0 if cloud.lattice is not None and cfg.split_components else None
        while len(found) < max_planes and pool.size >= min_support:
            t = time.perf_counter()
            best = self._search(cloud, pool, rng, params, cells)
            timings["ransac.search"] += time.perf_counter() - t
            if best is None:
                # No sample passed the sampler's test in a whole batch (a pool of scattered
                # crease points): another draw may, within the same allowance.
                if rejections >= cfg.max_rejections:
                    break
                rejections += 1
                continue
            graph = get_graph()
            t = time.perf_counter()
            prepared()  # the labeler's per-pool work, done while the search ran
            plane, inliers = self._label(cloud, graph, pool, best[0], best[1], params,
                                         context)
            labelled = inliers.copy()
            if cfg.split_components and inliers.any():
                inliers[np.flatnonzero(inliers)[~self._largest_part(cloud, graph, pool,
                                                                     inliers)]] = False
            timings["ransac.label"] += time.perf_counter() - t
            if inliers.sum() < min_support:
                # The best plane left is too small, or falls apart into pieces that each are:
                # its points leave the pool (non-planar), and the smaller faces elsewhere in
                # the pool, which a hypothesis through these points outscored, get their turn.
                if (fragments is not None and fragments < cfg.lattice_fragments
                        and labelled.sum() >= min_support):
                    fragments += 1  # a slab seen edge-on, parted by the lattice's jump test
                elif rejections >= cfg.max_rejections or not labelled.any():
                    break
                else:
                    rejections += 1
                inliers = labelled
            else:
                found.append(plane)
                point_labels[pool[inliers]] = len(found)
            pool = pool[~inliers]
            prepared = prepare(pool)
        prepared()  # nothing of this frame runs on after it
        planes = np.array(found, dtype=np.float64).reshape(-1, 4)
        return CloudPlanes(labels=point_labels, planes=planes, timings=timings)

    def _largest_part(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
                      inliers: np.ndarray) -> np.ndarray:
        """(K,) bool over ``pool[inliers]``: the largest connected part of a plane's inliers.

        In the neighbourhood graph; on a lattice cloud with ``lattice_split_reach`` > 1 the
        inliers also link across thin occluders (:func:`lattice_largest_component`): the
        lattice graph links image neighbours only, so a plane behind a table leg would fall
        into parts that the kNN graph, which links in 3D, keeps together.
        """
        reach = self.config.lattice_split_reach
        if cloud.lattice is None or reach <= 1:
            return graph.largest_component_within(pool, inliers)
        members = np.zeros(cloud.size, dtype=bool)
        members[pool[inliers]] = True  # the pool is ascending: so are its inliers
        return lattice_largest_component(members, cloud.lattice, cloud.points,
                                         cloud.center / cloud.scale, LATTICE_MAX_JUMP, reach)

    def _search(self, cloud: PlaneCloud, pool: np.ndarray, rng: np.random.Generator,
                params: RansacParams, cells: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray] | None:
        """Best hypothesis ``(plane (4,), model normal (3,))`` on the pool, or None;
        ``cells`` are the cloud's :func:`normal_cells`, when the caller keeps them."""
        cfg = self.config
        # Hypotheses are ranked on a fixed random subset of the pool: the ranking of MSAC-type
        # costs is stable under uniform subsampling, and scoring dominates the search time.
        scored = pool
        if 0 < cfg.score_points < pool.size:
            # The pool is ascending, so a mask of the drawn positions lists the subset in
            # ascending order: np.sort of the drawn points, without the sort.
            drawn_at = np.zeros(pool.size, dtype=bool)
            drawn_at[rng.choice(pool.size, size=cfg.score_points, replace=False)] = True
            scored = pool[drawn_at]
        if self.compiled_search:
            # The whole search in one compiled call: what the loop below does batch by batch.
            found, plane, normal = search_batches(
                rng, cloud.points, cloud.normals, pool, np.ascontiguousarray(scored),
                bin_points(cloud.points, cloud.normals, scored, params.epsilon_n, cells),
                self._search_rule(params))
            return (plane, normal) if found else None
        best_cost = math.inf
        best: tuple[np.ndarray, np.ndarray] | None = None
        needed = float(cfg.max_iterations)
        drawn = 0
        while drawn < min(max(needed, cfg.min_iterations), cfg.max_iterations):
            samples = _call(self.sampler, self.sampler.sample, cloud, pool, cfg.batch_size,
                            rng, params)
            # Samples the sampler rejected (e.g. normal-inconsistent ones) count as drawn: the
            # budget bounds the work per plane whatever the rejection rate.
            drawn += cfg.batch_size
            if samples.shape[0] == 0:
                break
            planes, model_normals = sample_hypotheses(cloud.points, cloud.normals, samples)
            if planes.shape[0] == 0:
                continue
            costs = _call(self.scorer, self.scorer.score, cloud, scored, planes,
                          model_normals, params)
            i = int(np.argmin(costs))
            if costs[i] < best_cost:
                best_cost = float(costs[i])
                best = (planes[i], model_normals[i])
                needed = needed_samples(
                    inlier_ratio(cloud.points, scored, planes[i], params.epsilon),
                    cfg.confidence)
        return best

    def _search_rule(self, params: RansacParams) -> SearchRule:
        """The scalars of a compiled search: the stated draw's rounds (:class:`TripletDraws`),
        the thresholds and the stopping rule (typed as the kernel was compiled for)."""
        cfg = self.config
        count = cfg.batch_size
        draws = self.sampler.draws
        assert draws is not None  # compiled_search: the sampler stated its draw
        budget = (count if draws == "uniform" else
                  _call(self.sampler, self.sampler.draw_budget, count))
        first, budget, cos_min = TripletDraws.stated(draws, count, budget, params.epsilon_n)
        return SearchRule(batch=int(count), first=int(first), budget=int(max(first, budget)),
                          check=cos_min is not None,
                          cos_min=-2.0 if cos_min is None else float(cos_min),
                          epsilon=float(params.epsilon), epsilon_n=float(params.epsilon_n),
                          min_iterations=int(cfg.min_iterations),
                          max_iterations=int(cfg.max_iterations),
                          confidence=float(cfg.confidence))

    def _label(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
               plane: np.ndarray, model_normal: np.ndarray, params: RansacParams,
               context: LabelingContext) -> tuple[np.ndarray, np.ndarray]:
        """Label the pool for a hypothesis, then refit and relabel while the energy drops.

        Returns the plane (4,) of the kept labelling and its (M,) bool inlier mask.
        """
        lab: Labeling = _call(self.labeler, self.labeler.label, cloud, graph, pool, plane,
                              model_normal, params, context)
        for _ in range(self.config.lo_iterations):
            members = pool[lab.inliers]
            if members.size < 3:
                break
            refit, refit_normal = refit_hypothesis(cloud.points, cloud.normals, members,
                                                   model_normal)
            new = _call(self.labeler, self.labeler.label, cloud, graph, pool, refit,
                        refit_normal, params, context)
            if not new.energy < lab.energy - 1e-9 * max(1.0, abs(lab.energy)):
                break
            lab, plane = new, refit
        return plane, np.asarray(lab.inliers, dtype=bool)

    @staticmethod
    def _finalize(frame: Frame, cloud: PlaneCloud, labels: np.ndarray, valid: np.ndarray,
                  count: int) -> Reconstruction:
        """Least-squares plane per label on all its pixels, camera frame and depth units.

        ``labels`` is the (H, W) label image, ``valid`` the (V,) labels of the cloud's
        ``all_pixels`` (:meth:`PlaneCloud.propagate_pixels`) and ``count`` the number of
        labels (at least the largest).

        The fit runs on the normalised points of all valid pixels, which the cloud holds
        already; a total-least-squares fit commutes with the similarity that maps them back
        to the camera frame, where planes and RMSE are then expressed.
        """
        renumber, params, rmse, support = refit_and_renumber(cloud.all_points, valid, count)
        params = cloud.plane_to_camera(params)
        if len(params) < count:  # labels too small to fit a plane are gone
            labels = renumber[labels]
        return Reconstruction(frame=frame, labels=labels,
                              planes=orient_towards_camera(params) if len(params)
                              else np.zeros((0, 4)),
                              rmse=rmse * cloud.scale, support=support)

