"""``graph-crf``: multi-plane refinement on the kNN graph of the cloud, no image needed.

Sequential RANSAC labels greedily: a point on the crease between two faces goes to whichever
plane was found first, and a point left over after the search stays non-planar. This refiner
revisits every point with all planes at once. It minimises a multi-label CRF on the cloud's kNN
graph

    E(l) = Σ_i U_i(l_i) + β Σ_(i,j)∈E w_ij [l_i ≠ l_j] / k̄

by mean-field inference, where

* ``U_i(0) = 1`` (non-planar) and ``U_i(p) = (φ(i, p) / ε)² + g(ρ(i, p))`` for plane ``p``:
  the GC-RANSAC truncated-L2 distance cost, untruncated so that a point beyond ε prefers
  "non-planar", plus the labeler's normal cost (paper eq. E_n) with threshold ε_n; ε and ε_n
  are the pipeline's ``[ransac]`` thresholds, handed in as :class:`RansacParams`;
* ``w_ij = 0.5 + k_p + k_c + k_n`` are the proximity labeler's cut costs (the same position,
  colour and normal affinities and bandwidths; colour is dropped when the cloud has none);
* ``k̄`` is the graph's mean degree, so β does not depend on ``knn``.

Afterwards each label is split into graph-connected components (coplanar but separate faces
become separate planes), components smaller than ``min_support`` are dropped, every plane is
refit by least squares on its points, and touching regions whose planes agree are merged.

The same code refines an image reconstruction: the frame's valid pixels are the cloud (no
subsampling), so it can serve ``monoplane run`` on range data as well.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from monoplane.algorithm.graphcut import proximity_weights
from monoplane.algorithm.label_mean_field import candidate_labels, potts_mean_field
from monoplane.contracts import ProximityAffinities, RansacParams, Refiner, Stage, WorkAhead, param
from monoplane.datamodel import Frame, Reconstruction, orient_towards_camera
from monoplane.errors import check_config
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.components import graph_components, same_label_components
from monoplane.geometry.graph import NeighbourGraph
from monoplane.geometry.lattice import pixel_grid_edges
from monoplane.geometry.planes import fit_planes_per_label
from monoplane.hookspecs import hookimpl
from monoplane.jit import chunks, kernel, run_threaded

#: Points per thread below which the data costs are computed on one thread.
_THREADED_NODES = 4096

#: Distance between diagonal neighbours ``stride`` pixels apart on a face at 70 deg incidence,
#: in units of ``stride / f`` times their depth: 3 √2 (1 / cos 70° ≈ 3).
_INCIDENCE_SPREAD = 3.0 * math.sqrt(2.0)

#: A frame's label-independent part of the refiner: its cloud, graph and weighted adjacency.
_Adjacency = tuple[np.ndarray, np.ndarray, np.ndarray]
_FrameGraph = tuple[PlaneCloud, NeighbourGraph, _Adjacency]

@dataclass
class GraphCrfConfig(ProximityAffinities):
    """Parameters of the ``graph-crf`` refiner (distances in unit-sphere units)."""

    noise_factor: float = param(
        0.0, "if > 0, the plane cost's distance scale is noise_factor × σ within "
        "[ransac.epsilon / 10, ransac.epsilon], σ the sensor noise estimated from the RANSAC "
        "planes' residuals (robust: 1.4826 × median |distance|)")
    normal_weight: float = param(
        1.0, "weight of the normal cost in the data term (0: distance only, for range data "
        "whose normals are blurred at creases)")
    beta: float = param(2.0, "weight β of the pairwise term against the data term")
    temperature: float = param(0.2, "mean-field temperature (lower = closer to hard ICM)")
    iterations: int = param(8, "mean-field iterations (0 keeps the labels, still splits/merges)")
    settle: float = param(
        0.0, "a point whose label probabilities all moved by at most this in an iteration "
        "counts as settled: its neighbours skip their next update unless another one moved "
        "(0: only points whose probabilities repeat exactly; labels as without the skip)")
    max_jump: float = param(
        0.05, "image input: relative depth jump that cuts the pixel-grid graph")
    max_points: int = param(
        0, "image input: the CRF runs on at most this many valid pixels, on the regular "
        "lattice of RANSAC's grid sampling, and the other pixels take the plane of a lattice "
        "neighbour they lie closest to; 0: every pixel")
    min_support: float = param(
        0.001, "smallest region kept, fraction of the cloud's points")
    min_support_points: int = param(20, "smallest region kept, points")
    merge_angle_deg: float = param(5.0, "touching regions merge when normals agree this well")
    merge_distance: float = param(
        0.5, "... and each region's RMS distance to the other's plane is below this times ε")
    rounds: int = param(
        1, "mean-field rounds; each later one starts from the labels and least-squares planes "
        "of the one before (a crease band a plane took in the search is given back)")

    def __post_init__(self) -> None:
        check_config([
            (self.noise_factor >= 0, "noise_factor must be >= 0"),
            (self.beta >= 0, "beta must be >= 0"),
            (self.normal_weight >= 0, "normal_weight must be >= 0"),
            (self.temperature > 0, "temperature must be positive"),
            (self.iterations >= 0, "iterations must be >= 0"),
            (0 <= self.settle < 1, "settle must lie in [0, 1)"),
            (self.rounds >= 1, "rounds must be >= 1"),
            (self.max_jump > 0, "max_jump must be positive"),
            (self.max_points == 0 or self.max_points >= 3,
             "max_points must be 0 (every pixel) or at least 3"),
            (min(self.alpha_p2, self.alpha_c2, self.alpha_n2) > 0, "bandwidths must be > 0"),
            (0 <= self.min_support < 1, "min_support must lie in [0, 1)"),
            (self.min_support_points >= 3, "min_support_points must be at least 3"),
            (0 <= self.merge_angle_deg <= 90, "merge_angle_deg must lie in [0, 90]"),
            (self.merge_distance >= 0, "merge_distance must be >= 0"),
        ], prefix="refiner (graph-crf): ")


def pixel_graph(cloud: PlaneCloud, max_jump: float) -> NeighbourGraph:
    """8-connected graph of a frame's valid pixels, cut across depth jumps.

    On an image the pixel grid is the natural neighbourhood: a 3D kNN graph over quantised
    range data links points only within one quantisation step (terrace) and falls apart into
    stripes. Two neighbouring pixels are linked unless their 3D distance exceeds ``max_jump``
    times their distance from the cloud's centre (a relative depth jump, as in the normals
    estimator).

    Parameters
    ----------
    cloud : PlaneCloud
        Cloud of the frame's valid pixels, all of them or those on a regular lattice
        (:meth:`PlaneCloud.from_frame` with ``grid``): the graph is the lattice's.
    max_jump : float
        Relative jump threshold, between neighbouring pixels and lattice nodes alike.
    """
    # A lattice cloud's neighbours are the lattice's: its rows and columns form the grid;
    # a cloud of every valid pixel is its own lattice.
    lattice = cloud.lattice
    if lattice is None:
        pixels, (h, w), _ = cloud.pixel_grid()
        lattice = np.full(h * w, -1, dtype=np.int64)
        lattice[pixels] = np.arange(cloud.size)
        lattice = lattice.reshape(h, w)
    # The cloud is centred on the scene; points are compared at their own depth scale.
    edges, gap, indptr, indices = pixel_grid_edges(np.ascontiguousarray(lattice), cloud.points,
                                               cloud.center / cloud.scale, float(max_jump),
                                               cloud.normals, -2.0)
    spacing = float(np.median(gap)) if gap.size else 0.0
    # No point index: the grid gave the neighbours, and building one over every pixel would
    # cost more than the graph.
    return NeighbourGraph(cloud.size, edges, indptr, indices, None, spacing)


def lattice_cloud(frame: Frame, max_points: int) -> PlaneCloud:
    """The cloud of a frame's valid pixels, on a regular lattice when there are too many.

    Parameters
    ----------
    frame : Frame
        With depth and normals.
    max_points : int
        At most this many points: the valid pixels at ``v, u ≡ s // 2 (mod s)`` for the
        smallest step ``s`` that keeps at most this many
        (:func:`monoplane.geometry.cloud.lattice_stride`); 0: every valid pixel.

    Returns
    -------
    PlaneCloud
        Normalised over all valid pixels (``all_points``), with its lattice step ``stride``
        (None or 1: every valid pixel).
    """
    if max_points == 0:
        return PlaneCloud.from_frame(frame)
    return PlaneCloud.from_frame(frame, max_points, grid=True)


@kernel
def _plane_costs(points: np.ndarray, normals: np.ndarray, planes: np.ndarray, inv_eps: np.float32,
                 normal_weight: float, epsilon_n: float, row0: int, row1: int, out: np.ndarray
                 ) -> None:
    """Rows ``row0:row1`` of :meth:`GraphCrfRefiner.unary` into ``out`` ((N, P + 1) float32),
    from (N, 3) float32 points and normals and (P, 4) float32 planes: ``out[:, 0] = 1``,
    ``out[:, p] = ((x·n_p + d_p) inv_eps)²`` plus ``normal_weight`` times the normal cost of
    :func:`monoplane.algorithm.graphcut.normal_costs` (float64, as there) when it is > 0."""
    for i in range(row0, row1):
        out[i, 0] = 1.0
        for p in range(planes.shape[0]):
            c = (points[i, 0] * planes[p, 0] + points[i, 1] * planes[p, 1]
                 + points[i, 2] * planes[p, 2] + planes[p, 3]) * inv_eps
            c = c * c
            if normal_weight > 0:
                cos = (normals[i, 0] * planes[p, 0] + normals[i, 1] * planes[p, 1]
                       + normals[i, 2] * planes[p, 2])
                angle = np.arccos(min(max(cos, np.float32(-1.0)), np.float32(1.0)))
                if angle >= epsilon_n:
                    c = np.float32(c + normal_weight * np.exp(angle / epsilon_n - 1.0))
            out[i, p + 1] = c


@kernel
def _touching_pairs(labels: np.ndarray, edges: np.ndarray, num: int) -> np.ndarray:
    """(K, 2) int64 pairs ``p < q`` of labels 1..``num`` joined by some of the (E, 2) int64
    ``edges`` of nodes labelled by the (N,) int64 ``labels``, in lexicographic order."""
    touch = np.zeros((num + 1, num + 1), dtype=np.bool_)
    count = 0
    for e in range(edges.shape[0]):
        a, b = labels[edges[e, 0]], labels[edges[e, 1]]
        if a > 0 and b > 0 and a != b:
            lo, hi = min(a, b), max(a, b)
            if not touch[lo, hi]:
                touch[lo, hi] = True
                count += 1
    pairs = np.empty((count, 2), dtype=np.int64)
    k = 0
    for p in range(1, num + 1):
        for q in range(p + 1, num + 1):
            if touch[p, q]:
                pairs[k, 0] = p
                pairs[k, 1] = q
                k += 1
    return pairs


@kernel
def _stable_order(labels: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """``np.argsort(labels, kind="stable")`` of (N,) int64 labels 0..L-1 with (L,) counts,
    by counting."""
    slot = np.zeros(counts.shape[0], dtype=np.int64)
    for k in range(1, counts.shape[0]):
        slot[k] = slot[k - 1] + counts[k - 1]
    order = np.empty(labels.shape[0], dtype=np.int64)
    for i in range(labels.shape[0]):
        order[slot[labels[i]]] = i
        slot[labels[i]] += 1
    return order


class GraphCrfRefiner(WorkAhead, Refiner):
    """Mean-field multi-plane CRF on the kNN graph, component split, refit, coplanar merge."""

    name = "graph-crf"
    Config = GraphCrfConfig
    needs_pixels = False

    def distance_scale(self, cloud: PlaneCloud, labels: np.ndarray, planes: np.ndarray,
                       params: RansacParams) -> float:
        """ε of the plane cost, normalised units: the RANSAC's ε or the noise-based one."""
        c = self.config
        planar = labels > 0
        if c.noise_factor == 0 or planar.sum() < 3:
            return params.epsilon
        p = planes[labels[planar] - 1]
        resid = np.abs(np.einsum("ij,ij->i", cloud.points[planar], p[:, :3]) + p[:, 3])
        sigma = 1.4826 * float(np.median(resid))
        # Exact or synthetic data have σ ≈ 0: a tenth of ε keeps the cost finite and above
        # the rounding of the plane fits.
        return float(np.clip(c.noise_factor * sigma, 0.1 * params.epsilon, params.epsilon))

    def unary(self, cloud: PlaneCloud, planes: np.ndarray, params: RansacParams,
              epsilon: float | None = None) -> np.ndarray:
        """(N, P + 1) float32 data costs: column 0 non-planar, column p plane p (module doc).

        The distance scale is ``epsilon`` when given (see :meth:`distance_scale`), else the
        RANSAC's ε; the normal threshold is the RANSAC's ε_n.
        """
        c = self.config
        epsilon = params.epsilon if epsilon is None else epsilon
        # float32: the costs only rank labels, and the (N, P + 1) arrays of a 512x512 range
        # image with 40 planes are the refiner's main memory traffic: one compiled pass
        # writes them, row range by row range on the frame's threads.
        points = np.ascontiguousarray(cloud.points, dtype=np.float32)
        normals = np.ascontiguousarray(cloud.normals, dtype=np.float32)
        planes32 = np.ascontiguousarray(planes, dtype=np.float32).reshape(-1, 4)
        out = np.empty((cloud.size, planes32.shape[0] + 1), dtype=np.float32)
        run_threaded([functools.partial(_plane_costs, points, normals, planes32,
                                        np.float32(1.0 / epsilon), float(c.normal_weight),
                                        float(params.epsilon_n), a, b, out)
                      for a, b in chunks(cloud.size, _THREADED_NODES)])
        return out

    def _mean_field(self, unary: np.ndarray, adj: tuple[np.ndarray, np.ndarray, np.ndarray],
                    labels: np.ndarray, mean_degree: float) -> np.ndarray:
        """Labels after mean-field inference from ``labels``; ``adj`` is the graph's weighted
        adjacency (:meth:`NeighbourGraph.weighted_adjacency`)."""
        c = self.config
        if c.iterations == 0 or unary.shape[1] < 2:
            return labels
        beta = c.beta / max(mean_degree, 1e-12)
        indptr, indices, weights = adj
        # Each pixel carries only the planes it can hold with non-negligible probability
        # (2-4 of up to 41 on a range image); the rest could change no sum and no argmax.
        # "Non-planar" after RANSAC means no plane claimed the point, not evidence against
        # every plane: such points start from their data term alone, so a strip the greedy
        # search left over does not hold itself in place through the pairwise term.
        ptr, cand, costs = candidate_labels(unary, labels, indptr, weights, beta,
                                            c.temperature)
        return potts_mean_field(ptr, cand, costs, indptr, indices, weights, labels, beta,
                                c.temperature, c.iterations, c.settle)

    def _components(self, graph: NeighbourGraph, labels: np.ndarray, min_size: int
                    ) -> np.ndarray:
        """Relabel every graph-connected region of one label as its own label 1..R."""
        comp = same_label_components(labels, graph.edges)
        comp = np.where(labels > 0, comp + 1, 0)
        sizes = np.bincount(comp)
        sizes[0] = 0
        keep = np.flatnonzero(sizes >= min_size)
        # Larger regions first, so plane ids follow size.
        keep = keep[np.argsort(-sizes[keep], kind="stable")]
        renumber = np.zeros(sizes.size, dtype=np.int32)
        renumber[keep] = np.arange(1, keep.size + 1)
        return renumber[comp]

    def _merge(self, cloud: PlaneCloud, graph: NeighbourGraph, labels: np.ndarray,
               planes: np.ndarray, epsilon: float) -> np.ndarray:
        """Merge touching regions whose planes agree (union-find over region adjacency);
        distances are compared against ``merge_distance`` × ``epsilon``."""
        c = self.config
        num = planes.shape[0]
        if num < 2 or c.merge_distance == 0:
            return labels
        pairs = _touching_pairs(np.ascontiguousarray(labels, dtype=np.int64), graph.edges, num)
        if pairs.size == 0:
            return labels
        cos_max = math.cos(math.radians(c.merge_angle_deg))
        tol2 = (c.merge_distance * epsilon) ** 2
        counts = np.bincount(labels, minlength=num + 1)
        order = _stable_order(np.ascontiguousarray(labels, dtype=np.int64), counts)
        groups = np.split(order, np.cumsum(counts)[:-1])
        agree = np.zeros(len(pairs), dtype=np.bool_)
        for i, (p, q) in enumerate(pairs):
            n_p, n_q = planes[p - 1], planes[q - 1]
            if abs(float(n_p[:3] @ n_q[:3])) < cos_max:
                continue
            pts_p, pts_q = cloud.points[groups[p]], cloud.points[groups[q]]
            agree[i] = not (np.mean((pts_p @ n_q[:3] + n_q[3]) ** 2) > tol2
                            or np.mean((pts_q @ n_p[:3] + n_p[3]) ** 2) > tol2)
        # Components number by their smallest region, so label 0 stays 0 and the merged
        # labels are dense in the order of their first region.
        return graph_components(num + 1, pairs[agree]).astype(np.int32)[labels]

    def _refit_round(self, cloud: PlaneCloud, adj: tuple[np.ndarray, np.ndarray, np.ndarray],
                     graph: NeighbourGraph, labels: np.ndarray, planes: np.ndarray,
                     params: RansacParams, epsilon: float) -> tuple[np.ndarray, np.ndarray]:
        """One more mean-field round on planes refit by least squares to the labels so far.

        The search's planes were fitted to their inlier bands, which along a crease include a
        strip of the neighbouring face; after one round most of that strip has gone back, so
        the refit planes sit on their own faces and the next round's distances separate the
        crease better. Labels that lost all their points keep their old plane (unused).
        """
        refit, _, support = fit_planes_per_label(cloud.points, labels, planes.shape[0])
        planes = np.where((support >= 3)[:, None] & np.isfinite(refit), refit, planes)
        labels = self._mean_field(self.unary(cloud, planes, params, epsilon), adj, labels,
                                  graph.mean_degree)
        return labels, planes

    def _adjacency(self, cloud: PlaneCloud, graph: NeighbourGraph) -> _Adjacency:
        """The graph's adjacency weighted by the proximity labeler's cut costs."""
        weights = proximity_weights(cloud.points, graph.edges, cloud.normals, cloud.colors,
                                    *self.config.affinities())
        return graph.weighted_adjacency(weights)

    def refine_cloud(self, cloud: PlaneCloud, graph: NeighbourGraph, labels: np.ndarray,
                     planes: np.ndarray, params: RansacParams) -> tuple[np.ndarray, np.ndarray]:
        """See :meth:`monoplane.contracts.Refiner.refine_cloud`."""
        c = self.config
        labels = np.asarray(labels, dtype=np.int32)
        planes = np.asarray(planes, dtype=np.float64).reshape(-1, 4)
        known, self._known = self._known, None
        if planes.shape[0] == 0:
            return labels, planes
        # refine() hands over the adjacency it prepared for this very graph.
        adj = (known[1] if known is not None and known[0] is graph
               else self._adjacency(cloud, graph))
        epsilon = self.distance_scale(cloud, labels, planes, params)
        labels = self._mean_field(self.unary(cloud, planes, params, epsilon), adj, labels,
                                  graph.mean_degree)
        for _ in range(c.rounds - 1):
            labels, planes = self._refit_round(cloud, adj, graph, labels, planes, params,
                                               epsilon)
        min_size = max(c.min_support_points, math.ceil(c.min_support * cloud.size))
        for _ in range(2):
            labels = self._components(graph, labels, min_size)
            num = int(labels.max(initial=0))
            planes, _, _ = fit_planes_per_label(cloud.points, labels, num)
            merged = self._merge(cloud, graph, labels, planes, params.epsilon)
            if int(merged.max(initial=0)) == num:
                break
            labels = merged
        return labels, planes

    #: The graph :meth:`refine` built (or picked up) and its weighted adjacency, for the
    #: :meth:`refine_cloud` call it makes next.
    _known: tuple[NeighbourGraph, _Adjacency] | None = None

    def prepare(self, frame: Frame) -> None:
        """Build the frame's lattice cloud, pixel graph and weighted adjacency on the
        background thread while the RANSAC runs (they do not depend on the labels);
        :meth:`refine` picks them up. With a budget of one thread :meth:`refine` builds
        them itself."""
        if frame.depth is not None and frame.normals is not None:
            self._start_ahead(frame, self._frame_graph)

    def _frame_graph(self, frame: Frame) -> _FrameGraph:
        """The label-independent part of :meth:`refine`: the cloud of the frame's valid
        pixels (on a lattice when there are more than ``max_points``, then with its
        image-nearest nodes cached), its pixel graph and the graph's weighted adjacency."""
        cloud = lattice_cloud(frame, self.config.max_points)
        jump = self.config.max_jump
        if cloud.stride is not None and cloud.stride > 1:
            # Diagonal lattice neighbours on a face seen at 70 deg incidence lie
            # 3 √2 stride / f of their depth apart: a coarse lattice on a low-resolution image
            # would cut such faces apart at max_jump. Only the cut is loosened, to that: ABW's
            # objects stand 5-10 % of the depth in front of their background.
            focal = float(min(frame.K[0, 0], frame.K[1, 1]))
            jump = max(jump, _INCIDENCE_SPREAD * cloud.stride / max(focal, 1e-9))
        graph = pixel_graph(cloud, jump)
        if cloud.subsampled:
            # The image-nearest lattice node of every pixel (a distance transform, 2-5 ms of
            # CPU), which refine's carry to every pixel starts from: it depends on the lattice
            # only, so it is cached on the cloud here rather than on refine's path.
            _ = cloud.image_nearest_sample
        return cloud, graph, self._adjacency(cloud, graph)

    def refine(self, rec: Reconstruction, params: RansacParams) -> Reconstruction:
        """Refine an image reconstruction on the kNN graph of all its valid pixels.

        Parameters
        ----------
        rec : Reconstruction
            RANSAC result; its frame needs depth and normals.

        Returns
        -------
        Reconstruction
            Labels 1..P' (graph-connected regions), planes refit on each region's pixels in
            the camera frame and depth units, facing the camera.
        """
        frame = rec.frame
        cloud, graph, adj = self._take_ahead(frame, self._frame_graph)
        pixels = cloud.pixel_grid()[0]
        start = rec.labels.ravel()[pixels]
        planes = cloud.plane_to_normalised(rec.planes) if rec.num_planes else np.zeros((0, 4))
        self._known = (graph, adj)
        labels, planes = self.refine_cloud(cloud, graph, start, planes, params)
        # Off the lattice, a pixel takes the plane it lies closest to among its nearest
        # lattice nodes' labels (non-planar when the nearest node is): creases stay where the
        # planes meet, not on the lattice's steps.
        image, on_valid = cloud.propagate_pixels(labels, planes, graph=graph)
        # The fit runs on the normalised points of every valid pixel, which the cloud holds
        # already: a least-squares plane commutes with the similarity back to the camera.
        fitted, rmse, support = fit_planes_per_label(cloud.all_points, on_valid,
                                                     int(labels.max(initial=0)))
        return Reconstruction(frame=frame, labels=image,
                              planes=orient_towards_camera(cloud.plane_to_camera(fitted))
                              if len(fitted) else np.zeros((0, 4)),
                              rmse=rmse * cloud.scale, support=support,
                              timings=dict(rec.timings))


@hookimpl
def monoplane_register_refiners() -> list[type[Stage]]:
    """Register the graph refiner."""
    return [GraphCrfRefiner]
