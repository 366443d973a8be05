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
states ``scores = "msac-normal"`` (:attr:`~monoplane.contracts.Scorer.scores`), the RANSAC
driver runs its whole search in one compiled call when the sampler states its draw too.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from monoplane.contracts import RansacParams, Scorer, Stage
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.hypotheses import (
    INLIERS,
    MSAC,
    MSAC_NORMAL,
    binned_costs,
    hypothesis_costs,
)
from monoplane.geometry.normal_bins import BinnedPoints, bin_points
from monoplane.hookspecs import hookimpl


class _KernelScorer(Scorer):
    """Scores hypotheses with :func:`~monoplane.geometry.hypotheses.hypothesis_costs`;
    subclasses choose the cost kind."""

    cost_kind: ClassVar[int]

    def score(self, cloud: PlaneCloud, pool: np.ndarray, planes: np.ndarray,
              model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.contracts.Scorer.score`; (H,) float64 costs."""
        return hypothesis_costs(cloud.points, cloud.normals,
                                np.ascontiguousarray(pool, dtype=np.int64),
                                np.ascontiguousarray(planes, dtype=np.float64),
                                np.ascontiguousarray(model_normals, dtype=np.float64),
                                float(params.epsilon), float(params.epsilon_n), self.cost_kind)


class InlierCountScorer(_KernelScorer):
    """Vanilla RANSAC: the negated number of points closer than ε."""

    name = "inliers"
    scores = "inliers"
    cost_kind = INLIERS


class MsacScorer(_KernelScorer):
    """MSAC: truncated quadratic cost Σ min(φ²/ε², 1)."""

    name = "msac"
    scores = "msac"
    cost_kind = MSAC


class MsacNormalScorer(_KernelScorer):
    """MSAC plus the normal cost g of E_n: Σ min(φ²/ε² + g(1, p), 1)."""

    name = "msac-normal"
    scores = "msac-normal"
    cost_kind = MSAC_NORMAL
    _last: tuple[np.ndarray, np.ndarray, float, BinnedPoints] | None = None

    def score(self, cloud: PlaneCloud, pool: np.ndarray, planes: np.ndarray,
              model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.contracts.Scorer.score`; (H,) float64 costs."""
        binned = self._binned(cloud, pool, params)
        return binned_costs(*binned, np.ascontiguousarray(planes, dtype=np.float64),
                            np.ascontiguousarray(model_normals, dtype=np.float64),
                            float(params.epsilon), float(params.epsilon_n))

    def _binned(self, cloud: PlaneCloud, pool: np.ndarray, params: RansacParams
                ) -> BinnedPoints:
        """The pool's points binned by normal direction, kept for the next call with the same
        pool (the RANSAC scores every batch of a search on one subset of the pool)."""
        last = self._last  # one read: a search ahead on another thread may replace it
        if (last is None or last[0] is not pool or last[1] is not cloud.points
                or last[2] != params.epsilon_n):
            last = self._last = (pool, cloud.points, params.epsilon_n,
                                 bin_points(cloud.points, cloud.normals, pool,
                                            params.epsilon_n))
        return last[3]


@hookimpl
def monoplane_register_scorers() -> list[type[Stage]]:
    """Built-in scorers."""
    return [InlierCountScorer, MsacScorer, MsacNormalScorer]
