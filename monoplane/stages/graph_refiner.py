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
from typing import TYPE_CHECKING

import numpy as np

from monoplane.datamodel import Reconstruction, orient_towards_camera
from monoplane.errors import check_config
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.components import graph_components
from monoplane.geometry.graph import NeighbourGraph
from monoplane.geometry.planes import fit_planes_per_label
from monoplane.algorithm.graphcut import normal_costs, proximity_weights
from monoplane.hookspecs import hookimpl
from monoplane.jit import chunks, kernel, run_threaded
from monoplane.stages.base import ProximityAffinities, RansacParams, Refiner, Stage, param

if TYPE_CHECKING:
    from scipy.sparse import csr_matrix

#: Nodes per thread below which a mean-field iteration runs on one thread.
_THREADED_NODES = 4096


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
    max_jump: float = param(
        0.05, "image input: relative depth jump that cuts the pixel-grid graph")
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
            (self.rounds >= 1, "rounds must be >= 1"),
            (self.max_jump > 0, "max_jump must be positive"),
            (min(self.alpha_p2, self.alpha_c2, self.alpha_n2) > 0, "bandwidths must be > 0"),
            (0 <= self.min_support < 1, "min_support must lie in [0, 1)"),
            (self.min_support_points >= 3, "min_support_points must be at least 3"),
            (0 <= self.merge_angle_deg <= 90, "merge_angle_deg must lie in [0, 90]"),
            (self.merge_distance >= 0, "merge_distance must be >= 0"),
        ], prefix="refiner (graph-crf): ")


def _adjacency(graph: NeighbourGraph, weights: np.ndarray) -> csr_matrix:
    """Symmetric (N, N) sparse matrix of edge weights."""
    from scipy.sparse import coo_matrix  # only this refiner needs SciPy's sparse matrices

    i, j = graph.edges[:, 0], graph.edges[:, 1]
    n = graph.num_nodes
    return coo_matrix((np.r_[weights, weights], (np.r_[i, j], np.r_[j, i])),
                      shape=(n, n)).tocsr()


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
        Cloud of the frame's valid pixels, not subsampled.
    max_jump : float
        Relative jump threshold.
    """
    pixels, (h, w), _ = cloud.pixel_grid()
    index = np.full(h * w, -1, dtype=np.int64)
    index[pixels] = np.arange(cloud.size)
    # The cloud is centred on the scene; points are compared at their own depth scale.
    edges, gap, indptr, indices = _pixel_graph(index.reshape(h, w), cloud.points,
                                               cloud.center / cloud.scale, float(max_jump))
    spacing = float(np.median(gap)) if gap.size else 0.0
    # No point index: the grid gave the neighbours, and building one over every pixel would
    # cost more than the graph.
    return NeighbourGraph(cloud.size, edges, indptr, indices, None, spacing)


@kernel
def _shifted_energy(indptr: np.ndarray, indices: np.ndarray, data: np.ndarray, q: np.ndarray,
                    unary: np.ndarray, weight: np.float32, scale: np.float32, row0: int,
                    row1: int, out: np.ndarray) -> None:
    """One mean-field step's exponent for rows ``row0:row1`` into ``out`` ((row1 - row0, L)
    float32): ``scale (e - min_l e)`` with ``e = weight (W Q) + U``.

    ``W`` is the CSR matrix ``(indptr, indices, data)`` (float32 weights), ``Q`` and ``U`` are
    (N, L) float32. Every operation is float32 in the order of the NumPy/SciPy expression it
    replaces (``W @ Q`` accumulates each row's entries in storage order), so the result is
    the same to the bit.
    """
    labels = q.shape[1]
    for i in range(row0, row1):
        row = out[i - row0]
        row[:] = 0
        for jj in range(indptr[i], indptr[i + 1]):
            j = indices[jj]
            a = data[jj]
            for k in range(labels):
                row[k] += a * q[j, k]
        low = np.float32(np.inf)
        for k in range(labels):
            row[k] = row[k] * weight + unary[i, k]
            low = min(low, row[k])
        for k in range(labels):
            row[k] = (row[k] - low) * scale


@kernel
def _pixel_graph(index: np.ndarray, points: np.ndarray, shift: np.ndarray, max_jump: float
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`pixel_graph` of the (H, W) int64 node ``index`` of each pixel (-1: none).

    Nodes number the valid pixels in raster order, so the four forward neighbours of a
    pixel, taken in raster order (right, below left, below, below right), are larger nodes
    in ascending order: scanning the pixels gives the edges sorted by ``(i, j)``.

    Returns
    -------
    edges : numpy.ndarray
        (E, 2) int64 kept edges, ``i < j``, sorted.
    gap : numpy.ndarray
        (M,) float64 3D distance of every candidate pair, kept or not.
    indptr, indices : numpy.ndarray
        Adjacency: the neighbours of node ``i`` are its larger ones, ascending, then its
        smaller ones, ascending.
    """
    h, w = index.shape
    n = points.shape[0]
    edges = np.empty((4 * n, 2), dtype=np.int64)
    gap = np.empty(4 * n, dtype=np.float64)
    kept = pairs = 0
    for v in range(h):
        for u in range(w):
            a = index[v, u]
            if a < 0:
                continue
            # sqrt of the squares summed in order, as numpy's norm over an axis of 3.
            x = points[a, 0] + shift[0]
            y = points[a, 1] + shift[1]
            z = points[a, 2] + shift[2]
            reach = max_jump * max(np.sqrt(x * x + y * y + z * z), 1e-12)
            for dv, du in ((0, 1), (1, -1), (1, 0), (1, 1)):
                vv, uu = v + dv, u + du
                if vv >= h or not 0 <= uu < w:
                    continue
                b = index[vv, uu]
                if b < 0:
                    continue
                dx = points[a, 0] - points[b, 0]
                dy = points[a, 1] - points[b, 1]
                dz = points[a, 2] - points[b, 2]
                g = np.sqrt(dx * dx + dy * dy + dz * dz)
                gap[pairs] = g
                pairs += 1
                if g <= reach:
                    edges[kept, 0] = a
                    edges[kept, 1] = b
                    kept += 1
    edges = edges[:kept].copy()
    larger = np.zeros(n, dtype=np.int64)
    degree = np.zeros(n, dtype=np.int64)
    for e in range(kept):
        larger[edges[e, 0]] += 1
        degree[edges[e, 0]] += 1
        degree[edges[e, 1]] += 1
    indptr = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        indptr[i + 1] = indptr[i] + degree[i]
    first = indptr[:-1].copy()  # next free slot of each node's larger neighbours
    second = indptr[:-1] + larger  # ... and of its smaller ones
    indices = np.empty(2 * kept, dtype=np.int64)
    for e in range(kept):
        a, b = edges[e, 0], edges[e, 1]
        indices[first[a]] = b
        first[a] += 1
        indices[second[b]] = a
        second[b] += 1
    return edges, gap[:pairs].copy(), indptr, indices


class GraphCrfRefiner(Refiner):
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
        # image with 40 planes are the refiner's main memory traffic.
        points = cloud.points.astype(np.float32)
        normals_p = planes[:, :3].astype(np.float32)
        out = np.empty((cloud.size, planes.shape[0] + 1), dtype=np.float32)
        out[:, 0] = 1.0
        cost = out[:, 1:]
        np.matmul(points, normals_p.T, out=cost)
        cost += planes[:, 3].astype(np.float32)
        cost *= np.float32(1.0 / epsilon)
        np.square(cost, out=cost)
        if c.normal_weight > 0:  # the angles are only needed then
            cos = np.clip(cloud.normals.astype(np.float32) @ normals_p.T, -1.0, 1.0)
            cost += c.normal_weight * normal_costs(np.arccos(cos), params.epsilon_n)
        return out

    def _mean_field(self, unary: np.ndarray, adj: csr_matrix, labels: np.ndarray,
                    mean_degree: float) -> np.ndarray:
        c = self.config
        if c.iterations == 0 or unary.shape[1] < 2:
            return labels
        beta = c.beta / max(mean_degree, 1e-12)
        adj = adj.astype(np.float32)
        inv_t = np.float32(1.0 / c.temperature)
        q = np.zeros(unary.shape, dtype=np.float32)
        q[np.arange(labels.size), labels] = 1.0
        # "Non-planar" after RANSAC means no plane claimed the point, not evidence against
        # every plane: such points start from their data term alone, so a strip the greedy
        # search left over does not hold itself in place through the pairwise term.
        free = labels == 0
        if free.any():
            e = unary[free] - unary[free].min(axis=1, keepdims=True)
            q[free] = np.exp(-e * inv_t)
            q[free] /= q[free].sum(axis=1, keepdims=True)
        unary = np.ascontiguousarray(unary, dtype=np.float32)
        weight = np.float32(-beta)
        spans = chunks(labels.size, _THREADED_NODES)
        nxt = np.empty_like(q)

        def update(a: int, b: int) -> None:
            # Expected Potts cost of label l at i: Σ_j w_ij (1 - Q_j(l)) = deg_i - (W Q)_i(l);
            # deg_i is the same for every label and cancels in the softmax.
            part = nxt[a:b]
            _shifted_energy(adj.indptr, adj.indices, adj.data, q, unary, weight, -inv_t, a, b,
                            part)
            np.exp(part, out=part)
            part /= part.sum(axis=1, keepdims=True)

        # Rows are independent within an iteration: contiguous row ranges run on parallel
        # threads, each reading the last iteration's Q and writing its rows of the next.
        for _ in range(c.iterations):
            run_threaded([functools.partial(update, a, b) for a, b in spans])
            q, nxt = nxt, q
        return np.argmax(q, axis=1).astype(np.int32)

    def _components(self, graph: NeighbourGraph, labels: np.ndarray, min_size: int
                    ) -> np.ndarray:
        """Relabel every graph-connected region of one label as its own label 1..R."""
        i, j = graph.edges[:, 0], graph.edges[:, 1]
        same = (labels[i] == labels[j]) & (labels[i] > 0)
        n = labels.size
        comp = graph_components(n, np.stack([i[same], j[same]], axis=1))
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
        a, b = labels[graph.edges[:, 0]], labels[graph.edges[:, 1]]
        touch = (a > 0) & (b > 0) & (a != b)
        pairs = np.unique(np.sort(np.stack([a[touch], b[touch]], axis=1), axis=1), axis=0)
        if pairs.size == 0:
            return labels
        cos_max = math.cos(math.radians(c.merge_angle_deg))
        tol2 = (c.merge_distance * epsilon) ** 2
        order = np.argsort(labels, kind="stable")
        counts = np.bincount(labels, minlength=num + 1)
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

    def _refit_round(self, cloud: PlaneCloud, adj: csr_matrix, graph: NeighbourGraph,
                     labels: np.ndarray, planes: np.ndarray, params: RansacParams,
                     epsilon: float) -> tuple[np.ndarray, np.ndarray]:
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

    def refine_cloud(self, cloud: PlaneCloud, graph: NeighbourGraph, labels: np.ndarray,
                     planes: np.ndarray, params: RansacParams) -> tuple[np.ndarray, np.ndarray]:
        """See :meth:`monoplane.stages.base.Refiner.refine_cloud`."""
        c = self.config
        labels = np.asarray(labels, dtype=np.int32)
        planes = np.asarray(planes, dtype=np.float64).reshape(-1, 4)
        if planes.shape[0] == 0:
            return labels, planes
        weights = proximity_weights(cloud.points, graph.edges, cloud.normals, cloud.colors,
                                    *c.affinities())
        adj = _adjacency(graph, weights)
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
        cloud = PlaneCloud.from_frame(frame)
        graph = pixel_graph(cloud, self.config.max_jump)
        pixels = cloud.pixel_grid()[0]
        start = rec.labels.ravel()[pixels]
        planes = cloud.plane_to_normalised(rec.planes) if rec.num_planes else np.zeros((0, 4))
        labels, _ = self.refine_cloud(cloud, graph, start, planes, params)
        image = np.zeros(frame.height * frame.width, dtype=np.int32)
        image[pixels] = labels
        params, rmse, support = fit_planes_per_label(frame.points().reshape(-1, 3), image,
                                                     int(labels.max(initial=0)))
        return Reconstruction(frame=frame, labels=image.reshape(frame.shape),
                              planes=orient_towards_camera(params) if len(params)
                              else np.zeros((0, 4)),
                              rmse=rmse, support=support, timings=dict(rec.timings))


@hookimpl
def monoplane_register_refiners() -> list[type[Stage]]:
    """Register the graph refiner."""
    return [GraphCrfRefiner]
