"""PointIndex: exact kNN queries with cKDTree's conventions (inf / N beyond the bound)."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from monoplane.errors import InvalidInput
from monoplane.geometry.neighbours import PointIndex


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
