"""Hypothesis scorers for plane RANSAC, vectorised over many hypotheses (lower cost is better).

* ``inliers``: vanilla RANSAC, cost = −(number of points with φ < ε).
* ``msac``: truncated quadratic, cost = Σ_p min(φ²/ε², 1) (MSAC; equals Σ_p min_L f(L, p)
  of the paper's data term up to the constant M, so it ranks hypotheses the same way).
* ``msac-normal``: MSAC where a point also pays the normal cost g(1, p) of E_n to count as an
  inlier, cost = Σ_p min(φ²/ε² + g(1, p), 1), with g measured against the model normal θ_n.

All three run in one compiled kernel over (hypothesis, point) pairs (:func:`_costs`): no
(H, M) matrix is materialised, and a batch on a small pool costs microseconds rather than
the fixed overhead of a dozen numpy passes.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from monoplane.geometry.cloud import PlaneCloud
from monoplane.hookspecs import hookimpl
from monoplane.jit import kernel
from monoplane.stages.base import RansacParams, Scorer, Stage

#: Cost kinds of :func:`_costs`.
_INLIERS, _MSAC, _MSAC_NORMAL = 0, 1, 2


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
        s0 = s1 = s2 = s3 = 0.0
        j = 0
        while j + 4 <= m:
            s0 += term[j]
            s1 += term[j + 1]
            s2 += term[j + 2]
            s3 += term[j + 3]
            j += 4
        total = (s0 + s1) + (s2 + s3)
        while j < m:
            total += term[j]
            j += 1
        out[h] = total
    return out


@hookimpl
def monoplane_register_scorers() -> list[type[Stage]]:
    """Built-in scorers."""
    return [InlierCountScorer, MsacScorer, MsacNormalScorer]
