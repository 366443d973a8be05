"""Hypothesis scorers for plane RANSAC, vectorised over many hypotheses (lower cost is better).

* ``inliers``: vanilla RANSAC, cost = −(number of points with φ < ε).
* ``msac``: truncated quadratic, cost = Σ_p min(φ²/ε², 1) (MSAC; equals Σ_p min_L f(L, p)
  of the paper's data term up to the constant M, so it ranks hypotheses the same way).
* ``msac-normal``: MSAC where a point also pays the normal cost g(1, p) of E_n to count as an
  inlier, cost = Σ_p min(φ²/ε² + g(1, p), 1), with g measured against the model normal θ_n.

Distances are evaluated as an (H, M) matrix in chunks of hypotheses so that memory stays
bounded (about :data:`CHUNK_ELEMENTS` floats at a time).
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import ClassVar

import numpy as np

from monoplane.geometry.cloud import PlaneCloud
from monoplane.hookspecs import hookimpl
from monoplane.stages.base import RansacParams, Scorer, Stage

#: Largest (hypotheses x points) block evaluated at once.
CHUNK_ELEMENTS = 2_000_000


def _chunks(num_planes: int, num_points: int) -> Iterator[slice]:
    step = max(1, CHUNK_ELEMENTS // max(num_points, 1))
    for start in range(0, num_planes, step):
        yield slice(start, min(start + step, num_planes))


def _dots(vectors: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """(h, M) float32 dot products of (h, 3) vectors with (3, M) coordinates.

    Written out per axis: a BLAS product with an inner dimension of 3 is several times slower.
    """
    v = vectors.astype(np.float32)
    out = v[:, 0:1] * coords[0]
    out += v[:, 1:2] * coords[1]
    out += v[:, 2:3] * coords[2]
    return out


def _distances(coords: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """(h, M) float32 absolute distances of (3, M) points to (h, 4) unit-normal planes."""
    d = _dots(planes[:, :3], coords)
    d += planes[:, 3:4].astype(np.float32)
    return np.abs(d, out=d)


def _columns(values: np.ndarray) -> np.ndarray:
    """(3, M) contiguous float32 copy of (M, 3) values."""
    return np.ascontiguousarray(values.T, dtype=np.float32)


def _truncated_squares(coords: np.ndarray, planes: np.ndarray, epsilon: float) -> np.ndarray:
    """(h, M) float32 MSAC costs min(φ²/ε², 1) of (3, M) points for (h, 4) planes."""
    r = _distances(coords, planes)
    r *= 1.0 / epsilon
    np.minimum(r, 1.0, out=r)
    r *= r
    return r


class _ChunkedScorer(Scorer):
    """Evaluates hypotheses in chunks (bounded memory); subclasses give one chunk's costs."""

    uses_normals: ClassVar[bool] = False

    def score(self, cloud: PlaneCloud, pool: np.ndarray, planes: np.ndarray,
              model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.stages.base.Scorer.score`; (H,) float64 costs."""
        pts = _columns(cloud.points[pool])
        nrm = _columns(cloud.normals[pool]) if self.uses_normals else None
        out = np.empty(planes.shape[0])
        for sl in _chunks(planes.shape[0], pts.shape[1]):
            out[sl] = self._chunk_costs(pts, nrm, planes[sl], model_normals[sl], params)
        return out

    def _chunk_costs(self, pts: np.ndarray, nrm: np.ndarray | None, planes: np.ndarray,
                     model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        """(h,) costs of (h, 4) planes on (3, M) points (and (3, M) normals when used)."""
        raise NotImplementedError


class InlierCountScorer(_ChunkedScorer):
    """Vanilla RANSAC: the negated number of points closer than ε."""

    name = "inliers"

    def _chunk_costs(self, pts: np.ndarray, nrm: np.ndarray | None, planes: np.ndarray,
                     model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        return -(_distances(pts, planes) < params.epsilon).sum(axis=1)


class MsacScorer(_ChunkedScorer):
    """MSAC: truncated quadratic cost Σ min(φ²/ε², 1)."""

    name = "msac"

    def _chunk_costs(self, pts: np.ndarray, nrm: np.ndarray | None, planes: np.ndarray,
                     model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        return _truncated_squares(pts, planes, params.epsilon).sum(axis=1, dtype=np.float64)


class MsacNormalScorer(_ChunkedScorer):
    """MSAC plus the normal cost g of E_n: Σ min(φ²/ε² + g(1, p), 1)."""

    name = "msac-normal"
    uses_normals = True

    def _chunk_costs(self, pts: np.ndarray, nrm: np.ndarray | None, planes: np.ndarray,
                     model_normals: np.ndarray, params: RansacParams) -> np.ndarray:
        assert nrm is not None  # uses_normals
        eps_n = params.epsilon_n
        r = _truncated_squares(pts, planes, params.epsilon)
        cos = _dots(model_normals, nrm)
        # g is non-zero only where the angle reaches ε_n; arccos only on inlier candidates.
        hit = (r < 1.0) & (cos <= np.cos(eps_n))
        ang = np.arccos(np.clip(cos[hit], -1.0, 1.0))
        r[hit] = np.minimum(r[hit] + np.exp(ang / eps_n - 1.0), 1.0)
        return r.sum(axis=1, dtype=np.float64)


@hookimpl
def monoplane_register_scorers() -> list[type[Stage]]:
    """Built-in scorers."""
    return [InlierCountScorer, MsacScorer, MsacNormalScorer]
