"""The neighbourhood graph G = (P, E) of graph-cut RANSAC (paper §III-B1).

Built once per frame as an undirected k-nearest-neighbour graph over the normalised cloud; each
plane's graph cut then uses only the edges whose both ends are still unassigned
(:meth:`NeighbourGraph.subgraph`). Keeping the graph local (3D kNN rather than random edges)
is what keeps max-flow fast.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.geometry.components import largest_component
from monoplane.geometry.lattice import pixel_grid_edges, turn_scale
from monoplane.geometry.neighbours import PointIndex
from monoplane.geometry.propagation import SampleImage, image_knn
from monoplane.jit import chunks, inline, kernel, run_threaded

#: Nodes per thread below which the edge list is built on one thread.
THREADED_NODES = 4096
#: Edges per chunk below which the lattice graph's turn weights are computed on one thread.
THREADED_EDGES = 10_000


@dataclass
class NeighbourGraph:
    """Undirected kNN graph over N points.

    Attributes
    ----------
    num_nodes : int
        N.
    edges : numpy.ndarray
        (E, 2) int64 unique undirected edges ``(i, j)`` with ``i < j``, sorted by ``(i, j)``.
    indptr, indices : numpy.ndarray
        Symmetric CSR adjacency: the neighbours of node ``i`` are
        ``indices[indptr[i]:indptr[i + 1]]`` (int64, ascending). Given to the constructor, or
        ``None`` there: then built from ``edges`` when first asked for (the graph cuts need
        only the edge list; the RANSAC builds these on its background thread).
    tree : PointIndex or None
        Nearest-neighbour index over the points the graph was built on; None for a graph
        that needed none (a kNN graph found through the image, the lattice graph).
    spacing : float
        Median distance from a point to its nearest other point, in the points' unit.
    affinity_scale : numpy.ndarray or None
        (E,) factor in [0, 1] on each edge's affinity in the proximity labeler's cut cost
        (:func:`monoplane.algorithm.graph_costs.proximity_weights`), or None: 1 for all
        (the lattice graph's, :meth:`from_lattice` with ``turn_scale_deg``).
    normal_angle : numpy.ndarray or None
        (E,) angle in radians between the unit normals of each edge's ends, when the graph
        computed it (:meth:`from_lattice` with ``turn_scale_deg``), else None: the proximity
        labeler's normal affinity reads it instead of taking every arccos again. These are
        the angles of the normals given to :meth:`from_lattice`; the proximity labeler
        assumes those are its cloud's normals, so build the graph from the cloud's own.
    """

    num_nodes: int
    edges: np.ndarray
    _indptr: np.ndarray | None
    _indices: np.ndarray | None
    tree: PointIndex | None
    spacing: float
    affinity_scale: np.ndarray | None = None
    normal_angle: np.ndarray | None = None
    _last_subgraph: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(
        default=None, init=False, repr=False, compare=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, init=False, repr=False,
                                  compare=False)

    @property
    def indptr(self) -> np.ndarray:
        """(N + 1,) int64 row starts of the adjacency (see the class docstring)."""
        return self.adjacency()[0]

    @property
    def indices(self) -> np.ndarray:
        """(2E,) int64 neighbours of each row of the adjacency, ascending."""
        return self.adjacency()[1]

    def adjacency(self) -> tuple[np.ndarray, np.ndarray]:
        """``(indptr, indices)``, built from the edges on first use (thread-safe)."""
        with self._lock:
            if self._indptr is None or self._indices is None:
                self._indptr, self._indices = _adjacency(self.num_nodes, self.edges)
            return self._indptr, self._indices

    @classmethod
    def build(cls, points: np.ndarray, k: int,
              tree: PointIndex | Callable[[], PointIndex] | None = None,
              image: SampleImage | None = None) -> NeighbourGraph:
        """Connect every point to its ``k`` nearest neighbours (symmetrised, deduplicated).

        Parameters
        ----------
        points : numpy.ndarray
            (N, 3) float points (normalised RANSAC frame).
        k : int
            Neighbours per point, >= 1; capped at N - 1.
        tree : PointIndex or callable, optional
            An index over exactly these points, to avoid building another, or a function
            returning it (called only when the index is needed: a cloud's cached index,
            :attr:`monoplane.geometry.cloud.PlaneCloud.tree`).
        image : SampleImage, optional
            Where the points lie in their frame's image: their neighbours are then found
            through the image (:func:`~monoplane.geometry.propagation.image_knn`), and only
            the few it leaves in the point index (built for them when ``tree`` is None). The
            same graph either way.

        Returns
        -------
        NeighbourGraph
            Its ``tree`` is None when the image found every point's neighbours and no
            index was given (a function returning one is then not called).
        """
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InvalidInput(f"points must have shape (N, 3), got {pts.shape}")
        if k < 1:
            raise InvalidInput(f"k must be at least 1, got {k}")
        n = pts.shape[0]
        given = tree if isinstance(tree, PointIndex) else None  # not through a function
        if given is not None and given.n != n:
            raise InvalidInput(f"the index holds {given.n} points, not the graph's {n}")
        if image is not None and image.pixels.shape != (n,):
            raise InvalidInput(f"the image holds {image.pixels.shape[0]} samples, not the "
                               f"graph's {n} points")
        kk = min(k, n - 1)
        if kk < 1:
            empty = np.zeros((0, 2), dtype=np.int64)
            return cls(n, empty, np.zeros(n + 1, dtype=np.int64), np.zeros(0, dtype=np.int64),
                       _index(pts, tree) if image is None else given, 0.0)
        missed = np.arange(n)  # the points the index answers for: all, without an image
        if image is not None:
            dist, nbr, missed = image_knn(np.ascontiguousarray(pts), image, kk + 1)
        if not missed.size:  # the image found every point's neighbours
            np.sqrt(dist, out=dist)
        else:
            given = _index(pts, tree)
            if missed.size == n:  # no image, or the image search gave up
                dist, nbr = given.query_indexed(kk + 1)
            else:
                dist[missed] = 0.0  # rows the point index fills in below
                np.sqrt(dist, out=dist)
                dist[missed], nbr[missed] = given.query(pts[missed], kk + 1)
        # Each thread lists the edges whose smaller end lies in its range of nodes; in range
        # order they are the sorted edge list.
        parts = run_threaded([lambda a=a, b=b: _knn_edges(nbr, a, b)
                              for a, b in chunks(n, THREADED_NODES)])
        edges = np.concatenate(parts) if len(parts) > 1 else parts[0]
        spacing = float(np.median(dist[:, 1]))
        return cls(n, edges, None, None, given, spacing)

    @classmethod
    def from_lattice(cls, points: np.ndarray, lattice: np.ndarray, shift: np.ndarray,
                     max_jump: float, normals: np.ndarray | None = None,
                     max_turn_deg: float | None = None, turn_scale_deg: float | None = None
                     ) -> NeighbourGraph:
        """The 8-neighbourhood of points sampled on a regular pixel lattice, cut at depth jumps
        and, optionally, cut or weakened where the normals turn.

        On an organised frame sampled on a lattice the lattice already says who neighbours
        whom: one scan in raster order (:func:`pixel_grid_edges`) replaces the kNN query,
        and builds the adjacency with the sorted edges.

        Parameters
        ----------
        points : numpy.ndarray
            (N, 3) float64 normalised points, in ascending pixel order.
        lattice : numpy.ndarray
            (R, C) int64 point at each lattice node, -1 where there is none
            (:attr:`monoplane.geometry.cloud.PlaneCloud.lattice`): every point once, in
            raster order.
        shift : numpy.ndarray
            (3,) float64 camera centre's offset in the normalised frame (``center / scale``):
            a jump is judged relative to the points' distance from the camera.
        max_jump : float
            Two lattice neighbours are linked unless their 3D distance exceeds ``max_jump``
            times their distance from the camera.
        normals : numpy.ndarray, optional
            (N, 3) float64 unit normals of the points; needed with ``max_turn_deg``.
        max_turn_deg : float, optional
            Two lattice neighbours whose normals differ by more than this angle in degrees are
            not linked either: a curved surface (its normals turn from sample to sample) is
            then no bridge for a plane's labels, a flat one stays linked. None: no such cut.
        turn_scale_deg : float, optional
            σ in degrees: each kept pair's :attr:`affinity_scale` is ``exp(-t² / 2σ²)``, t the
            angle between its normals, so that a plane's labels spread less readily where the
            normals turn; unlike ``max_turn_deg`` no pair is cut for the noise of sensor or
            network normals. Needs ``normals``. None: no :attr:`affinity_scale` (nor
            :attr:`normal_angle`).

        Returns
        -------
        NeighbourGraph
            Without a point index; ``spacing`` is the median length of the lattice pairs.
        """
        lattice = np.ascontiguousarray(lattice, dtype=np.int64)
        nodes = lattice[lattice >= 0]
        if lattice.ndim != 2 or not np.array_equal(nodes, np.arange(points.shape[0])):
            raise InvalidInput(f"the lattice must hold each of the {points.shape[0]} points "
                               "once, in raster order")
        points = np.ascontiguousarray(points, dtype=np.float64)
        uses_normals = max_turn_deg is not None or turn_scale_deg is not None
        if uses_normals and (normals is None or np.shape(normals) != points.shape):
            raise InvalidInput("max_turn_deg and turn_scale_deg need (N, 3) normals of the "
                               f"{points.shape[0]} points")
        unit = np.ascontiguousarray(normals if uses_normals else np.zeros_like(points),
                                    dtype=np.float64)
        # cos_min -2: every pair agrees.
        cos_min = -2.0 if max_turn_deg is None else float(np.cos(np.radians(max_turn_deg)))
        edges, gap, indptr, indices = pixel_grid_edges(
            lattice, points, np.asarray(shift, dtype=np.float64), float(max_jump), unit, cos_min)
        # The pairs' median length and the turn weights, each edge's alone, in chunks on
        # parallel threads: they lie on the path to the first plane's labelling.
        tasks: list[Callable[[], Any]] = [lambda: float(np.median(gap)) if gap.size else 0.0]
        if turn_scale_deg is not None:
            sigma = float(turn_scale_deg)
            tasks += [partial(turn_scale, edges[a:b], unit, sigma)
                      for a, b in chunks(edges.shape[0], THREADED_EDGES, per_thread=2)]
        spacing, *parts = run_threaded(tasks)
        scale = angle = None
        if parts:
            scale, angle = (np.concatenate(a) if len(a) > 1 else a[0]
                            for a in zip(*parts, strict=True))
        return cls(int(points.shape[0]), edges, indptr, indices, None, spacing, scale, angle)

    def weighted_adjacency(self, weights: np.ndarray
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Symmetric CSR matrix of per-edge weights, every row's columns ascending.

        Parameters
        ----------
        weights : numpy.ndarray
            (E,) weight of each edge of :attr:`edges`.

        Returns
        -------
        indptr, indices, data : numpy.ndarray
            (N + 1,) int64, (2E,) int64 and (2E,) float32: the entries of row ``i`` are
            ``indices[indptr[i]:indptr[i + 1]]`` with weights ``data[...]`` (the layout of
            ``scipy.sparse.csr_matrix`` with sorted indices).
        """
        w = np.asarray(weights, dtype=np.float32)
        if w.shape != (self.num_edges,):
            raise InvalidInput(f"weights must be ({self.num_edges},), got {w.shape}")
        return _weighted_adjacency(self.num_nodes, self.edges, w)

    @property
    def num_edges(self) -> int:
        """Number E of undirected edges."""
        return int(self.edges.shape[0])

    @property
    def mean_degree(self) -> float:
        """Mean number of neighbours per node, ``2E / N`` (0 for an empty graph)."""
        return 2.0 * self.num_edges / self.num_nodes if self.num_nodes else 0.0

    def largest_component_within(self, pool: np.ndarray, members: np.ndarray) -> np.ndarray:
        """Which of ``pool[members]`` lie in the largest connected component of their subgraph.

        The subgraph comes from the pool's (cached, see :meth:`subgraph`) one, so asking again
        with fewer members of the same pool costs no new subgraph; pass ``members`` all True
        for the component of a plain node subset.

        Parameters
        ----------
        pool : numpy.ndarray
            (M,) int64 distinct node indices.
        members : numpy.ndarray
            (M,) bool selection of the pool.

        Returns
        -------
        numpy.ndarray
            (K,) bool over ``pool[members]`` (K = ``members.sum()``), True on the largest
            connected component of the subgraph they induce (lowest-numbered on ties).
        """
        members = np.ascontiguousarray(members, dtype=bool)
        edges, _ = self.subgraph(pool)
        return largest_component(members, edges)

    def neighbours(self, i: int) -> np.ndarray:
        """(deg,) int64 neighbours of node ``i``."""
        return self.indices[self.indptr[i]:self.indptr[i + 1]]

    def subgraph(self, pool: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Edges among a subset of nodes, renumbered to positions in ``pool``.

        The result for the last pool asked for is kept: the RANSAC driver labels one pool
        several times (local optimisation, component split) before it shrinks, and the
        subgraph of a pool within the last one is taken from the last one's
        (:func:`shrink_subgraph`).

        Parameters
        ----------
        pool : numpy.ndarray
            (M,) int64 distinct node indices.

        Returns
        -------
        edges : numpy.ndarray
            (E', 2) int64 edges ``(a, b)`` with ``pool[a]``–``pool[b]`` an edge of the graph,
            in the order of :attr:`edges` (read-only).
        edge_ids : numpy.ndarray
            (E',) int64 rows of :attr:`edges` they come from (to index per-edge caches;
            read-only).
        """
        pool = np.asarray(pool, dtype=np.int64)
        # One snapshot of the cache: the RANSAC asks from its labeler's background thread and
        # from its own, one after the other; a race would only compute a subgraph twice.
        last = self._last_subgraph
        if last is not None and np.array_equal(last[0], pool):
            return last[1], last[2]
        shrunk = None if last is None else shrink_subgraph(last[0], pool, last[1])
        if shrunk is not None:
            # The RANSAC's pool only shrinks: one pass over the last pool's subgraph.
            edges, rows = shrunk
            edge_ids = last[2][rows]
        elif pool.size == self.num_nodes and _ascending(pool):
            # Every node, in order (the first plane's pool): the graph itself.
            edges, edge_ids = self.edges.view(), np.arange(self.num_edges, dtype=np.int64)
        else:
            edges, edge_ids = _pool_edges(self.num_nodes, self.edges, pool)
        for a in (edges, edge_ids):
            a.flags.writeable = False
        self._last_subgraph = (pool.copy(), edges, edge_ids)
        return edges, edge_ids


def _index(points: np.ndarray, tree: PointIndex | Callable[[], PointIndex] | None
           ) -> PointIndex:
    """The point index over ``points`` that :meth:`NeighbourGraph.build` was given, from the
    function that provides it, or built now."""
    if tree is None:
        return PointIndex(points)
    return tree if isinstance(tree, PointIndex) else tree()


def shrink_subgraph(old_pool: np.ndarray, pool: np.ndarray, edges: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray] | None:
    """A pool's subgraph from the subgraph of a larger pool, without the whole graph.

    The RANSAC's pool only shrinks (the inliers of each plane leave it), so the edges among
    the new pool are those of the last pool's subgraph whose ends both stayed: one pass over
    that subgraph instead of over every edge of the frame's graph. The result is the
    :meth:`monoplane.geometry.graph.NeighbourGraph.subgraph` of ``pool``, row for row.

    Parameters
    ----------
    old_pool, pool : numpy.ndarray
        (M,) and (M',) int64 ascending node indices.
    edges : numpy.ndarray
        (E, 2) int64 subgraph of ``old_pool``, in ``old_pool`` positions, in graph order.

    Returns
    -------
    tuple or None
        ``(edges', rows)``: the (E', 2) int64 subgraph of ``pool`` in ``pool`` positions and
        the (E',) int64 rows of ``edges`` it keeps (to carry per-edge arrays along); None when
        ``pool`` is not a subset of ``old_pool``.
    """
    old = np.ascontiguousarray(old_pool, dtype=np.int64)
    new = np.ascontiguousarray(pool, dtype=np.int64)
    within, remap = _subset_positions(old, new)
    if not within:
        return None
    return _kept_edges(np.ascontiguousarray(edges, dtype=np.int64), remap)


@kernel
def _subset_positions(old: np.ndarray, new: np.ndarray) -> tuple[bool, np.ndarray]:
    """Whether the (M',) int64 ``new`` is found in the (M,) int64 ``old`` in order (both
    ascending: a subset), and the (M,) int64 position in ``new`` of each entry of ``old``
    (-1: gone)."""
    remap = np.full(old.shape[0], -1, dtype=np.int64)
    i = 0
    for k in range(new.shape[0]):
        while i < old.shape[0] and old[i] != new[k]:
            i += 1
        if i == old.shape[0]:
            return False, remap
        remap[i] = k
        i += 1
    return True, remap


@kernel
def _kept_edges(edges: np.ndarray, remap: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (E', 2) edges whose ends both have a position in ``remap``, renumbered, and their
    (E',) rows."""
    # One pass into buffers of the input's size, returned as views of their heads: pages of
    # an empty buffer that are never written to are never touched, so the unused tail costs
    # nothing (a counting pass first would cost a second read of every edge).
    out = np.empty((edges.shape[0], 2), dtype=np.int64)
    rows = np.empty(edges.shape[0], dtype=np.int64)
    count = 0
    for e in range(edges.shape[0]):
        a, b = remap[edges[e, 0]], remap[edges[e, 1]]
        if a >= 0 and b >= 0:
            out[count, 0] = a
            out[count, 1] = b
            rows[count] = e
            count += 1
    return out[:count], rows[:count]


@kernel
def _knn_edges(nbr: np.ndarray, lo_start: int, lo_stop: int) -> np.ndarray:
    """Unique undirected edges of kNN lists whose smaller end lies in ``[lo_start, lo_stop)``.

    ``nbr`` is the (N, K) int64 neighbour table of a kNN query (a row may contain the point
    itself, anywhere among exact duplicates). Returns the (E, 2) edges ``i < j`` sorted by
    ``(i, j)`` without self-loops or repeats. A bucket per smaller end, sorted in place,
    replaces a global sort of all pairs; the rows from ``lo_start`` on are read (a row before
    it has a smaller end before it too), only the range's buckets filled.
    """
    n, k = nbr.shape
    width = lo_stop - lo_start
    start = np.zeros(width + 1, dtype=np.int64)
    for i in range(lo_start, n):
        for c in range(k):
            j = nbr[i, c]
            lo = min(i, j)
            if j != i and lo_start <= lo < lo_stop:
                start[lo - lo_start + 1] += 1
    for i in range(width):
        start[i + 1] += start[i]
    bucket = np.empty(start[width], dtype=np.int64)
    fill = start[:width].copy()
    for i in range(lo_start, n):
        for c in range(k):
            j = nbr[i, c]
            lo = min(i, j)
            if j != i and lo_start <= lo < lo_stop:
                bucket[fill[lo - lo_start]] = max(i, j)
                fill[lo - lo_start] += 1
    edges = np.empty((start[width], 2), dtype=np.int64)
    count = 0
    for r in range(width):
        a, b = start[r], start[r + 1]
        for x in range(a + 1, b):  # insertion sort: buckets hold about K entries
            v = bucket[x]
            y = x - 1
            while y >= a and bucket[y] > v:
                bucket[y + 1] = bucket[y]
                y -= 1
            bucket[y + 1] = v
        for x in range(a, b):
            if x == a or bucket[x] != bucket[x - 1]:
                edges[count, 0] = lo_start + r
                edges[count, 1] = bucket[x]
                count += 1
    return edges[:count].copy()


@inline
def _row_starts(n: int, edges: np.ndarray) -> np.ndarray:
    """(N + 1,) int64 CSR row starts of the symmetric adjacency of (E, 2) edges: each edge
    counts once in the row of each end."""
    indptr = np.zeros(n + 1, dtype=np.int64)
    for e in range(edges.shape[0]):
        indptr[edges[e, 0] + 1] += 1
        indptr[edges[e, 1] + 1] += 1
    for i in range(n):
        indptr[i + 1] += indptr[i]
    return indptr


@kernel
def _adjacency(n: int, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric CSR adjacency ``indptr`` (N + 1,), ``indices`` (2E,) of (E, 2) int64 edges
    ``i < j`` sorted by ``(i, j)``, every node's neighbours in ascending order."""
    indptr = _row_starts(n, edges)
    indices = np.empty(2 * edges.shape[0], dtype=np.int64)
    pos = indptr[:n].copy()
    # Edges come sorted by (lo, hi): each row receives its smaller neighbours (as hi) before
    # its larger ones (as lo), both ascending, so rows come out sorted.
    for e in range(edges.shape[0]):
        lo, hi = edges[e, 0], edges[e, 1]
        indices[pos[lo]] = hi
        pos[lo] += 1
        indices[pos[hi]] = lo
        pos[hi] += 1
    return indptr, indices


@kernel
def _weighted_adjacency(n: int, edges: np.ndarray, weights: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_adjacency` of the sorted (E, 2) int64 edges, with their (E,) float32 weights."""
    indptr = _row_starts(n, edges)
    indices = np.empty(2 * edges.shape[0], dtype=np.int64)
    data = np.empty(2 * edges.shape[0], dtype=np.float32)
    pos = indptr[:n].copy()
    for e in range(edges.shape[0]):
        lo, hi = edges[e, 0], edges[e, 1]
        indices[pos[lo]] = hi
        data[pos[lo]] = weights[e]
        pos[lo] += 1
        indices[pos[hi]] = lo
        data[pos[hi]] = weights[e]
        pos[hi] += 1
    return indptr, indices, data


@kernel
def _ascending(values: np.ndarray) -> bool:
    """Whether a (M,) int64 array is strictly increasing."""
    for i in range(1, values.shape[0]):
        if values[i] <= values[i - 1]:
            return False
    return True


def _pool_edges(num_nodes: int, edges: np.ndarray, pool: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """(E', 2) edges among the (M,) ``pool`` in pool positions and their (E',) rows."""
    local = np.full(num_nodes, -1, dtype=np.int64)
    local[pool] = np.arange(pool.shape[0], dtype=np.int64)
    return _kept_edges(edges, local)
