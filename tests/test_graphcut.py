"""Energies and exact minimisation of monoplane.algorithm.graphcut, checked by brute force."""

import itertools

import numpy as np
import pytest

from monoplane.algorithm.graphcut import (
    BinaryEnergy,
    check_submodular,
    data_costs,
    degree_normalisation,
    energy,
    gc_ransac_cut_energy,
    gc_ransac_energy,
    minimize,
    minimize_gc_ransac,
    msac_costs,
    normal_angles,
    normal_costs,
    pool_payback,
    proximity_weights,
)
from monoplane.errors import InvalidInput
from monoplane.geometry.graph import NeighbourGraph, shrink_subgraph
from monoplane.geometry.lattice import turn_scale


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


def random_gc_problem(seed):
    """A random GC-RANSAC problem: MSAC costs, sparse normal costs, random proximity cuts."""
    rng = np.random.default_rng(seed)
    m = int(rng.integers(2, 400))
    f0, f1 = msac_costs(rng.exponential(0.03, m), 0.02)
    g1 = np.where(rng.random(m) < 0.5, normal_costs(rng.uniform(0, np.pi, m), 0.17), 0.0)
    edges = rng.integers(0, m, size=(int(rng.integers(0, 6 * m)), 2))
    edges = edges[edges[:, 0] != edges[:, 1]]
    cut = 0.5 + 3.0 * rng.random(len(edges))
    return f0, f1, g1, edges, cut, float(rng.uniform(0.3, 1.0)), float(rng.choice([1.0, 0.1]))


@pytest.mark.parametrize("seed", range(40))
def test_fast_gc_ransac_minimiser_equals_the_table_based_one(seed):
    # Reference: the general (E, 2, 2)-table energy and its max-flow. Random real costs have no
    # ties, so the labelling must be identical, and the energies equal up to summation order.
    f0, f1, g1, edges, cut, lam, scale = random_gc_problem(seed)
    ref = gc_ransac_energy(f0, f1, edges, cut, lam, g1, pairwise_scale=scale)
    expected = ref.minimize()
    labels, value = minimize_gc_ransac(f0, f1 + g1, edges, cut, lam, scale)
    np.testing.assert_array_equal(labels, expected)
    assert value == pytest.approx(ref.energy(expected), rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("seed", range(10))
def test_payback_kept_per_pool_gives_the_same_result(seed):
    f0, f1, g1, edges, cut, lam, scale = random_gc_problem(seed)
    payback = pool_payback(len(f0), edges, cut, lam, scale)
    # λ s Σ_q w_pq over each point's edges.
    expected = np.zeros(len(f0))
    np.add.at(expected, edges[:, 0], lam * scale * cut)
    np.add.at(expected, edges[:, 1], lam * scale * cut)
    np.testing.assert_allclose(payback, expected, rtol=1e-12)
    with_it = minimize_gc_ransac(f0, f1 + g1, edges, cut, lam, scale, payback=payback)
    without = minimize_gc_ransac(f0, f1 + g1, edges, cut, lam, scale)
    np.testing.assert_array_equal(with_it[0], without[0])
    assert with_it[1] == without[1]
    with pytest.raises(InvalidInput, match="one entry per point"):
        minimize_gc_ransac(f0, f1, edges, cut, lam, scale, payback=payback[:-1])


@pytest.mark.parametrize("seed", range(10))
def test_energy_left_out_is_the_same_float_when_summed_later(seed):
    # The graph-cut labelers sum the energy only when the driver reads it: the same cut,
    # and the same float as the one the minimiser returns with it.
    f0, f1, g1, edges, cut, lam, scale = random_gc_problem(seed)
    labels, value = minimize_gc_ransac(f0, f1 + g1, edges, cut, lam, scale)
    alone, none = minimize_gc_ransac(f0, f1 + g1, edges, cut, lam, scale, with_energy=False)
    assert none is None
    np.testing.assert_array_equal(alone, labels)
    assert gc_ransac_cut_energy(f0, f1 + g1, edges, cut, lam, alone, scale) == value
    assert gc_ransac_cut_energy(f0, f1 + g1, edges, cut, lam, ~alone, scale) >= value


def test_submodularity_is_checked_whenever_a_cut_can_be_too_cheap():
    # Cut costs >= 1/2 with f(0, p) <= 1 cannot break submodularity; anything else is checked.
    f0 = np.array([1.0, 1.0])
    edges = np.array([[0, 1]])
    assert minimize_gc_ransac(f0, np.zeros(2), edges, 0.5, 0.9)[0].all()
    with pytest.raises(InvalidInput, match="not submodular"):
        minimize_gc_ransac(f0, np.zeros(2), edges, 0.49, 0.9)
    with pytest.raises(InvalidInput, match="not submodular"):
        minimize_gc_ransac(np.array([3.0, 3.0]), np.zeros(2), edges, 1.0, 0.9)


def test_fast_gc_ransac_minimiser_on_small_problems_is_the_brute_force_optimum():
    for seed in range(30):
        rng = np.random.default_rng(100 + seed)
        f0, f1, g1, _, _, lam, scale = random_gc_problem(seed)
        m = min(len(f0), 8)
        f0, f1, g1 = f0[:m], f1[:m], g1[:m]
        edges = np.array([(i, j) for i in range(m) for j in range(i + 1, m)
                          if rng.random() < 0.5], dtype=np.int64).reshape(-1, 2)
        cut = 0.5 + rng.random(len(edges))
        ref = gc_ransac_energy(f0, f1, edges, cut, lam, g1, pairwise_scale=scale)
        _, best = brute_force(ref)
        labels, value = minimize_gc_ransac(f0, f1 + g1, edges, cut, lam, scale)
        assert value == pytest.approx(best, abs=1e-12)
        assert ref.energy(labels) == pytest.approx(best, abs=1e-12)


def test_fast_gc_ransac_minimiser_rejects_bad_input():
    f0, f1 = msac_costs(np.array([0.0, 0.0]), 0.02)
    with pytest.raises(InvalidInput, match="not submodular"):
        minimize_gc_ransac(f0, f1, np.array([[0, 1]]), 0.1, 0.9)
    with pytest.raises(InvalidInput, match="lambda"):
        minimize_gc_ransac(f0, f1, np.array([[0, 1]]), 1.0, 1.5)
    labels, value = minimize_gc_ransac(np.zeros(0), np.zeros(0), np.zeros((0, 2)), 1.0, 0.9)
    assert labels.shape == (0,) and value == 0.0


def reference_proximity_weights(points, edges, normals, colors, ap2, ac2, an2, wp, wc, wn):
    """Eqs. kp, kc, kn written out over all edges at once."""
    i, j = edges[:, 0], edges[:, 1]
    pos = -((points[i] - points[j]) ** 2).sum(axis=1) / (2.0 * ap2)
    w = 0.5 + wp * np.exp(pos)
    if colors is not None:
        w += wc * np.exp(pos - ((colors[i] - colors[j]) ** 2).sum(axis=1) / (2.0 * ac2))
    if normals is not None:
        ang = np.arccos(np.clip((normals[i] * normals[j]).sum(axis=1), -1.0, 1.0))
        w += wn * np.exp(pos - ang / (2.0 * an2))
    return w


@pytest.mark.parametrize("threads", [1, 3])
@pytest.mark.parametrize("seed", range(6))
def test_proximity_weight_kernel_matches_the_vectorised_formula(seed, threads, monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", str(threads))
    # 600 edges: 3 chunks
    monkeypatch.setattr("monoplane.algorithm.graph_costs.THREADED_EDGES", 100)
    rng = np.random.default_rng(seed)
    n = 200
    pts = rng.normal(0, 0.05, (n, 3))
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm[:5] = nrm[5]  # dot products at exactly 1 (clipping)
    col = rng.random((n, 3))
    edges = rng.integers(0, n, size=(600, 2))
    params = (0.005, 0.1, 5.0, *rng.uniform(0.5, 2.0, 3))
    for normals in (nrm, None):
        for colors in (col, None):
            np.testing.assert_allclose(
                proximity_weights(pts, edges, normals, colors, *params),
                reference_proximity_weights(pts, edges, normals, colors, *params),
                rtol=1e-12)
    # A per-edge scale shrinks the affinity above the 0.5 floor, chunk by chunk alike.
    scale = rng.random(600)
    np.testing.assert_allclose(
        proximity_weights(pts, edges, nrm, col, *params, scale=scale),
        0.5 + scale * (reference_proximity_weights(pts, edges, nrm, col, *params) - 0.5),
        rtol=1e-12)
    with pytest.raises(InvalidInput, match=r"scale must be \(600,\)"):
        proximity_weights(pts, edges, nrm, col, *params, scale=scale[:-1])
    # The edges' normal angles, when given, replace the arccos of the normals: the same bits
    # for the lattice graph's angles (compiled alike, dot products summed in the same order;
    # numpy's own arccos may differ in the last bit), the formula for any others.
    i, j = edges.T
    _, angles = turn_scale(np.ascontiguousarray(edges, dtype=np.int64), nrm, 10.0)
    np.testing.assert_array_equal(
        proximity_weights(pts, edges, nrm, col, *params, scale=scale, angles=angles),
        proximity_weights(pts, edges, nrm, col, *params, scale=scale))
    other = rng.uniform(0.0, np.pi, 600)
    pos = -np.sum((pts[i] - pts[j]) ** 2, axis=1) / (2 * params[0])
    without_n = reference_proximity_weights(pts, edges, None, col, *params)
    np.testing.assert_allclose(
        proximity_weights(pts, edges, nrm, col, *params, angles=other),
        without_n + params[5] * np.exp(pos - other / (2 * params[2])), rtol=1e-12)
    with pytest.raises(InvalidInput, match=r"angles must be \(600,\)"):
        proximity_weights(pts, edges, nrm, col, *params, angles=other[:-1])


def test_fused_data_costs_match_msac_and_normal_costs():
    # Reference: msac_costs of the distances plus normal_costs of the angles, vectorised.
    rng = np.random.default_rng(8)
    pts = rng.normal(0, 0.05, (400, 3))
    nrm = rng.normal(size=(400, 3))
    nrm[:200] = [0.0, 0.0, -1.0] + 0.05 * rng.normal(size=(200, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    eps, eps_n = 0.02, np.deg2rad(10.0)
    # Normals just inside and outside ε_n of the model normal: g jumps from 0 to 1 there.
    tilt = eps_n * np.array([1 - 1e-5, 1 - 1e-9, 1 + 1e-9, 1 + 1e-5])
    nrm[200:204] = np.stack([np.sin(tilt), np.zeros(4), -np.cos(tilt)], axis=1)
    pool = np.union1d(np.sort(rng.choice(400, 300, replace=False)), np.arange(200, 204))
    plane = np.array([0.0, 0.0, -1.0, 0.01])
    mn = np.array([0.0, 0.0, -1.0])
    f0_ref, f1_ref = msac_costs(np.abs(pts[pool] @ plane[:3] + plane[3]), eps)
    g1_ref = normal_costs(normal_angles(nrm[pool], mn), eps_n)
    f0, data1 = data_costs(pts, nrm, pool, plane, mn, eps, eps_n)
    np.testing.assert_allclose(f0, f0_ref, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(data1, f1_ref + g1_ref, rtol=1e-12, atol=1e-15)
    assert (f0 > 0).any() and (g1_ref > 0).any()
    f0, data1 = data_costs(pts, nrm, pool, plane, None, eps)
    np.testing.assert_allclose(data1, f1_ref, rtol=1e-12, atol=1e-15)


@pytest.mark.parametrize("seed", range(6))
def test_data_costs_bounded_by_the_payback_give_the_same_cut(seed):
    # Points whose distance alone makes them outliers of every minimiser skip the normal
    # term: their inlier cost is lower than the exact one, the cut and its energy are not.
    rng = np.random.default_rng(seed)
    # Half on the plane z = 0.01 (normals along it), half scattered far and wide.
    pts = rng.uniform(-1.0, 1.0, (500, 3))
    pts[:250, 2] = 0.01 + rng.normal(0, 0.01, 250)
    nrm = rng.normal(size=(500, 3))
    nrm[:250] = [0.0, 0.0, -1.0] + 0.05 * rng.normal(size=(250, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    graph = NeighbourGraph.build(pts, 6)
    pool = np.sort(rng.choice(500, 400, replace=False))
    edges, _ = graph.subgraph(pool)
    cut = proximity_weights(pts[pool], edges, nrm[pool])
    lam, eps, eps_n = 0.95, 0.02, np.deg2rad(10.0)
    plane, mn = np.array([0.0, 0.0, -1.0, 0.01]), np.array([0.0, 0.0, -1.0])
    payback = pool_payback(pool.size, edges, cut, lam)
    exact = data_costs(pts, nrm, pool, plane, mn, eps, eps_n)
    bounded = data_costs(pts, nrm, pool, plane, mn, eps, eps_n, payback, 1 - lam)
    np.testing.assert_array_equal(bounded[0], exact[0])
    left_out = bounded[1] != exact[1]
    assert left_out.any() and np.all(bounded[1][left_out] < exact[1][left_out])
    labels, energy = minimize_gc_ransac(*exact, edges, cut, lam, payback=payback)
    again, energy_again = minimize_gc_ransac(*bounded, edges, cut, lam, payback=payback)
    np.testing.assert_array_equal(again, labels)
    assert energy_again == energy and labels.any() and not labels[left_out].any()


@pytest.mark.parametrize("seed", range(8))
def test_a_shrunk_pool_subgraph_is_the_graphs_own_subgraph_row_for_row(seed):
    rng = np.random.default_rng(seed)
    graph = NeighbourGraph.build(rng.random((300, 3)), 6)
    pool = np.arange(300, dtype=np.int64)
    edges, edge_ids = graph.edges, np.arange(graph.num_edges)
    for _ in range(4):  # a RANSAC pool loses a plane's inliers at a time
        smaller = pool[rng.random(pool.size) < 0.7]
        shrunk, rows = shrink_subgraph(pool, smaller, edges)
        expected, expected_ids = graph.subgraph(smaller)
        np.testing.assert_array_equal(shrunk, expected)
        np.testing.assert_array_equal(edge_ids[rows], expected_ids)
        pool, edges, edge_ids = smaller, shrunk, edge_ids[rows]


def test_a_pool_not_within_the_last_one_is_not_shrunk():
    old = np.array([1, 3, 5], dtype=np.int64)
    edges = np.array([[0, 1], [1, 2]], dtype=np.int64)
    assert shrink_subgraph(old, np.array([1, 4]), edges) is None
    assert shrink_subgraph(old, np.array([5, 3]), edges) is None  # not in the same order
    assert shrink_subgraph(np.zeros(0, dtype=np.int64), np.array([2]), edges[:0]) is None
    kept, rows = shrink_subgraph(old, np.array([3, 5]), edges)
    assert kept.tolist() == [[0, 1]] and rows.tolist() == [1]


@pytest.mark.parametrize("seed", range(6))
def test_gated_bounded_data_costs_match_the_plain_formulas(seed):
    # The gate with the pool's edges and the payback bound: +inf at a turned point whose
    # neighbours are all turned; f(1) alone at a point its distance fixes as an outlier; else
    # f(1) + g(1). (The turned points' normal terms are added after the gate; the result must
    # not show it.)
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-1.0, 1.0, (600, 3))
    pts[:300, 2] = 0.01 + rng.normal(0, 0.01, 300)
    nrm = rng.normal(size=(600, 3)) + [0.0, 0.0, -2.0]
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    graph = NeighbourGraph.build(pts, 6)
    pool = np.sort(rng.choice(600, 500, replace=False))
    edges, _ = graph.subgraph(pool)
    cut = proximity_weights(pts[pool], edges, nrm[pool])
    lam, eps, eps_n, gate = 0.95, 0.02, np.deg2rad(10.0), np.deg2rad(30.0)
    plane, mn = np.array([0.0, 0.0, -1.0, 0.01]), np.array([0.0, 0.0, -1.0])
    payback = pool_payback(pool.size, edges, cut, lam)
    f0, data1 = data_costs(pts, nrm, pool, plane, mn, eps, eps_n, payback, 1 - lam, gate, edges)
    ref_f0, f1 = msac_costs(np.abs(pts[pool] @ plane[:3] + plane[3]), eps)
    angles = normal_angles(nrm[pool], mn)
    g1 = normal_costs(angles, eps_n)
    turned = angles > gate
    gated = turned.copy()
    for i, j in edges:
        gated[i] &= turned[j]
        gated[j] &= turned[i]
    fixed = (f1 >= 1.0) & ((1 - lam) * f1 > payback * (1 + 1e-9) + 1e-12)
    expected = np.where(gated, np.inf, np.where(fixed, f1, f1 + g1))
    np.testing.assert_array_equal(f0, ref_f0)
    np.testing.assert_allclose(data1, expected, rtol=1e-12)
    assert gated.any() and (turned & ~gated & ~fixed & (g1 > 0)).any() and (fixed & ~gated).any()
    # The cut is the one of the exact, ungated-by-bound costs with the same gate.
    exact = data_costs(pts, nrm, pool, plane, mn, eps, eps_n, gate=gate, edges=edges)
    labels, value = minimize_gc_ransac(f0, data1, edges, cut, lam, payback=payback)
    again, value_again = minimize_gc_ransac(*exact, edges, cut, lam, payback=payback)
    np.testing.assert_array_equal(labels, again)
    assert value == value_again


def test_normal_gate_keeps_a_plane_off_a_point_its_smoothness_would_carry():
    # Three points on the plane z = 0 in a chain, the middle one's normal 40° from the model
    # normal (ε_n = 10°): f(0) = 1 and f(1) = 0 each, g(1, middle) = e³. Cut cost 1, λ = 0.95.
    # All inliers: 0.05 e³ = 1.004; middle out: 0.05 + 2 λ = 1.95; all out: 0.15 + 2 λ = 2.05.
    pts = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.02, 0.0, 0.0]])
    t = np.deg2rad(40.0)
    nrm = np.array([[0.0, 0.0, -1.0], [np.sin(t), 0.0, -np.cos(t)], [0.0, 0.0, -1.0]])
    pool = np.arange(3, dtype=np.int64)
    plane, mn = np.array([0.0, 0.0, -1.0, 0.0]), np.array([0.0, 0.0, -1.0])
    edges = np.array([[0, 1], [1, 2]])
    eps_n = np.deg2rad(10.0)
    f0, data1 = data_costs(pts, nrm, pool, plane, mn, 0.02, eps_n)
    labels, value = minimize_gc_ransac(f0, data1, edges, 1.0, 0.95)
    assert labels.all() and value == pytest.approx(0.05 * np.e ** 3)
    # Gated at 30°: the middle point cannot be an inlier, its neighbours stay.
    f0, data1 = data_costs(pts, nrm, pool, plane, mn, 0.02, eps_n, gate=np.deg2rad(30.0))
    assert np.isinf(data1[1]) and np.array_equal(data1[[0, 2]], [0.0, 0.0])
    labels, value = minimize_gc_ransac(f0, data1, edges, 1.0, 0.95)
    assert labels.tolist() == [True, False, True] and value == pytest.approx(0.05 + 2 * 0.95)
    # A gate above the middle normal's angle changes nothing.
    same = data_costs(pts, nrm, pool, plane, mn, 0.02, eps_n, gate=np.deg2rad(45.0))
    np.testing.assert_array_equal(same[1], data_costs(pts, nrm, pool, plane, mn, 0.02, eps_n)[1])


def test_normal_gate_cuts_exactly_at_its_angle_and_only_with_a_model_normal():
    gate = np.deg2rad(30.0)
    tilt = gate * np.array([0.5, 1 - 1e-6, 1 + 1e-6, 3.0])
    nrm = np.stack([np.sin(tilt), np.zeros(4), -np.cos(tilt)], axis=1)
    pts = np.zeros((4, 3))
    pool = np.arange(4, dtype=np.int64)
    plane, mn = np.array([0.0, 0.0, -1.0, 0.0]), np.array([0.0, 0.0, -1.0])
    _, data1 = data_costs(pts, nrm, pool, plane, mn, 0.02, np.deg2rad(10.0), gate=gate)
    assert np.isinf(data1).tolist() == [False, False, True, True]
    np.testing.assert_allclose(data1[:2], normal_costs(tilt[:2], np.deg2rad(10.0)))
    _, data1 = data_costs(pts, nrm, pool, plane, None, 0.02, gate=gate)
    assert not np.isinf(data1).any()


def test_normal_gate_with_edges_spares_turned_points_beside_unturned_ones():
    # Five points on the plane z = 0 in a chain; points 1-3 turned 35° (ε_n = 10°: g = e^2.5,
    # inlier unary 0.05 e^2.5 = 0.609). Cut cost 1, λ = 0.95. With the chain's edges only point
    # 2, whose neighbours are both turned, is gated; then [1, 1, 0, 1, 1] costs
    # 0.05 + 2 (0.609) + 2 λ = 3.168, against 3.559 for [1, 1, 0, 0, 1] and 3.95 for
    # [1, 0, 0, 0, 1]. Ungated, all inliers (3 x 0.609 = 1.827) win.
    pts = np.zeros((5, 3))
    pts[:, 0] = 0.01 * np.arange(5)
    t = np.deg2rad(35.0)
    nrm = np.tile([0.0, 0.0, -1.0], (5, 1))
    nrm[1:4] = [np.sin(t), 0.0, -np.cos(t)]
    pool = np.arange(5, dtype=np.int64)
    plane, mn = np.array([0.0, 0.0, -1.0, 0.0]), np.array([0.0, 0.0, -1.0])
    chain = np.array([[0, 1], [1, 2], [2, 3], [3, 4]])
    args = (pts, nrm, pool, plane, mn, 0.02, np.deg2rad(10.0))
    f0, data1 = data_costs(*args)
    labels, _ = minimize_gc_ransac(f0, data1, chain, 1.0, 0.95)
    assert labels.all()
    f0, data1 = data_costs(*args, gate=np.deg2rad(30.0), edges=chain)
    assert np.isinf(data1).tolist() == [False, False, True, False, False]
    labels, value = minimize_gc_ransac(f0, data1, chain, 1.0, 0.95)
    assert labels.tolist() == [True, True, False, True, True]
    assert value == pytest.approx(0.05 + 2 * 0.05 * np.exp(2.5) + 2 * 0.95)
    # Without the edges every turned point is gated; two turned points side by side both have
    # an unturned neighbour, so neither is.
    assert np.isinf(data_costs(*args, gate=np.deg2rad(30.0))[1]).sum() == 3
    short = chain[[0, 1, 3]]  # 0-1, 1-2, 3-4: point 2's only other neighbour is gone
    nrm[3] = [0.0, 0.0, -1.0]
    assert not np.isinf(data_costs(*args, gate=np.deg2rad(30.0), edges=chain)[1]).any()
    assert np.isinf(data_costs(*args, gate=np.deg2rad(30.0), edges=short)[1]).tolist() == [
        False, False, True, False, False]
