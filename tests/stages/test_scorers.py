"""Scorers: compiled costs equal per-point reference formulas."""

import numpy as np
import pytest

from monoplane.contracts import RansacParams
from monoplane.stages.scorers import InlierCountScorer, MsacNormalScorer, MsacScorer
from monoplane.testing import cloud_from_arrays


@pytest.fixture
def setup():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.5, 0.5, size=(500, 3))
    pts[:300, 2] = 0.1 + rng.normal(0, 0.01, size=300)  # a noisy plane z = 0.1
    nrm = rng.normal(size=(500, 3))
    nrm[:300] = [0.0, 0.0, -1.0] + rng.normal(0, 0.1, size=(300, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    cloud = cloud_from_arrays(pts, nrm)
    planes = rng.normal(size=(40, 4))
    planes[:, :3] /= np.linalg.norm(planes[:, :3], axis=1, keepdims=True)
    planes[:, 3] *= 0.2
    planes[0] = [0.0, 0.0, -1.0, 0.1]
    mn = rng.normal(size=(40, 3))
    mn /= np.linalg.norm(mn, axis=1, keepdims=True)
    mn[0] = [0.0, 0.0, -1.0]
    pool = np.arange(0, 500, 2, dtype=np.int64)
    return cloud, pool, planes, mn


def reference(cloud, pool, plane, mn, params, kind):
    total = 0.0
    for i in pool:
        phi = abs(cloud.points[i] @ plane[:3] + plane[3])
        if kind == "inliers":
            total -= phi < params.epsilon
            continue
        r = min(phi**2 / params.epsilon**2, 1.0)
        if kind == "msac-normal" and r < 1.0:
            rho = np.arccos(np.clip(cloud.normals[i] @ mn, -1, 1))
            if rho >= params.epsilon_n:
                r = min(r + np.exp(rho / params.epsilon_n - 1.0), 1.0)
        total += r
    return total


@pytest.mark.parametrize("scorer", [InlierCountScorer(), MsacScorer(), MsacNormalScorer()])
def test_costs_match_reference_and_true_plane_wins(setup, scorer):
    cloud, pool, planes, mn = setup
    params = RansacParams(epsilon=0.02, epsilon_n_deg=10.0)
    costs = scorer.score(cloud, pool, planes, mn, params)
    ref = [reference(cloud, pool, planes[h], mn[h], params, scorer.name) for h in range(40)]
    np.testing.assert_allclose(costs, ref, rtol=1e-12, atol=1e-12)
    assert int(np.argmin(costs)) == 0


def test_normal_term_penalises_a_wrong_model_normal(setup):
    cloud, pool, planes, mn = setup
    params = RansacParams()
    good = MsacNormalScorer().score(cloud, pool, planes[:1], mn[:1], params)
    tilted = np.array([[0.0, np.sin(0.5), -np.cos(0.5)]])
    bad = MsacNormalScorer().score(cloud, pool, planes[:1], tilted, params)
    plain = MsacScorer().score(cloud, pool, planes[:1], mn[:1], params)
    assert bad[0] > good[0] >= plain[0]



def test_normal_cells_bound_their_normals_and_skipping_changes_nothing():
    from monoplane.geometry.hypotheses import MSAC_NORMAL, hypothesis_costs
    from monoplane.geometry.normal_bins import (
        NORMAL_CELLS,
        bin_by_normal,
        bin_points,
        cell_cones,
        normal_cells,
    )

    rng = np.random.default_rng(3)
    n = 4000
    # Boxes of random yaw: a few orientations, with noise, plus normals on cell borders.
    axes = rng.normal(size=(12, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    nrm = axes[rng.integers(0, 12, n)] + rng.normal(0, 0.05, (n, 3))
    nrm[:6] = [[1, 0, 0], [0, -1, 0], [0, 0, 1], [1, 1, 0], [1, 1, 1], [-1, 0.5, 0.5]]
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    pts = rng.uniform(-0.5, 0.5, (n, 3))
    cloud = cloud_from_arrays(pts, nrm)
    pool = np.sort(rng.choice(n, 3000, replace=False)).astype(np.int64)
    coords, start = bin_by_normal(cloud.points, cloud.normals, pool, NORMAL_CELLS)
    centres, radii = cell_cones(NORMAL_CELLS)
    # Every point lies in its cell's cone, and the cells hold every pool point once.
    cell = np.repeat(np.arange(len(radii)), np.diff(start))
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", coords[3:].T, centres[cell]), -1, 1))
    assert np.all(angle <= radii[cell] + 1e-12)
    assert sorted(map(tuple, coords[:3].T)) == sorted(map(tuple, cloud.points[pool]))
    planes = np.column_stack([axes[rng.integers(0, 12, 200)], rng.uniform(-0.3, 0.3, 200)])
    mn = planes[:, :3] + rng.normal(0, 0.05, (200, 3))
    mn /= np.linalg.norm(mn, axis=1, keepdims=True)
    params = RansacParams()
    full = hypothesis_costs(cloud.points, cloud.normals, pool, planes, mn, params.epsilon,
                            params.epsilon_n, MSAC_NORMAL)
    np.testing.assert_allclose(MsacNormalScorer().score(cloud, pool, planes, mn, params), full,
                               rtol=1e-13)
    # Cells computed once for the whole cloud group any pool as its own computation does.
    cells = normal_cells(cloud.normals, NORMAL_CELLS)
    for a, b in zip(bin_points(cloud.points, cloud.normals, pool, 0.3, cells),
                    bin_points(cloud.points, cloud.normals, pool, 0.3), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(cells[pool][np.argsort(cells[pool], kind="stable")],
                                  cell)
