"""The neighbourhood graph G = (P, E) of graph-cut RANSAC (paper §III-B1).

Built once per frame as an undirected k-nearest-neighbour graph over the normalised cloud; each
plane's graph cut then uses only the edges whose both ends are still unassigned
(:meth:`NeighbourGraph.subgraph`). Keeping the graph local (3D kNN rather than random edges)
is what keeps max-flow fast.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from monoplane.errors import InvalidInput


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
        ``indices[indptr[i]:indptr[i + 1]]`` (int64).
    tree : scipy.spatial.cKDTree
        KD-tree over the points the graph was built on.
    spacing : float
        Median distance from a point to its nearest other point, in the points' unit.
    cache : dict
        Per-edge arrays that stages derive from static point attributes (e.g. proximity
        weights), keyed by the stage; lives as long as the graph, i.e. one frame.
    """

    num_nodes: int
    edges: np.ndarray
    indptr: np.ndarray
    indices: np.ndarray
    tree: cKDTree
    spacing: float
    cache: dict = field(default_factory=dict, repr=False)
    _last_subgraph: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(
        default=None, init=False, repr=False, compare=False)

    @classmethod
    def build(cls, points: np.ndarray, k: int, tree: cKDTree | None = None) -> NeighbourGraph:
        """Connect every point to its ``k`` nearest neighbours (symmetrised, deduplicated).

        Parameters
        ----------
        points : numpy.ndarray
            (N, 3) float points (normalised RANSAC frame).
        k : int
            Neighbours per point, >= 1; capped at N - 1.
        tree : scipy.spatial.cKDTree, optional
            An existing KD-tree over exactly these points, to avoid building another.

        Returns
        -------
        NeighbourGraph
        """
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InvalidInput(f"points must have shape (N, 3), got {pts.shape}")
        if k < 1:
            raise InvalidInput(f"k must be at least 1, got {k}")
        n = pts.shape[0]
        if tree is None:
            tree = cKDTree(pts)
        kk = min(k, n - 1)
        if kk < 1:
            empty = np.zeros((0, 2), dtype=np.int64)
            return cls(n, empty, np.zeros(n + 1, dtype=np.int64), np.zeros(0, dtype=np.int64),
                       tree, 0.0)
        dist, nbr = tree.query(pts, k=kk + 1)
        # Column 0 is the point itself except among exact duplicates; drop self-loops anywhere.
        src = np.repeat(np.arange(n, dtype=np.int64), kk + 1)
        dst = nbr.ravel().astype(np.int64)
        keep = src != dst
        src, dst = src[keep], dst[keep]
        lo, hi = np.minimum(src, dst), np.maximum(src, dst)
        key = np.sort(lo * n + hi)
        key = key[np.r_[True, key[1:] != key[:-1]]]
        edges = np.stack([key // n, key % n], axis=1)
        both = np.concatenate([edges, edges[:, ::-1]])
        both = both[np.argsort(both[:, 0], kind="stable")]
        indptr = np.zeros(n + 1, dtype=np.int64)
        np.cumsum(np.bincount(both[:, 0], minlength=n), out=indptr[1:])
        spacing = float(np.median(dist[:, 1]))
        return cls(n, edges, indptr, both[:, 1].copy(), tree, spacing)

    @property
    def num_edges(self) -> int:
        """Number E of undirected edges."""
        return int(self.edges.shape[0])

    @property
    def mean_degree(self) -> float:
        """Mean number of neighbours per node, ``2E / N`` (0 for an empty graph)."""
        return 2.0 * self.num_edges / self.num_nodes if self.num_nodes else 0.0

    def largest_component(self, nodes: np.ndarray) -> np.ndarray:
        """Which of ``nodes`` lie in the largest connected component of their subgraph.

        Parameters
        ----------
        nodes : numpy.ndarray
            (M,) int64 distinct node indices.

        Returns
        -------
        numpy.ndarray
            (M,) bool, True on the nodes of the largest component of the subgraph induced by
            ``nodes`` (the lowest-numbered one among equally large components).
        """
        nodes = np.asarray(nodes, dtype=np.int64)
        return self.largest_component_within(nodes, np.ones(nodes.size, dtype=bool))

    def largest_component_within(self, pool: np.ndarray, members: np.ndarray) -> np.ndarray:
        """:meth:`largest_component` of ``pool[members]``, from the pool's (cached) subgraph.

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
        members = np.asarray(members, dtype=bool)
        count = int(members.sum())
        if count == 0:
            return np.zeros(0, dtype=bool)
        edges, _ = self.subgraph(pool)
        inside = members[edges[:, 0]] & members[edges[:, 1]]
        rank = np.cumsum(members) - 1
        ends = rank[edges[inside]]
        adj = coo_matrix((np.ones(ends.shape[0]), (ends[:, 0], ends[:, 1])),
                         shape=(count, count))
        _, comp = connected_components(adj, directed=False)
        return comp == np.argmax(np.bincount(comp))

    def neighbours(self, i: int) -> np.ndarray:
        """(deg,) int64 neighbours of node ``i``."""
        return self.indices[self.indptr[i]:self.indptr[i + 1]]

    def subgraph(self, pool: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Edges among a subset of nodes, renumbered to positions in ``pool``.

        The result for the last pool asked for is kept: the RANSAC driver labels one pool
        several times (local optimisation, component split) before it shrinks.

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
        last = self._last_subgraph
        if last is not None and np.array_equal(last[0], pool):
            return last[1], last[2]
        local = np.full(self.num_nodes, -1, dtype=np.int64)
        local[pool] = np.arange(pool.size, dtype=np.int64)
        mapped = local[self.edges]
        edge_ids = np.flatnonzero((mapped[:, 0] >= 0) & (mapped[:, 1] >= 0))
        edges = mapped[edge_ids]
        for a in (edges, edge_ids):
            a.flags.writeable = False
        self._last_subgraph = (pool.copy(), edges, edge_ids)
        return edges, edge_ids
