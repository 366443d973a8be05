"""Hypothesis scorers for plane RANSAC, vectorised over many hypotheses (lower cost is better).

* ``inliers``: vanilla RANSAC, cost = −(number of points with φ < ε).
* ``msac``: truncated quadratic, cost = Σ_p min(φ²/ε², 1) (MSAC; equals Σ_p min_L f(L, p)
  of the paper's data term up to the constant M, so it ranks hypotheses the same way).
* ``msac-normal``: MSAC where a point also pays the normal cost g(1, p) of E_n to count as an
  inlier, cost = Σ_p min(φ²/ε² + g(1, p), 1), with g measured against the model normal θ_n.

All three run in one compiled kernel over (hypothesis, point) pairs (:func:`_costs`): no
(H, M) matrix is materialised, and a batch on a small pool costs microseconds rather than
the fixed overhead of a dozen numpy passes.

``msac-normal`` visits only the points whose normal can lie within ε_n of a hypothesis'
model normal: every other point costs exactly 1. The points are grouped once per pool by the
direction of their normal (:func:`_binned_points`, the cells of a cube map), and a cell whose
whole cone of directions lies farther than ε_n from the model normal is counted, not visited
(:func:`_binned_costs`). A hypothesis of one orientation in a scene of several thus reads
a fraction of the points; the sum comes out equal up to the order of its additions.
"""

from __future__ import annotations

import functools
from typing import ClassVar

import numpy as np

from monoplane.geometry.cloud import PlaneCloud
from monoplane.hookspecs import hookimpl
from monoplane.jit import inline, kernel
from monoplane.stages.base import RansacParams, Scorer, Stage

#: Cost kinds of :func:`_costs`.
_INLIERS, _MSAC, _MSAC_NORMAL = 0, 1, 2
#: Cells per cube-map face side of the normal directions :func:`_binned_points` groups by.
NORMAL_CELLS = 4
#: Angle (radians) added to a cell's radius before its points are counted instead of visited:
#: far wider than the rounding of a cosine, so no point the full test would visit is skipped.
_SKIP_MARGIN = 1e-6


class _KernelScorer(Scorer):
    """Scores hypotheses with :func:`_costs`; subclasses choose the cost kind."""

    cost_kind: ClassVar[int]

    def score(self, cloud: PlaneCloud, pool: np.ndarray, planes: np.ndarray,
              model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.stages.base.Scorer.score`; (H,) float64 costs."""
        return _costs(cloud.points, cloud.normals, np.ascontiguousarray(pool, dtype=np.int64),
                      np.ascontiguousarray(planes, dtype=np.float64),
                      np.ascontiguousarray(model_normals, dtype=np.float64),
                      float(params.epsilon), float(params.epsilon_n), self.cost_kind)


class InlierCountScorer(_KernelScorer):
    """Vanilla RANSAC: the negated number of points closer than ε."""

    name = "inliers"
    cost_kind = _INLIERS


class MsacScorer(_KernelScorer):
    """MSAC: truncated quadratic cost Σ min(φ²/ε², 1)."""

    name = "msac"
    cost_kind = _MSAC


class MsacNormalScorer(_KernelScorer):
    """MSAC plus the normal cost g of E_n: Σ min(φ²/ε² + g(1, p), 1)."""

    name = "msac-normal"
    cost_kind = _MSAC_NORMAL
    _last: tuple[np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray]] | None = None

    def score(self, cloud: PlaneCloud, pool: np.ndarray, planes: np.ndarray,
              model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.stages.base.Scorer.score`; (H,) float64 costs.

        The points binned by normal direction are kept for the next call with the same pool
        (the RANSAC scores every batch of a search on one subset of the pool).
        """
        last = self._last
        if last is None or last[0] is not pool or last[1] is not cloud.points:
            last = self._last = (pool, cloud.points, _binned_points(
                cloud.points, cloud.normals, np.ascontiguousarray(pool, dtype=np.int64),
                NORMAL_CELLS))
        coords, start = last[2]
        centres, cos_reach = _cell_reach(NORMAL_CELLS, params.epsilon_n)
        return _binned_costs(coords, start, centres, cos_reach,
                             np.ascontiguousarray(planes, dtype=np.float64),
                             np.ascontiguousarray(model_normals, dtype=np.float64),
                             float(params.epsilon), float(params.epsilon_n))


@functools.cache
def _cell_cones(cells: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit centre direction (6 c², 3) and angular radius (6 c²,) in radians of each cube-map
    cell of :func:`_binned_points`: the largest angle from the centre to a corner of the cell
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
def _cell_reach(cells: int, epsilon_n: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre directions (6 c², 3) of the cells of :func:`_cell_cones` and the cosine of
    their radius plus ε_n (radians) plus a margin: the test :func:`_binned_costs` skips cells
    by (asked once per batch of hypotheses, with the same ε_n all frame long)."""
    centres, radii = _cell_cones(cells)
    return centres, np.cos(np.minimum(epsilon_n + radii + _SKIP_MARGIN, np.pi))


def _face_direction(face: int, u: float, v: float) -> np.ndarray:
    """Unit direction at position (u, v) of cube-map face ``face`` (see :func:`_binned_points`:
    axis ``face // 2``, negative when ``face`` is odd; u and v along the other two axes)."""
    axis = face // 2
    a, b = [k for k in range(3) if k != axis]
    d = np.zeros(3)
    d[axis], d[a], d[b] = 1.0 - 2.0 * (face % 2), u, v
    return d / np.linalg.norm(d)


@inline
def _sum4(term: np.ndarray, n: int) -> float:
    """Sum of ``term[:n]`` in four interleaved partial sums, which the CPU adds independently
    (one running sum waits for each addition); the order of the additions is fixed, so the
    scores do not depend on the compiler."""
    s0 = s1 = s2 = s3 = 0.0
    j = 0
    while j + 4 <= n:
        s0 += term[j]
        s1 += term[j + 1]
        s2 += term[j + 2]
        s3 += term[j + 3]
        j += 4
    total = (s0 + s1) + (s2 + s3)
    while j < n:
        total += term[j]
        j += 1
    return total


@kernel
def _binned_points(points: np.ndarray, normals: np.ndarray, pool: np.ndarray, cells: int
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The (M,) ``pool`` points grouped by cube-map cell of their normal.

    The cell of a normal n: its face is the axis of its largest component and that
    component's sign (face ``2 axis + (sign < 0)``), its position on the face the other two
    components divided by the largest (in [-1, 1]), cut into ``cells`` x ``cells``.
    Returns (6, M) float64 coordinates ``x, y, z, nx, ny, nz`` ordered by cell (pool order
    within one) and the (6 cells² + 1,) start of each cell's run.
    """
    m = pool.shape[0]
    count = 6 * cells * cells
    cell = np.empty(m, dtype=np.int64)
    start = np.zeros(count + 1, dtype=np.int64)
    for i in range(m):
        p = pool[i]
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
        cell[i] = (face * cells + iu) * cells + iv
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
def _binned_costs(coords: np.ndarray, start: np.ndarray, centres: np.ndarray,
                  cos_reach: np.ndarray, planes: np.ndarray, model_normals: np.ndarray,
                  epsilon: float, epsilon_n: float) -> np.ndarray:
    """(H,) msac-normal costs of (H, 4) planes with (H, 3) model normals on binned points.

    ``coords`` and ``start`` come from :func:`_binned_points`; ``centres`` (C, 3) and
    ``cos_reach`` (C,) are each cell's centre direction and the cosine of its radius plus ε_n
    (plus a margin): a cell whose centre is farther from the model normal than that holds
    only normals farther than ε_n from it, each point of which costs exactly 1 (see
    :func:`_costs`). The others' terms are summed as :func:`_costs` sums them.
    """
    m = coords.shape[1]
    x, y, z = coords[0], coords[1], coords[2]
    nx, ny, nz = coords[3], coords[4], coords[5]
    # The occupied cells only, as runs (first point, end) with their centre and reach.
    occupied = np.flatnonzero(start[1:] > start[:-1])
    n_cells = occupied.shape[0]
    lo_of = start[occupied]
    hi_of = start[occupied + 1]
    cx, cy, cz = centres[occupied, 0], centres[occupied, 1], centres[occupied, 2]
    reach = cos_reach[occupied]
    near = np.empty(n_cells, dtype=np.bool_)
    out = np.empty(planes.shape[0])
    cos_n = np.cos(epsilon_n)
    term = np.empty(m)
    for h in range(planes.shape[0]):
        a, b, c, d = planes[h, 0], planes[h, 1], planes[h, 2], planes[h, 3]
        m0, m1, m2 = model_normals[h, 0], model_normals[h, 1], model_normals[h, 2]
        for j in range(n_cells):
            near[j] = m0 * cx[j] + m1 * cy[j] + m2 * cz[j] >= reach[j]
        far = 0
        k = 0
        for j in range(n_cells):
            lo, hi = lo_of[j], hi_of[j]
            if not near[j]:
                far += hi - lo
                continue
            # Slices indexed from 0: with offsets into the whole arrays the loop does not
            # vectorise (7 times slower).
            xs, ys, zs = x[lo:hi], y[lo:hi], z[lo:hi]
            nxs, nys, nzs = nx[lo:hi], ny[lo:hi], nz[lo:hi]
            run = term[k:k + hi - lo]
            for t in range(hi - lo):
                phi = abs(a * xs[t] + b * ys[t] + c * zs[t] + d)
                cos = m0 * nxs[t] + m1 * nys[t] + m2 * nzs[t]
                q = min((phi / epsilon) ** 2, 1.0)
                run[t] = q if cos > cos_n else 1.0
            k += hi - lo
        out[h] = _sum4(term, k) + far
    return out


@kernel
def _costs(points: np.ndarray, normals: np.ndarray, pool: np.ndarray, planes: np.ndarray,
           model_normals: np.ndarray, epsilon: float, epsilon_n: float, kind: int
           ) -> np.ndarray:
    """(H,) costs of (H, 4) planes with (H, 3) model normals on the (M,) ``pool`` points.

    ``points`` and ``normals`` are the cloud's (N, 3) float64 arrays. ``kind`` is
    :data:`_INLIERS`, :data:`_MSAC` or :data:`_MSAC_NORMAL`.

    The normal term needs no arccos: g(1, p) = exp(ρ/ε_n - 1) is 0 below ε_n and at least 1
    from ε_n on, so min(φ²/ε² + g, 1) is 1 exactly where ρ >= ε_n, i.e. where the cosine of
    the point normal with the model normal is at most cos ε_n.

    Speed: the pool is gathered once into contiguous coordinate arrays, each hypothesis fills
    a branch-free (M,) buffer of per-point terms (which the compiler vectorises), and the
    buffer is summed in four interleaved partial sums. A single running sum would be bound by
    the latency of one addition per point; the four sums change the result only by rounding
    (about 1e-15 relative).
    """
    m = pool.shape[0]
    x, y, z = np.empty(m), np.empty(m), np.empty(m)
    nx, ny, nz = np.empty(m), np.empty(m), np.empty(m)
    for i in range(m):
        p = pool[i]
        x[i], y[i], z[i] = points[p, 0], points[p, 1], points[p, 2]
        nx[i], ny[i], nz[i] = normals[p, 0], normals[p, 1], normals[p, 2]
    n_planes = planes.shape[0]
    out = np.empty(n_planes)
    cos_n = np.cos(epsilon_n)
    term = np.empty(m)
    for h in range(n_planes):
        a, b, c, d = planes[h, 0], planes[h, 1], planes[h, 2], planes[h, 3]
        m0, m1, m2 = model_normals[h, 0], model_normals[h, 1], model_normals[h, 2]
        if kind == _INLIERS:
            for i in range(m):
                phi = abs(a * x[i] + b * y[i] + c * z[i] + d)
                term[i] = -1.0 if phi < epsilon else 0.0
        elif kind == _MSAC:
            for i in range(m):
                phi = abs(a * x[i] + b * y[i] + c * z[i] + d)
                term[i] = min((phi / epsilon) ** 2, 1.0)
        else:
            for i in range(m):
                phi = abs(a * x[i] + b * y[i] + c * z[i] + d)
                cos = m0 * nx[i] + m1 * ny[i] + m2 * nz[i]
                # Both operands first, then a select: a conditional expression around min()
                # compiles to a branch, which keeps the loop from being vectorised.
                q = min((phi / epsilon) ** 2, 1.0)
                term[i] = q if cos > cos_n else 1.0
        out[h] = _sum4(term, m)
    return out


@hookimpl
def monoplane_register_scorers() -> list[type[Stage]]:
    """Built-in scorers."""
    return [InlierCountScorer, MsacScorer, MsacNormalScorer]
