"""Exact k-nearest-neighbour queries over a fixed 3D point set, on SciPy's ``cKDTree``.

RANSAC needs one index per frame for three query patterns: every point's k nearest neighbours
(the graph-cut neighbourhood graph), the few nearest samples of the pixels that propagation
cannot settle from the image, and the NAPSAC sampler's neighbourhoods. :class:`PointIndex`
serves all three with the call convention of :meth:`scipy.spatial.cKDTree.query`.

Open3D's ``core.nns.NearestNeighborSearch`` (nanoflann) was measured against ``cKDTree`` on the
kNN graph of the 20 000 points of a bench frame (k = 9, index build included): 27-28 ms of CPU
time for both. ``cKDTree`` is used because importing Open3D costs about 2.2 s of CPU per
process (it loads its ML datasets module, hence scikit-learn, and its Plotly visualiser); every
worker process of the multi-view and batch pools paid it before its first frame. Queries run
in float64: in float32 the rounding of the normalised points breaks exact distance ties
differently when the depth's unit changes, and a frame in millimetres must give the labels it
gives in metres.
"""

from __future__ import annotations

import numpy as np

from monoplane.errors import InvalidInput


class PointIndex:
    """KD-tree over (N, 3) points for exact k-nearest-neighbour queries.

    Parameters
    ----------
    points : numpy.ndarray
        (N, 3) float points, any frame and unit.
    """

    def __init__(self, points: np.ndarray) -> None:
        from scipy.spatial import cKDTree

        pts = np.asarray(points)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InvalidInput(f"a point index needs (N, 3) points, got {pts.shape}")
        self.n = int(pts.shape[0])
        self._tree = cKDTree(np.ascontiguousarray(pts, dtype=np.float64)) if self.n else None

    def query(self, queries: np.ndarray, k: int = 1,
              distance_upper_bound: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest indexed points of each query point, nearest first.

        Parameters
        ----------
        queries : numpy.ndarray
            (Q, 3) points in the index's frame.
        k : int
            Neighbours per query, >= 1.
        distance_upper_bound : float
            Neighbours farther than this are not returned.

        Returns
        -------
        dist : numpy.ndarray
            (Q, k) float64 Euclidean distances; ``inf`` where fewer than k points lie within
            the bound (or fewer than k are indexed).
        idx : numpy.ndarray
            (Q, k) int64 indices into the indexed points; ``N`` where ``dist`` is ``inf``.
        """
        if k < 1:
            raise InvalidInput(f"k must be at least 1, got {k}")
        q = np.ascontiguousarray(np.asarray(queries).reshape(-1, 3), dtype=np.float64)
        dist = np.full((q.shape[0], k), np.inf)
        idx = np.full((q.shape[0], k), self.n, dtype=np.int64)
        kk = min(k, self.n)
        if q.shape[0] and self._tree is not None:
            d, found = self._tree.query(q, k=kk, distance_upper_bound=distance_upper_bound)
            dist[:, :kk] = np.asarray(d).reshape(-1, kk)
            idx[:, :kk] = np.asarray(found).reshape(-1, kk)
        return dist, idx
