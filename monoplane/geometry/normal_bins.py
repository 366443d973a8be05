"""Unit normals grouped by direction on the cells of a cube map.

A cost that charges the full price to every point whose normal lies farther than ε_n from a
hypothesis' model normal (the ``msac-normal`` scorer's) need not visit a cell whose whole cone
of directions lies that far: its points are counted, not visited
(:func:`monoplane.geometry.hypotheses.binned_costs`). :func:`bin_by_normal` groups the points
by cell and :func:`cell_reach` gives each cell's centre and the cosine below which it is
skipped.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from monoplane.jit import inline, kernel

#: Cells per cube-map face side of the normal directions :func:`bin_by_normal` groups by.
NORMAL_CELLS = 4
#: Angle (radians) added to a cell's radius before its points are counted instead of visited:
#: far wider than the rounding of a cosine, so no point the full test would visit is skipped.
_SKIP_MARGIN = 1e-6


class BinnedPoints(NamedTuple):
    """Points grouped by normal direction (:func:`bin_points`), as
    :func:`monoplane.geometry.hypotheses.binned_costs` and the compiled search score them."""

    coords: np.ndarray
    """(6, K) float64 x, y, z, nx, ny, nz of the points, ordered by cell."""
    start: np.ndarray
    """(C + 1,) int64 start of each cell's run in ``coords``."""
    centres: np.ndarray
    """(C, 3) float64 unit centre direction of each cell."""
    cos_reach: np.ndarray
    """(C,) float64 cosine of each cell's angular radius plus ε_n (plus a margin)."""


@inline
def _cell_of(normals: np.ndarray, p: int, cells: int) -> int:
    """Cube-map cell of ``normals[p]`` (see :func:`bin_by_normal`)."""
    axis = 0
    for k in range(1, 3):
        if abs(normals[p, k]) > abs(normals[p, axis]):
            axis = k
    top = normals[p, axis]
    a = 1 if axis == 0 else 0
    b = 1 if axis == 2 else 2
    scale = 1.0 / abs(top) if top != 0.0 else 0.0
    iu = min(max(int((normals[p, a] * scale + 1.0) * 0.5 * cells), 0), cells - 1)
    iv = min(max(int((normals[p, b] * scale + 1.0) * 0.5 * cells), 0), cells - 1)
    face = 2 * axis + (1 if top < 0.0 else 0)
    return (face * cells + iu) * cells + iv


@inline
def _grouped(points: np.ndarray, normals: np.ndarray, pool: np.ndarray, cell: np.ndarray,
             count: int) -> tuple[np.ndarray, np.ndarray]:
    """The (6, M) coordinates of the ``pool`` points ordered by their (M,) ``cell`` (pool
    order within one) and the (count + 1,) start of each cell's run."""
    m = pool.shape[0]
    start = np.zeros(count + 1, dtype=np.int64)
    for i in range(m):
        start[cell[i] + 1] += 1
    for c in range(count):
        start[c + 1] += start[c]
    fill = start[:-1].copy()
    coords = np.empty((6, m))
    for i in range(m):
        j = fill[cell[i]]
        fill[cell[i]] += 1
        p = pool[i]
        for k in range(3):
            coords[k, j] = points[p, k]
            coords[3 + k, j] = normals[p, k]
    return coords, start


@kernel
def bin_by_normal(points: np.ndarray, normals: np.ndarray, pool: np.ndarray, cells: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The (M,) ``pool`` points grouped by cube-map cell of their normal.

    The cell of a normal n: its face is the axis of its largest component and that
    component's sign (face ``2 axis + (sign < 0)``), its position on the face the other two
    components divided by the largest (in [-1, 1]), cut into ``cells`` x ``cells``.
    Returns (6, M) float64 coordinates ``x, y, z, nx, ny, nz`` ordered by cell (pool order
    within one) and the (6 cells² + 1,) start of each cell's run.
    """
    cell = np.empty(pool.shape[0], dtype=np.int64)
    for i in range(pool.shape[0]):
        cell[i] = _cell_of(normals, pool[i], cells)
    return _grouped(points, normals, pool, cell, 6 * cells * cells)


@kernel
def normal_cells(normals: np.ndarray, cells: int) -> np.ndarray:
    """(N,) int64 cube-map cell (:func:`bin_by_normal`) of each of the (N, 3) float64 unit
    ``normals``: computed once, it serves every pool of a cloud (:func:`bin_points`)."""
    out = np.empty(normals.shape[0], dtype=np.int64)
    for p in range(normals.shape[0]):
        out[p] = _cell_of(normals, p, cells)
    return out


@kernel
def _bin_by_cell(points: np.ndarray, normals: np.ndarray, pool: np.ndarray,
                 point_cells: np.ndarray, cells: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`bin_by_normal` with each point's cell given ((N,) :func:`normal_cells`)."""
    cell = np.empty(pool.shape[0], dtype=np.int64)
    for i in range(pool.shape[0]):
        cell[i] = point_cells[pool[i]]
    return _grouped(points, normals, pool, cell, 6 * cells * cells)


@functools.cache
def cell_cones(cells: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit centre direction (6 c², 3) and angular radius (6 c²,) in radians of each cube-map
    cell of :func:`bin_by_normal`: the largest angle from the centre to a corner of the cell
    (the farthest point of a cell, which is convex on the sphere)."""
    edges = np.linspace(-1.0, 1.0, cells + 1)
    mids = (edges[:-1] + edges[1:]) / 2
    centres, radii = [], []
    for face in range(6):
        for iu in range(cells):
            for iv in range(cells):
                c = _face_direction(face, mids[iu], mids[iv])
                corners = [_face_direction(face, edges[iu + du], edges[iv + dv])
                           for du in (0, 1) for dv in (0, 1)]
                centres.append(c)
                radii.append(max(np.arccos(np.clip(c @ k, -1.0, 1.0)) for k in corners))
    return np.array(centres), np.array(radii)


@functools.lru_cache(maxsize=8)
def cell_reach(cells: int, epsilon_n: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre directions (6 c², 3) of the cells of :func:`cell_cones` and the cosine of
    their radius plus ε_n (radians) plus a margin: the test by which
    :func:`~monoplane.geometry.hypotheses.binned_costs` skips cells (asked once per pool, with
    the same ε_n all frame long)."""
    centres, radii = cell_cones(cells)
    return centres, np.cos(np.minimum(epsilon_n + radii + _SKIP_MARGIN, np.pi))


def _face_direction(face: int, u: float, v: float) -> np.ndarray:
    """Unit direction at position (u, v) of cube-map face ``face`` (see
    :func:`~monoplane.geometry.hypotheses.bin_by_normal`: axis ``face // 2``, negative when
    ``face`` is odd; u and v along the other two axes)."""
    axis = face // 2
    a, b = [k for k in range(3) if k != axis]
    d = np.zeros(3)
    d[axis], d[a], d[b] = 1.0 - 2.0 * (face % 2), u, v
    return d / np.linalg.norm(d)


def bin_points(points: np.ndarray, normals: np.ndarray, pool: np.ndarray, epsilon_n: float,
               point_cells: np.ndarray | None = None) -> BinnedPoints:
    """The ``pool`` points grouped by normal direction, with each cell's skipping test.

    Parameters
    ----------
    points, normals : numpy.ndarray
        (N, 3) float64 points and unit normals, one frame.
    pool : numpy.ndarray
        (M,) int64 indices of the points to group.
    epsilon_n : float
        Normal threshold ε_n in radians of the cost the cells are skipped for.
    point_cells : numpy.ndarray, optional
        (N,) int64 ``normal_cells(normals, NORMAL_CELLS)``, when the caller groups many pools
        of one cloud (the RANSAC: one per plane); computed for the pool when omitted. The
        result is the same.

    Returns
    -------
    BinnedPoints
        :func:`bin_by_normal` of the pool in :data:`NORMAL_CELLS` cells per face side, and
        :func:`cell_reach` of those cells.
    """
    pool = np.ascontiguousarray(pool, dtype=np.int64)
    if point_cells is None:
        coords, start = bin_by_normal(points, normals, pool, NORMAL_CELLS)
    else:
        coords, start = _bin_by_cell(points, normals, pool, point_cells, NORMAL_CELLS)
    centres, cos_reach = cell_reach(NORMAL_CELLS, epsilon_n)
    return BinnedPoints(coords, start, centres, cos_reach)
