"""PointIndex: exact kNN queries with cKDTree's conventions (inf / N beyond the bound)."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from monoplane.errors import InvalidInput
from monoplane.geometry.neighbours import PointIndex, _bounds


@pytest.mark.parametrize("seed", range(5))
def test_queries_match_ckdtree(seed):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1, 1, size=(int(rng.integers(1, 500)), 3))
    queries = rng.uniform(-1.2, 1.2, size=(200, 3))
    for k in (1, 4, 9):
        for bound in (np.inf, 0.2):
            dist, idx = PointIndex(pts).query(queries, k=k, distance_upper_bound=bound)
            ref_d, ref_i = cKDTree(pts).query(queries, k=k, distance_upper_bound=bound)
            ref_d, ref_i = ref_d.reshape(200, k), ref_i.reshape(200, k)
            np.testing.assert_allclose(dist, ref_d, rtol=1e-12)
            np.testing.assert_array_equal(idx, ref_i)
            assert dist.shape == idx.shape == (200, k) and idx.dtype == np.int64


def test_empty_index_and_bad_input():
    dist, idx = PointIndex(np.zeros((0, 3))).query(np.zeros((2, 3)), k=2)
    assert np.isinf(dist).all() and (idx == 0).all()
    with pytest.raises(InvalidInput):
        PointIndex(np.zeros((4, 2)))
    with pytest.raises(InvalidInput):
        PointIndex(np.zeros((4, 3))).query(np.zeros((1, 3)), k=0)


def test_threaded_chunks_give_the_single_thread_answer(monkeypatch):
    rng = np.random.default_rng(7)
    pts = rng.normal(size=(3000, 3)) * [1.0, 1.0, 0.01]  # a noisy sheet, like a plane's cloud
    index = PointIndex(pts)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    one = index.query(pts, k=9)
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    monkeypatch.setattr("monoplane.geometry.neighbours.THREADED_QUERIES", 500)
    three = index.query(pts, k=9)
    np.testing.assert_array_equal(one[0], three[0])
    np.testing.assert_array_equal(one[1], three[1])
    ref_d, ref_i = cKDTree(pts).query(pts, k=9)
    np.testing.assert_allclose(one[0], ref_d, rtol=1e-12)
    np.testing.assert_array_equal(one[1], ref_i)


def test_ties_are_broken_by_index():
    # Exact duplicates and a regular grid: many equal distances, answered in index order.
    g = np.stack(np.meshgrid(np.arange(6.0), np.arange(6.0), [0.0]), -1).reshape(-1, 3)
    pts = np.vstack([g, g[::5]])
    dist, idx = PointIndex(pts).query(pts, k=7)
    ref_d, _ = cKDTree(pts).query(pts, k=7)
    np.testing.assert_allclose(dist, ref_d, rtol=1e-12)
    brute = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
    for row in range(len(pts)):
        order = np.lexsort((np.arange(len(pts)), brute[row]))[:7]
        np.testing.assert_array_equal(idx[row], order)


@pytest.mark.parametrize("threads", ["1", "3"])
@pytest.mark.parametrize("case", ["sheet", "blob", "grid ties", "tiny", "clusters"])
def test_query_indexed_equals_query_on_the_indexed_points(case, threads, monkeypatch):
    rng = np.random.default_rng(len(case))
    if case == "sheet":
        pts = rng.normal(size=(4000, 3)) * [1.0, 1.0, 0.01]
    elif case == "blob":
        pts = rng.uniform(-1, 1, size=(1500, 3))
    elif case == "grid ties":
        g = np.stack(np.meshgrid(np.arange(9.0), np.arange(9.0), [0.0, 1.0]), -1)
        pts = np.vstack([g.reshape(-1, 3), g.reshape(-1, 3)[::7]])
    elif case == "tiny":
        pts = rng.normal(size=(5, 3))
    else:  # far-apart clusters: many points whose k-th neighbour lies outside their block
        pts = np.vstack([c + 0.01 * rng.normal(size=(40, 3))
                         for c in rng.uniform(-5, 5, size=(12, 3))])
    monkeypatch.setenv("OMP_NUM_THREADS", threads)
    monkeypatch.setattr("monoplane.geometry.neighbours.THREADED_QUERIES", 300)
    index = PointIndex(pts)
    for k in (1, 9, 12):
        dist, idx = index.query_indexed(k)
        ref_d, ref_i = index.query(pts, k=k)
        np.testing.assert_array_equal(dist, ref_d)
        np.testing.assert_array_equal(idx, ref_i)
    with pytest.raises(InvalidInput):
        index.query_indexed(0)
    assert PointIndex(np.zeros((0, 3))).query_indexed(3)[0].shape == (0, 3)


@pytest.mark.parametrize("seed", range(6))
def test_bounds_kernel_matches_numpy(seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(int(rng.integers(1, 400)), 3)) * rng.uniform(0.01, 100, 3)
    lo, hi, finite = _bounds(pts)
    np.testing.assert_array_equal(lo, pts.min(axis=0))
    np.testing.assert_array_equal(hi, pts.max(axis=0))
    assert finite
    bad = pts.copy()
    bad[rng.integers(len(bad)), rng.integers(3)] = [np.nan, np.inf, -np.inf][seed % 3]
    assert not _bounds(bad)[2]
    with pytest.raises(InvalidInput, match="finite"):
        PointIndex(bad)
