"""Minimal-sample generators for plane RANSAC: 3 distinct points per sample.

* ``uniform``: three distinct points drawn uniformly from the remaining pool.
* ``normal-consistent``: uniform draws, keeping only samples whose three predicted normals are
  pairwise within ε_n of each other (paper §III-B2, last paragraph).
* ``napsac``: a uniformly drawn seed point plus two points drawn from its spatial neighbourhood
  (a ball around the seed in the normalised cloud), in the spirit of NAPSAC; locality makes
  all-inlier samples far likelier on small planes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.geometry.cloud import PlaneCloud
from monoplane.hookspecs import hookimpl
from monoplane.jit import inline, kernel
from monoplane.stages.base import RansacParams, Sampler, Stage, param


def _triplets(pool: np.ndarray, count: int, rng: np.random.Generator,
              normals: np.ndarray | None = None, cos_min: float = -2.0,
              limit: int | None = None, budget: int | None = None) -> np.ndarray:
    """Uniform samples of three distinct pool points, optionally normal-checked.

    ``count`` candidates are drawn; when fewer than ``limit`` of them pass and ``budget``
    exceeds ``count``, the rest of the budget is drawn in one more round. Returns the (S, 3)
    int64 point indices of the samples whose three (N, 3) ``normals`` are pairwise within
    ``cos_min`` (all of them without ``normals``), in draw order, at most ``limit`` (default
    ``count``) of them. Needs at least three pool points.
    """
    limit = count if limit is None else int(limit)
    return _drawn_triplets(rng, np.ascontiguousarray(pool, dtype=np.int64), int(count),
                           max(int(count), count if budget is None else int(budget)), limit,
                           np.zeros((0, 3)) if normals is None else normals,
                           normals is not None, float(cos_min))


class UniformSampler(Sampler):
    """Three distinct points drawn uniformly from the remaining pool."""

    name = "uniform"

    def sample(self, cloud: PlaneCloud, pool: np.ndarray, count: int,
               rng: np.random.Generator, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.stages.base.Sampler.sample`; returns (count, 3) int64."""
        if pool.size < 3 or count <= 0:
            return np.zeros((0, 3), dtype=np.int64)
        return _triplets(pool, count, rng)


@dataclass
class NormalConsistentConfig:
    """Parameters of the normal-consistent sampler."""

    max_draw_factor: int = param(
        20, "give up after drawing this many times `count` candidate samples")


class NormalConsistentSampler(Sampler):
    """Uniform samples, rejected when any pair of predicted normals differs by more than ε_n."""

    name = "normal-consistent"
    Config = NormalConsistentConfig

    def sample(self, cloud: PlaneCloud, pool: np.ndarray, count: int,
               rng: np.random.Generator, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.stages.base.Sampler.sample`.

        ``2 * count`` candidates are drawn first and, if fewer than ``count`` pass the check,
        the rest of the ``max_draw_factor * count`` budget in one more batch; may return fewer
        than ``count``.
        """
        if pool.size < 3 or count <= 0:
            return np.zeros((0, 3), dtype=np.int64)
        budget = self.config.max_draw_factor * count
        return _triplets(pool, min(2 * count, budget), rng, cloud.normals,
                         np.cos(params.epsilon_n), count, budget)


@dataclass
class NapsacConfig:
    """Parameters of the NAPSAC-style locality sampler."""

    radius: float = param(0.1, "neighbourhood radius around the seed point, unit-sphere units")
    candidates: int = param(32, "nearest cloud points considered as the seed's neighbourhood")


class NapsacSampler(Sampler):
    """A random seed point and two random pool points among its nearest cloud neighbours."""

    name = "napsac"
    Config = NapsacConfig

    def sample(self, cloud: PlaneCloud, pool: np.ndarray, count: int,
               rng: np.random.Generator, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.stages.base.Sampler.sample`.

        Seeds whose neighbourhood holds fewer than two other pool points are dropped, so fewer
        than ``count`` samples may be returned.
        """
        if pool.size < 3 or count <= 0:
            return np.zeros((0, 3), dtype=np.int64)
        in_pool = np.zeros(cloud.size, dtype=bool)
        in_pool[pool] = True
        seeds = pool[rng.integers(0, pool.size, size=count)]
        k = min(self.config.candidates, cloud.size - 1)
        dist, nbr = cloud.tree.query(cloud.points[seeds], k=k + 1,
                                     distance_upper_bound=self.config.radius)
        # Neighbours beyond the radius come back as inf with index N; the seed itself may appear.
        found = np.isfinite(dist)
        nbr = np.where(found, nbr, 0)
        usable = found & in_pool[nbr] & (nbr != seeds[:, None])
        # Pick two usable neighbours per seed at random: random keys, unusable ones last.
        keys = np.where(usable, rng.random(usable.shape), -1.0)
        top = np.argsort(-keys, axis=1)[:, :2]
        ok = usable.sum(axis=1) >= 2
        rows = np.flatnonzero(ok)
        picked = nbr[rows[:, None], top[ok]]
        return np.concatenate([seeds[ok, None], picked], axis=1).astype(np.int64)


@inline
def _keep_triplets(rng: np.random.Generator, pool: np.ndarray, count: int, normals: np.ndarray,
                   check: bool, cos_min: float, out: np.ndarray, kept: int) -> int:
    """Draw ``count`` candidate samples and append those that pass to ``out`` from row
    ``kept`` on, until it is full; returns the new number of rows.

    Draws without replacement per row by offsetting: a in [0, m), b in [0, m-1), c in
    [0, m-2), then b shifted past a and c past the two others; this is exact and needs no
    rejection. With ``check``, a sample is kept only when its three normals' pairwise dot
    products all reach ``cos_min``.
    """
    m = pool.shape[0]
    a = rng.integers(0, m, size=count)
    b = rng.integers(0, m - 1, size=count)
    c = rng.integers(0, m - 2, size=count)
    for s in range(count):
        if kept == out.shape[0]:
            break
        pa, pb, pc = a[s], b[s], c[s]
        if pb >= pa:
            pb += 1
        lo, hi = min(pa, pb), max(pa, pb)
        if pc >= lo:
            pc += 1
        if pc >= hi:
            pc += 1
        i, j, k = pool[pa], pool[pb], pool[pc]
        if check:
            ij = ik = jk = 0.0
            for d in range(3):
                ij += normals[i, d] * normals[j, d]
                ik += normals[i, d] * normals[k, d]
                jk += normals[j, d] * normals[k, d]
            if not (ij >= cos_min and ik >= cos_min and jk >= cos_min):
                continue
        out[kept, 0], out[kept, 1], out[kept, 2] = i, j, k
        kept += 1
    return kept


@kernel
def _drawn_triplets(rng: np.random.Generator, pool: np.ndarray, first: int, budget: int,
                    limit: int, normals: np.ndarray, check: bool, cos_min: float
                    ) -> np.ndarray:
    """:func:`_triplets` in one call: the generator is drawn from here, as numpy draws
    (numba's ``Generator.integers`` gives numpy's stream), so no Python runs between rounds.

    ``first`` candidates, then the other ``budget - first`` when fewer than ``limit`` passed;
    (K, 3) int64 rows, K <= ``limit``.
    """
    out = np.empty((max(min(budget, limit), 0), 3), dtype=np.int64)
    kept = _keep_triplets(rng, pool, first, normals, check, cos_min, out, 0)
    if kept < out.shape[0] and budget > first:
        kept = _keep_triplets(rng, pool, budget - first, normals, check, cos_min, out, kept)
    return out[:kept].copy()


@hookimpl
def monoplane_register_samplers() -> list[type[Stage]]:
    """Built-in samplers."""
    return [UniformSampler, NormalConsistentSampler, NapsacSampler]
