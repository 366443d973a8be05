"""Orienting estimated normals of a point cloud: the viewpoint where it sees, the surface elsewhere.

PCA normals have no sign; the sampler, scorer and labeler compare signed normals, so the points
of one face must agree. Turning every normal towards a viewpoint is right for a single scan,
whose sensor sees every point, but wrong wherever the viewpoint lies on or near a point's
tangent plane: a box whose corner sits at the origin (the default viewpoint) has three faces
through it, and on those the sign flips at random from point to point, so each face breaks
into pieces. Orienting over the surface (Hoppe et al. 1992) needs no viewpoint but is slow in
Open3D (``orient_normals_consistent_tangent_plane``, about 11 s for 20 000 points).

:func:`orient_normals` does both in one spanning tree. The kNN graph's edges cost
``1 − |n_i · n_j|`` (cheap between parallel normals, so orientation travels along smooth
surfaces before it crosses a crease); a virtual root is joined at no cost to every point that
sees the viewpoint clearly (the line of sight meets its tangent plane at ``min_view_angle_deg``
or more, and the viewpoint lies ``min_view_spacings`` point spacings or more off that plane),
with that point's viewpoint sign. The minimum spanning tree from the root then orients every
point: a clear point by the viewpoint, as before, and an unclear one as its tree parent, i.e.
along the smoothest path from a clear point. A connected part with no clear point at all is
oriented from its first point, consistently over its surface.

Cost: one kNN query and one minimum spanning tree (SciPy), about 0.1 s for 20 000 points.
"""

from __future__ import annotations

import numpy as np

from monoplane.geometry.neighbours import PointIndex


def orient_normals(points: np.ndarray, normals: np.ndarray, viewpoint: np.ndarray,
                   knn: int = 10, min_view_angle_deg: float = 5.0,
                   min_view_spacings: float = 10.0) -> np.ndarray:
    """Sign unit normals consistently: towards ``viewpoint`` where it sees, over the surface
    elsewhere.

    Parameters
    ----------
    points : numpy.ndarray
        (N, 3) points, any frame and unit.
    normals : numpy.ndarray
        (N, 3) unit normals (signs arbitrary) in the points' frame.
    viewpoint : numpy.ndarray
        (3,) sensor position in the points' frame.
    knn : int
        Neighbours per point of the graph orientation travels over.
    min_view_angle_deg, min_view_spacings : float
        A point sees the viewpoint clearly when the line of sight makes at least this angle
        with its tangent plane and the viewpoint lies at least this many point spacings
        (the median distance to the nearest other point) off that plane.

    Returns
    -------
    numpy.ndarray
        (N, 3) float64 ``normals`` with some rows negated.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, minimum_spanning_tree

    pts = np.asarray(points, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    n = len(pts)
    if n == 0:
        return nrm.copy()
    sight = np.asarray(viewpoint, dtype=np.float64) - pts
    along = np.einsum("ij,ij->i", sight, nrm)
    towards = np.where(along < 0, -1.0, 1.0)
    if n < 2:
        return nrm * towards[:, None]
    k = min(knn, n - 1)
    gaps, nbr = PointIndex(pts).query_indexed(k + 1)
    # Clear: the line of sight meets the tangent plane steeply, and the viewpoint lies well off
    # it (many point spacings), so that a normal's estimation error cannot flip the sign: near
    # a viewpoint that sits on the surface both fail.
    spacing = float(np.median(gaps[:, 1]))
    dist = np.linalg.norm(sight, axis=1)
    clear = ((np.abs(along) >= np.sin(np.radians(min_view_angle_deg)) * dist)
             & (np.abs(along) >= min_view_spacings * spacing))
    if clear.all():
        return nrm * towards[:, None]
    src = np.repeat(np.arange(n), k + 1)
    dst = nbr.ravel()
    keep = (dst < n) & (dst != src)
    src, dst = src[keep], dst[keep]
    # A zero weight would read as "no edge": every cost gets a small floor.
    cost = 1.0 - np.abs(np.einsum("ij,ij->i", nrm[src], nrm[dst])) + 1e-6
    root = n  # the virtual root, joined to the clear points
    seeds = np.flatnonzero(clear)
    rows = np.concatenate([src, np.full(seeds.size, root)])
    cols = np.concatenate([dst, seeds])
    vals = np.concatenate([cost, np.full(seeds.size, 1e-9)])
    graph = coo_matrix((vals, (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    tree = minimum_spanning_tree(graph)
    tree = tree + tree.T
    sign = np.zeros(n + 1)
    start = root
    while True:
        sign[start] = 1.0
        order, parent = breadth_first_order(tree, start, directed=False)
        _propagate_signs(order, parent, root, towards, nrm, sign)
        left = np.flatnonzero(sign[:n] == 0)
        if left.size == 0:
            break
        start = int(left[0])  # a connected part with no clear point
    return nrm * sign[:n, None]


def _propagate_signs(order: np.ndarray, parent: np.ndarray, root: int, towards: np.ndarray,
                     normals: np.ndarray, sign: np.ndarray) -> None:
    """Give each node of a breadth-first ``order`` its sign from its tree ``parent`` (in
    place): the viewpoint's sign ``towards`` under the virtual ``root``, else the parent's
    sign, negated where the two normals point apart. One breadth-first level at a time, since
    every parent of a level is signed in an earlier one."""
    nodes = order[1:]
    depth = np.zeros(len(sign), dtype=np.int64)
    for node in nodes:  # integer work only; breadth-first order lists parents first
        depth[node] = depth[parent[node]] + 1
    level = depth[nodes]  # non-decreasing along a breadth-first order
    bounds = np.searchsorted(level, np.arange(1, level.max(initial=0) + 2))
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        lv = nodes[a:b]
        par = parent[lv]
        under_root = par == root
        agree = np.einsum("ij,ij->i", normals[lv], normals[np.where(under_root, lv, par)])
        sign[lv] = np.where(under_root, towards[np.minimum(lv, len(towards) - 1)],
                            sign[par] * np.where(agree >= 0, 1.0, -1.0))
