"""Energies and exact minimisation of monoplane.graphcut, checked by brute force."""

import itertools

import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.graphcut import (
    BinaryEnergy,
    check_submodular,
    degree_normalisation,
    energy,
    gc_ransac_energy,
    minimize,
    msac_costs,
    normal_costs,
    proximity_weights,
)


def brute_force(e: BinaryEnergy) -> tuple[np.ndarray, float]:
    best, best_l = np.inf, None
    for bits in itertools.product([0, 1], repeat=e.num_nodes):
        lab = np.array(bits, dtype=bool)
        val = e.energy(lab)
        if val < best:
            best, best_l = val, lab
    return best_l, best


def test_msac_costs_match_paper_cases():
    eps = 0.02
    f0, f1 = msac_costs(np.array([0.0, 0.01, 0.02, 0.04]), eps)
    np.testing.assert_allclose(f0, [1.0, 0.75, 0.0, 0.0])
    np.testing.assert_allclose(f1, [0.0, 0.0, 1.0, 4.0])


def test_normal_costs_are_zero_below_threshold_and_exponential_above():
    en = np.deg2rad(10.0)
    g = normal_costs(np.deg2rad([0.0, 9.9, 10.0, 20.0]), en)
    np.testing.assert_allclose(g, [0.0, 0.0, 1.0, np.e])


def test_hand_computed_energy_of_one_labelling():
    # Two points, one edge: p inside (φ = ε/2), q outside (φ = 2ε); λ = 0.5, cut cost 1.
    f0, f1 = msac_costs(np.array([0.01, 0.04]), 0.02)
    e = gc_ransac_energy(f0, f1, np.array([[0, 1]]), 1.0, 0.5)
    # L = (0, 0): data 0.5*(0.75 + 0) + pair 0.5*0.5*(0.75 + 0)
    assert e.energy(np.array([0, 0])) == pytest.approx(0.375 + 0.1875)
    # L = (1, 0): data 0.5*(0 + 0) + pair 0.5*1
    assert e.energy(np.array([1, 0])) == pytest.approx(0.5)
    # L = (1, 1): data 0.5*(0 + 4) + 0
    assert e.energy(np.array([1, 1])) == pytest.approx(2.0)
    # L = (0, 1): data 0.5*(0.75 + 4) + 0.5
    assert e.energy(np.array([0, 1])) == pytest.approx(2.875)
    np.testing.assert_array_equal(e.minimize(), [True, False])


@pytest.mark.parametrize("seed", range(6))
def test_graph_cut_matches_brute_force_on_four_nodes(seed):
    rng = np.random.default_rng(seed)
    dist = rng.uniform(0.0, 0.05, size=4)
    f0, f1 = msac_costs(dist, 0.02)
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]])
    pts = rng.normal(scale=0.05, size=(4, 3))
    nrm = rng.normal(size=(4, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    col = rng.uniform(size=(4, 3))
    w = proximity_weights(pts, edges, nrm, col)
    g1 = normal_costs(rng.uniform(0, 0.5, size=4), np.deg2rad(10))
    lam = rng.uniform(0.3, 0.97)
    e = gc_ransac_energy(f0, f1, edges, w, lam, g1)
    assert e.is_submodular()
    labels = e.minimize()
    best_l, best = brute_force(e)
    assert e.energy(labels) == pytest.approx(best, abs=1e-9)


def test_both_outlier_term_prevents_all_outlier_minimum():
    # A chain of perfect inliers: with λ = 0.95 the all-outlier labelling would cost nothing
    # in E_s without the ½(f(0,p) + f(0,q)) term and only 0.05 per point in E_d.
    n = 4
    f0, f1 = msac_costs(np.zeros(n), 0.02)
    edges = np.array([[0, 1], [1, 2], [2, 3]])
    e = gc_ransac_energy(f0, f1, edges, 1.0, 0.95)
    assert e.energy(np.zeros(n, bool)) == pytest.approx(0.05 * 4 + 0.95 * 3)
    np.testing.assert_array_equal(e.minimize(), np.ones(n, bool))
    np.testing.assert_allclose(e.tables[:, 0, 0], 0.95)


def test_proximity_weights_terms():
    pts = np.array([[0.0, 0, 0], [0.1, 0, 0]])
    nrm = np.array([[0.0, 0, -1], [0.0, -1, 0]])
    col = np.array([[1.0, 0, 0], [0.0, 0, 0]])
    edges = np.array([[0, 1]])
    kp = np.exp(-0.01 / 0.01)
    kc = np.exp(-0.01 / 0.01 - 1.0 / 0.2)
    kn = np.exp(-0.01 / 0.01 - (np.pi / 2) / 10.0)
    np.testing.assert_allclose(proximity_weights(pts, edges, nrm, col), 0.5 + kp + kc + kn)
    np.testing.assert_allclose(proximity_weights(pts, edges, nrm, None), 0.5 + kp + kn)
    np.testing.assert_allclose(proximity_weights(pts, edges), 0.5 + kp)


def test_check_submodular_and_minimize_rejects_non_submodular():
    good = np.array([[[0.0, 1.0], [1.0, 0.0]]])
    bad = np.array([[[1.0, 0.0], [0.0, 1.0]]])
    assert check_submodular(good).all()
    assert not check_submodular(bad).any()
    with pytest.raises(InvalidInput):
        minimize(np.zeros((2, 2)), np.array([[0, 1]]), bad)


def test_energy_without_edges_is_sum_of_unaries():
    u = np.array([[1.0, 2.0], [3.0, 0.5]])
    assert energy(np.array([0, 1]), u, np.zeros((0, 2), int), np.zeros((0, 2, 2))) == 1.5
    np.testing.assert_array_equal(minimize(u, np.zeros((0, 2), int), np.zeros((0, 2, 2))),
                                  [False, True])


def test_pairwise_scale_multiplies_only_the_pairwise_term():
    rng = np.random.default_rng(7)
    f0, f1 = msac_costs(rng.uniform(0, 0.04, size=6), 0.02)
    edges = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [0, 5]])
    base = gc_ransac_energy(f0, f1, edges, 1.0, 0.9)
    half = gc_ransac_energy(f0, f1, edges, 1.0, 0.9, pairwise_scale=0.5)
    np.testing.assert_allclose(half.unary, base.unary)
    np.testing.assert_allclose(half.tables, 0.5 * base.tables)
    for bits in itertools.product([0, 1], repeat=6):
        lab = np.array(bits)
        unary = base.unary[np.arange(6), lab].sum()
        assert half.energy(lab) == pytest.approx(unary + 0.5 * (base.energy(lab) - unary))
    with pytest.raises(InvalidInput):
        gc_ransac_energy(f0, f1, edges, 1.0, 0.9, pairwise_scale=0.0)


def test_degree_normalisation():
    assert degree_normalisation(10.0) == pytest.approx(0.1)
    assert degree_normalisation(0.0) == 1.0
