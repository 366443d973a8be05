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

from monoplane.contracts import RansacParams, Sampler, Stage, TripletDraws, param
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.hypotheses import draw_triplets
from monoplane.hookspecs import hookimpl


class UniformSampler(Sampler):
    """Three distinct points drawn uniformly from the remaining pool."""

    name = "uniform"
    draws = "uniform"

    def sample(self, cloud: PlaneCloud, pool: np.ndarray, count: int,
               rng: np.random.Generator, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.contracts.Sampler.sample`; returns (count, 3) int64."""
        if pool.size < 3 or count <= 0:
            return np.zeros((0, 3), dtype=np.int64)
        return draw_triplets(rng, pool, count, count, count)


@dataclass
class NormalConsistentConfig:
    """Parameters of the normal-consistent sampler."""

    max_draw_factor: int = param(
        20, "give up after drawing this many times `count` candidate samples")


class NormalConsistentSampler(Sampler):
    """Uniform samples, rejected when any pair of predicted normals differs by more than ε_n."""

    name = "normal-consistent"
    Config = NormalConsistentConfig
    draws = "normal-consistent"

    def sample(self, cloud: PlaneCloud, pool: np.ndarray, count: int,
               rng: np.random.Generator, params: RansacParams) -> np.ndarray:
        """See :meth:`monoplane.contracts.Sampler.sample`.

        ``2 * count`` candidates are drawn first and, if fewer than ``count`` pass the check,
        the rest of the ``max_draw_factor * count`` budget in one more batch; may return fewer
        than ``count``.
        """
        if pool.size < 3 or count <= 0:
            return np.zeros((0, 3), dtype=np.int64)
        first, budget, cos_min = TripletDraws.stated("normal-consistent", count,
                                                     self.draw_budget(count), params.epsilon_n)
        return draw_triplets(rng, pool, first, budget, count, cloud.normals,
                             -2.0 if cos_min is None else cos_min)

    def draw_budget(self, count: int) -> int:
        """``max_draw_factor * count`` candidates at most (see
        :meth:`monoplane.contracts.Sampler.draw_budget`)."""
        return self.config.max_draw_factor * count


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
        """See :meth:`monoplane.contracts.Sampler.sample`.

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


@hookimpl
def monoplane_register_samplers() -> list[type[Stage]]:
    """Built-in samplers."""
    return [UniformSampler, NormalConsistentSampler, NapsacSampler]
