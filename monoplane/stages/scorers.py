"""Hypothesis scorers for plane RANSAC, vectorised over many hypotheses (lower cost is better).

* ``inliers``: vanilla RANSAC, cost = −(number of points with φ < ε).
* ``msac``: truncated quadratic, cost = Σ_p min(φ²/ε², 1) (MSAC; equals Σ_p min_L f(L, p)
  of the paper's data term up to the constant M, so it ranks hypotheses the same way).
* ``msac-normal``: MSAC where a point also pays the normal cost g(1, p) of E_n to count as an
  inlier, cost = Σ_p min(φ²/ε² + g(1, p), 1), with g measured against the model normal θ_n.

The kernels live in :mod:`monoplane.geometry.hypotheses`. All three costs run in one compiled
kernel over (hypothesis, point) pairs (``hypothesis_costs``): no (H, M) matrix is materialised,
and a batch on a small pool costs microseconds rather than the fixed overhead of a dozen numpy
passes.

``msac-normal`` visits only the points whose normal can lie within ε_n of a hypothesis'
model normal: every other point costs exactly 1. The points are grouped once per pool by the
direction of their normal (``bin_by_normal``, the cells of a cube map), and a cell whose whole
cone of directions lies farther than ε_n from the model normal is counted, not visited
(``binned_costs``). A hypothesis of one orientation in a scene of several thus reads a
fraction of the points; the sum comes out equal up to the order of its additions. Because it
answers :meth:`~monoplane.stages.base.Scorer.binned_points`, the RANSAC driver runs its whole
search in one compiled call when the sampler allows it too.
"""

from __future__ import annotations

import functools
from typing import ClassVar

import numpy as np

from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.hypotheses import (
    INLIERS,
    MSAC,
    MSAC_NORMAL,
    bin_by_normal,
    binned_costs,
    hypothesis_costs,
)
from monoplane.hookspecs import hookimpl
from monoplane.stages.base import BinnedPoints, RansacParams, Scorer, Stage

#: Cells per cube-map face side of the normal directions :func:`bin_by_normal` groups by.
NORMAL_CELLS = 4
#: Angle (radians) added to a cell's radius before its points are counted instead of visited:
#: far wider than the rounding of a cosine, so no point the full test would visit is skipped.
_SKIP_MARGIN = 1e-6


class _KernelScorer(Scorer):
    """Scores hypotheses with :func:`~monoplane.geometry.hypotheses.hypothesis_costs`;
    subclasses choose the cost kind."""

    cost_kind: ClassVar[int]

    def score(self, cloud: PlaneCloud, pool: np.ndarray, planes: np.ndarray,
              model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.stages.base.Scorer.score`; (H,) float64 costs."""
        return hypothesis_costs(cloud.points, cloud.normals,
                                np.ascontiguousarray(pool, dtype=np.int64),
                                np.ascontiguousarray(planes, dtype=np.float64),
                                np.ascontiguousarray(model_normals, dtype=np.float64),
                                float(params.epsilon), float(params.epsilon_n), self.cost_kind)


class InlierCountScorer(_KernelScorer):
    """Vanilla RANSAC: the negated number of points closer than ε."""

    name = "inliers"
    cost_kind = INLIERS


class MsacScorer(_KernelScorer):
    """MSAC: truncated quadratic cost Σ min(φ²/ε², 1)."""

    name = "msac"
    cost_kind = MSAC


class MsacNormalScorer(_KernelScorer):
    """MSAC plus the normal cost g of E_n: Σ min(φ²/ε² + g(1, p), 1)."""

    name = "msac-normal"
    cost_kind = MSAC_NORMAL
    _last: tuple[np.ndarray, np.ndarray, float, BinnedPoints] | None = None

    def score(self, cloud: PlaneCloud, pool: np.ndarray, planes: np.ndarray,
              model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.stages.base.Scorer.score`; (H,) float64 costs."""
        binned = self._binned(cloud, pool, params)
        return binned_costs(*binned, np.ascontiguousarray(planes, dtype=np.float64),
                            np.ascontiguousarray(model_normals, dtype=np.float64),
                            float(params.epsilon), float(params.epsilon_n))

    def binned_points(self, cloud: PlaneCloud, pool: np.ndarray, params: RansacParams
                      ) -> BinnedPoints | None:
        """See :meth:`monoplane.stages.base.Scorer.binned_points` (None for a subclass that
        scores otherwise)."""
        if type(self).score is not MsacNormalScorer.score:
            return None
        return self._binned(cloud, pool, params)

    def _binned(self, cloud: PlaneCloud, pool: np.ndarray, params: RansacParams
                ) -> BinnedPoints:
        """The pool's points binned by normal direction, kept for the next call with the same
        pool (the RANSAC scores every batch of a search on one subset of the pool)."""
        last = self._last  # one read: a search ahead on another thread may replace it
        if (last is None or last[0] is not pool or last[1] is not cloud.points
                or last[2] != params.epsilon_n):
            coords, start = bin_by_normal(cloud.points, cloud.normals,
                                          np.ascontiguousarray(pool, dtype=np.int64),
                                          NORMAL_CELLS)
            centres, cos_reach = _cell_reach(NORMAL_CELLS, params.epsilon_n)
            last = self._last = (pool, cloud.points, params.epsilon_n,
                                 BinnedPoints(coords, start, centres, cos_reach))
        return last[3]


@functools.cache
def _cell_cones(cells: int) -> tuple[np.ndarray, np.ndarray]:
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
def _cell_reach(cells: int, epsilon_n: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre directions (6 c², 3) of the cells of :func:`_cell_cones` and the cosine of
    their radius plus ε_n (radians) plus a margin: the test by which
    :func:`~monoplane.geometry.hypotheses.binned_costs` skips cells (asked once per pool, with
    the same ε_n all frame long)."""
    centres, radii = _cell_cones(cells)
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


@hookimpl
def monoplane_register_scorers() -> list[type[Stage]]:
    """Built-in scorers."""
    return [InlierCountScorer, MsacScorer, MsacNormalScorer]
