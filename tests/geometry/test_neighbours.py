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
