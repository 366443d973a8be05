"""Samplers: distinct in-pool triplets, normal-consistency rejection, locality, determinism."""

import numpy as np
import pytest

from monoplane.contracts import RansacParams
from monoplane.geometry.hypotheses import draw_triplets
from monoplane.stages.samplers import NapsacSampler, NormalConsistentSampler, UniformSampler
from monoplane.testing import cloud_from_arrays


@pytest.fixture
def cloud():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.5, 0.5, size=(400, 3))
    nrm = np.tile([0.0, 0.0, -1.0], (400, 1))
    # Every other point has a normal tilted by 30 degrees.
    t = np.deg2rad(30)
    nrm[1::2] = [np.sin(t), 0.0, -np.cos(t)]
    return cloud_from_arrays(pts, nrm)


@pytest.mark.parametrize("sampler", [UniformSampler(), NormalConsistentSampler(),
                                     NapsacSampler()])
def test_samples_are_distinct_pool_members_and_deterministic(cloud, sampler):
    pool = np.arange(0, 400, 3, dtype=np.int64)
    params = RansacParams()
    a = sampler.sample(cloud, pool, 500, np.random.default_rng(7), params)
    b = sampler.sample(cloud, pool, 500, np.random.default_rng(7), params)
    np.testing.assert_array_equal(a, b)
    assert a.dtype == np.int64 and a.shape[1] == 3 and 0 < len(a) <= 500
    assert np.isin(a, pool).all()
    assert np.all((a[:, 0] != a[:, 1]) & (a[:, 0] != a[:, 2]) & (a[:, 1] != a[:, 2]))


def test_uniform_sampler_covers_the_pool_evenly(cloud):
    pool = np.arange(10, dtype=np.int64)
    s = UniformSampler().sample(cloud, pool, 30000, np.random.default_rng(1), RansacParams())
    counts = np.bincount(s.ravel(), minlength=10)
    np.testing.assert_allclose(counts / counts.sum(), 0.1, atol=0.01)


def test_normal_consistent_sampler_rejects_mixed_normal_samples(cloud):
    pool = np.arange(400, dtype=np.int64)
    params = RansacParams(epsilon_n_deg=10.0)
    s = NormalConsistentSampler().sample(cloud, pool, 300, np.random.default_rng(2), params)
    assert len(s) == 300
    parity = s % 2
    assert np.all(parity == parity[:, :1])  # all three from the same normal family
    # With ε_n above 30 degrees nothing is rejected, so mixed samples appear.
    loose = NormalConsistentSampler().sample(cloud, pool, 300, np.random.default_rng(2),
                                             RansacParams(epsilon_n_deg=31.0))
    assert np.any((loose % 2).min(axis=1) != (loose % 2).max(axis=1))


def test_normal_consistent_sampler_gives_up_when_nothing_passes():
    pts = np.random.default_rng(0).uniform(size=(6, 3))
    nrm = np.eye(3)[[0, 1, 2, 0, 1, 2]]
    nrm[3:] *= -1
    c = cloud_from_arrays(pts, nrm)
    pool = np.array([0, 1, 2], dtype=np.int64)
    s = NormalConsistentSampler().sample(c, pool, 10, np.random.default_rng(0), RansacParams())
    assert s.shape == (0, 3)


def test_napsac_samples_are_local(cloud):
    pool = np.arange(400, dtype=np.int64)
    sampler = NapsacSampler(NapsacSampler.Config(radius=0.15, candidates=20))
    s = sampler.sample(cloud, pool, 200, np.random.default_rng(3), RansacParams())
    assert len(s) > 0
    p = cloud.points
    assert np.all(np.linalg.norm(p[s[:, 1]] - p[s[:, 0]], axis=1) <= 0.15)
    assert np.all(np.linalg.norm(p[s[:, 2]] - p[s[:, 0]], axis=1) <= 0.15)


def test_too_small_pools_give_no_samples(cloud):
    for sampler in (UniformSampler(), NormalConsistentSampler(), NapsacSampler()):
        s = sampler.sample(cloud, np.array([1, 2], dtype=np.int64), 5,
                           np.random.default_rng(0), RansacParams())
        assert s.shape == (0, 3)


def reference_triplets(pool, count, rng, normals=None, cos_min=-2.0, limit=None):
    """numpy form of _triplets: offset draws, pool mapping, pairwise dot products, limit."""
    m = pool.size
    a, b, c = (rng.integers(0, m - i, size=count) for i in range(3))
    b = b + (b >= a)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    c = c + (c >= lo)
    c = c + (c >= hi)
    idx = pool[np.stack([a, b, c], axis=1)]
    if normals is not None:
        n = normals[idx]
        ok = ((n[:, 0] * n[:, 1]).sum(1) >= cos_min) & ((n[:, 0] * n[:, 2]).sum(1) >= cos_min) \
            & ((n[:, 1] * n[:, 2]).sum(1) >= cos_min)
        idx = idx[ok]
    return idx[: count if limit is None else limit]


@pytest.mark.parametrize("limit", [None, 0, 37, 5000])
def test_triplet_kernel_matches_the_numpy_reference(limit):
    rng = np.random.default_rng(4)
    nrm = rng.normal(size=(300, 3))
    nrm[:150] = [0.0, 0.0, -1.0] + 0.1 * rng.normal(size=(150, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    pool = np.sort(rng.choice(300, 200, replace=False))
    cos_min = np.cos(np.deg2rad(10.0))
    for normals in (None, nrm):
        got = draw_triplets(np.random.default_rng(9), pool, 2000, 2000,
                            2000 if limit is None else limit, normals, cos_min)
        want = reference_triplets(pool, 2000, np.random.default_rng(9), normals, cos_min, limit)
        np.testing.assert_array_equal(got, want)
        assert got.dtype == np.int64
        assert (got[:, 0] != got[:, 1]).all() and (got[:, 1] != got[:, 2]).all() \
            and (got[:, 0] != got[:, 2]).all()
    assert 0 < reference_triplets(pool, 2000, np.random.default_rng(9), nrm, cos_min).shape[0] \
        < 2000
