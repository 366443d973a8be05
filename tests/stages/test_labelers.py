"""Labelers: threshold vs graph cuts on a plane with noisy points, E_n, colour-free input."""

import numpy as np
import pytest

from monoplane.algorithm.graphcut import (
    gc_ransac_energy,
    msac_costs,
    normal_angles,
    normal_costs,
    proximity_weights,
)
from monoplane.contracts import Labeling, RansacParams
from monoplane.errors import ConfigError
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.graph import NeighbourGraph
from monoplane.stages.labelers import (
    GraphCutLabeler,
    ProximityGraphCutLabeler,
    ThresholdLabeler,
)

EPS = 0.02
PLANE = np.array([0.0, 0.0, -1.0, 0.0])  # z = 0 in the normalised frame


def grid_cloud(colors=True, tilt_deg=0.0):
    """A 30x30 grid on z = 0 (spacing 0.01) plus a far cluster; 3x3 bumps at 1.3 ε.

    Returns the cloud, the flat indices of the bumps and of the far cluster.
    """
    u, v = np.meshgrid(np.linspace(-0.15, 0.14, 30), np.linspace(-0.15, 0.14, 30))
    pts = np.stack([u.ravel(), v.ravel(), np.zeros(900)], axis=1)
    bump = (np.abs(u - 0.0) < 0.015).ravel() & (np.abs(v - 0.0) < 0.015).ravel()
    pts[bump, 2] = 1.3 * EPS
    far = np.random.default_rng(0).uniform(-0.1, 0.1, size=(50, 3)) + [0, 0, 0.5]
    pts = np.concatenate([pts, far])
    nrm = np.tile([0.0, 0.0, -1.0], (950, 1))
    t = np.deg2rad(tilt_deg)
    patch = np.zeros(950, bool)
    patch[:900] = ((u > 0.05) & (v > 0.05)).ravel()
    nrm[patch] = [np.sin(t), 0.0, -np.cos(t)]
    col = np.full((950, 3), 0.5) if colors else None
    cloud = PlaneCloud(points=pts, normals=nrm, colors=col,
                       pixels=np.arange(950, dtype=np.int64), center=np.zeros(3), scale=1.0,
                       shape=(1, 950), all_points=pts, all_pixels=np.arange(950, dtype=np.int64))
    return cloud, np.flatnonzero(bump), np.arange(900, 950), np.flatnonzero(patch)


def run(labeler, cloud, pool=None):
    graph = NeighbourGraph.build(cloud.points, k=8)
    pool = np.arange(cloud.size, dtype=np.int64) if pool is None else pool
    return labeler.label(cloud, graph, pool, PLANE, np.array([0.0, 0.0, -1.0]),
                         RansacParams(epsilon=EPS, epsilon_n_deg=10.0)), graph


def test_threshold_labels_by_distance_and_reports_minus_count():
    cloud, bump, far, _ = grid_cloud()
    lab, _ = run(ThresholdLabeler(), cloud)
    expected = np.ones(950, bool)
    expected[bump] = False
    expected[far] = False
    np.testing.assert_array_equal(lab.inliers, expected)
    assert lab.energy == -expected.sum()


# The paper's unnormalised E_s: the bump is a 3x3 cluster 2.6 spacings off the grid, so few
# edges tie it to the plane; only the unnormalised pairwise weight pulls it in.
@pytest.mark.parametrize("labeler", [GraphCutLabeler(GraphCutLabeler.Config(normalise=False)),
                                     ProximityGraphCutLabeler()])
@pytest.mark.parametrize("colors", [True, False])
def test_graph_cuts_close_holes_but_keep_far_points_out(labeler, colors):
    cloud, bump, far, _ = grid_cloud(colors=colors)
    lab, _ = run(labeler, cloud)
    assert lab.inliers[bump].all()  # spatial coherence absorbs the 1.3 ε bump
    assert not lab.inliers[far].any()
    assert lab.inliers[:900].all()


@pytest.mark.parametrize("labeler", [GraphCutLabeler(), ProximityGraphCutLabeler()])
def test_graph_cut_labelling_is_a_local_minimum_of_its_energy(labeler):
    cloud, _, _, _ = grid_cloud(tilt_deg=40.0)
    lab, graph = run(labeler, cloud)
    thr, _ = run(ThresholdLabeler(), cloud)
    rng = np.random.default_rng(0)
    base = lab.energy

    def energy_of(labels):
        d = np.abs(cloud.points @ PLANE[:3] + PLANE[3])
        f0, f1 = msac_costs(d, EPS)
        edges = graph.edges
        if labeler.name == "graph-cut":
            e = gc_ransac_energy(f0, f1, edges, 1.0, 0.95,
                                 pairwise_scale=1.0 / graph.mean_degree)
        else:
            g1 = normal_costs(normal_angles(cloud.normals, PLANE[:3]), np.deg2rad(10))
            w = proximity_weights(cloud.points, edges, cloud.normals, cloud.colors)
            e = gc_ransac_energy(f0, f1, edges, w, 0.95, g1)
        return e.energy(labels)

    assert energy_of(lab.inliers) == pytest.approx(base)
    assert base <= energy_of(thr.inliers) + 1e-9
    for _ in range(20):
        flipped = lab.inliers.copy()
        idx = rng.choice(950, size=3, replace=False)
        flipped[idx] = ~flipped[idx]
        assert energy_of(flipped) >= base - 1e-9


def test_normal_energy_rejects_coplanar_points_with_wrong_normals():
    cloud, _, _, patch = grid_cloud(tilt_deg=60.0)
    gc, _ = run(GraphCutLabeler(), cloud)
    prox, _ = run(ProximityGraphCutLabeler(), cloud)
    assert gc.inliers[patch].all()
    assert prox.inliers[patch].mean() < 0.1  # only a few boundary points stay in
    no_en, _ = run(ProximityGraphCutLabeler(ProximityGraphCutLabeler.Config(normal_term=False)),
                   cloud)
    assert no_en.inliers[patch].all()


def test_subgraph_pool_and_weight_cache():
    cloud, bump, far, _ = grid_cloud()
    pool = np.arange(0, 950, 2, dtype=np.int64)
    labeler = ProximityGraphCutLabeler()
    graph = NeighbourGraph.build(cloud.points, k=8)
    context = labeler.new_context()
    lab = labeler.label(cloud, graph, pool, PLANE, np.array([0.0, 0.0, -1.0]),
                        RansacParams(epsilon=EPS, epsilon_n_deg=10.0), context)
    assert lab.inliers.shape == pool.shape
    assert not lab.inliers[np.isin(pool, far)].any()
    # The frame's edge weights are computed once, for the whole graph, in the context.
    assert context.weights is not None and context.weights.shape == (graph.edges.shape[0],)


@pytest.mark.parametrize("labeler", [GraphCutLabeler, ProximityGraphCutLabeler])
def test_relabelling_a_pool_reuses_its_terms_and_changes_nothing(labeler):
    # The local optimisation labels one pool for a hypothesis, then for its refit: the second
    # labelling reuses the pool's terms (subgraph, cut costs, payback) kept by the labeler.
    cloud, _, _, _ = grid_cloud(tilt_deg=5.0)
    graph = NeighbourGraph.build(cloud.points, k=8)
    pool = np.arange(cloud.size, dtype=np.int64)
    params = RansacParams(epsilon=EPS, epsilon_n_deg=10.0)
    tilted = np.array([0.0, np.sin(0.02), -np.cos(0.02), 0.004])
    mn = np.array([0.0, 0.0, -1.0])
    warm = labeler()
    context = warm.new_context()
    first = warm.label(cloud, graph, pool, PLANE, mn, params, context)
    kept = context.pool
    second = warm.label(cloud, graph, pool, tilted, mn, params, context)
    assert context.pool is kept  # the same pool's terms, reused
    for plane, lab in ((PLANE, first), (tilted, second)):
        cold = labeler().label(cloud, graph, pool, plane, mn, params)
        np.testing.assert_array_equal(lab.inliers, cold.inliers)
        assert lab.energy == cold.energy
    # Another pool gets terms of its own.
    warm.label(cloud, graph, pool[::2], PLANE, mn, params, context)
    assert context.pool is not kept
    assert vars(warm) == vars(labeler())  # the labeler itself keeps nothing


@pytest.mark.parametrize("labeler", [GraphCutLabeler, ProximityGraphCutLabeler])
def test_two_frames_labelled_in_turn_with_one_labeler_match_each_alone(labeler):
    # The driver's per-frame context holds all the labeler reuses, so interleaving the calls
    # of two frames (as two threads sharing one pipeline would) changes nothing.
    params = RansacParams(epsilon=EPS, epsilon_n_deg=10.0)
    mn = np.array([0.0, 0.0, -1.0])
    frames = []
    for tilt in (2.0, 7.0):
        cloud, _, _, _ = grid_cloud(tilt_deg=tilt)
        frames.append((cloud, NeighbourGraph.build(cloud.points, k=8),
                       np.arange(cloud.size, dtype=np.int64)))
    alone = [[labeler().label(c, g, p[::s], PLANE, mn, params) for s in (1, 2)]
             for c, g, p in frames]
    shared = labeler()
    contexts = [shared.new_context() for _ in frames]
    for step in (1, 2):
        for (c, g, p), ctx, expected in zip(frames, contexts, alone, strict=True):
            lab = shared.label(c, g, p[::step], PLANE, mn, params, ctx)
            np.testing.assert_array_equal(lab.inliers, expected[step - 1].inliers)
            assert lab.energy == expected[step - 1].energy


@pytest.mark.parametrize("normalise", [False, True])
def test_degree_normalisation_decides_whether_an_isolated_far_point_is_absorbed(normalise):
    # A flat 20x20 grid (spacing 0.01) with one point lifted to 6ε: r = φ²/ε² = 36. All its
    # neighbours are firm inliers, so it is an inlier iff (1-λ) r < λ s deg, with s = 1/k̄
    # when normalised: 1.8 < 0.95 * deg without, and 1.8 > 0.95 * deg / k̄ ≈ 0.95 with.
    u, v = np.meshgrid(np.arange(20) * 0.01, np.arange(20) * 0.01)
    pts = np.stack([u.ravel(), v.ravel(), np.zeros(400)], axis=1)
    lifted = 210
    pts[lifted, 2] = 6 * EPS
    nrm = np.tile([0.0, 0.0, -1.0], (400, 1))
    cloud = PlaneCloud(points=pts, normals=nrm, colors=None, pixels=np.arange(400),
                       center=np.zeros(3), scale=1.0, shape=(20, 20), all_points=pts,
                       all_pixels=np.arange(400))
    lab, graph = run(GraphCutLabeler(GraphCutLabeler.Config(normalise=normalise)), cloud)
    deg = graph.neighbours(lifted).size
    s = 1.0 / graph.mean_degree if normalise else 1.0
    assert lab.inliers[lifted] == (0.05 * 36 < 0.95 * s * deg)
    assert lab.inliers[lifted] != normalise
    assert lab.inliers[np.arange(400) != lifted].all()


def test_proximity_labeler_scales_the_affinities_of_a_graph_that_has_a_scale():
    # The lattice graph weakens the pairs whose normals turn (NeighbourGraph.affinity_scale):
    # the labeler's cut costs are 0.5 + scale × (proximity weight - 0.5).
    cloud, _, _, _ = grid_cloud()
    graph = NeighbourGraph.build(cloud.points, k=8)
    graph.affinity_scale = np.linspace(0.0, 1.0, graph.num_edges)
    labeler = ProximityGraphCutLabeler()
    context = labeler.new_context()
    labeler.label(cloud, graph, np.arange(cloud.size, dtype=np.int64), PLANE,
                  np.array([0.0, 0.0, -1.0]), RansacParams(epsilon=EPS, epsilon_n_deg=10.0),
                  context)
    full = proximity_weights(cloud.points, graph.edges, cloud.normals, cloud.colors)
    np.testing.assert_allclose(context.weights, 0.5 + graph.affinity_scale * (full - 0.5))


def test_proximity_labeler_reads_the_normal_angles_of_a_graph_that_has_them():
    # The lattice graph keeps the angles between its ends' normals (NeighbourGraph.normal_angle):
    # the labeler's cut costs read them (all right angles here: k_n = w_n exp(pos - π/2 / 2α_n²)).
    cloud, _, _, _ = grid_cloud()
    graph = NeighbourGraph.build(cloud.points, k=8)
    graph.normal_angle = np.full(graph.num_edges, np.pi / 2)
    labeler = ProximityGraphCutLabeler()
    context = labeler.new_context()
    labeler.label(cloud, graph, np.arange(cloud.size, dtype=np.int64), PLANE,
                  np.array([0.0, 0.0, -1.0]), RansacParams(epsilon=EPS, epsilon_n_deg=10.0),
                  context)
    i, j = graph.edges.T
    pos = -np.sum((cloud.points[i] - cloud.points[j]) ** 2, axis=1) / (2 * 0.005)
    without_n = proximity_weights(cloud.points, graph.edges, None, cloud.colors)
    np.testing.assert_allclose(context.weights, without_n + np.exp(pos - np.pi / 20.0),
                               rtol=1e-12)


def test_normal_gate_is_validated_and_removes_a_tilted_patch_smoothness_kept():
    with pytest.raises(ConfigError, match="normal_gate_deg must lie in"):
        ProximityGraphCutLabeler.Config(normal_gate_deg=0.0)
    # A coplanar 10x10 patch whose normals turn 40° from the plane, in the grid's corner: the
    # smoothness carries the plane over all of it; gated at 30°, over its rim (the two
    # rows next to the plane, whose kNN reach the plane's points) at most.
    cloud, _, _, patch = grid_cloud(tilt_deg=40.0)
    # Given normals are not gated by default; normals estimated from depth are.
    plain, _ = run(ProximityGraphCutLabeler(), cloud)
    assert plain.inliers[patch].all()
    cloud.normals_from_sensor_depth = True
    from_depth, _ = run(ProximityGraphCutLabeler(ProximityGraphCutLabeler.Config(
        normal_gate_deg=30.0)), cloud)
    cloud.normals_from_sensor_depth = False
    cfg = ProximityGraphCutLabeler.Config
    gated, _ = run(ProximityGraphCutLabeler(cfg(normal_gate_deg=30.0, gate_given_normals=True)),
                   cloud)
    inner = (cloud.points[patch, 0] > 0.07) & (cloud.points[patch, 1] > 0.07)
    assert inner.sum() == 64 and not gated.inliers[patch][inner].any()
    np.testing.assert_array_equal(from_depth.inliers, gated.inliers)
    assert gated.inliers[:900][~np.isin(np.arange(900), patch)].mean() > 0.95


def test_a_labelings_energy_given_as_a_function_is_summed_once_when_first_read():
    calls = []
    lab = Labeling(np.array([True, False]), lambda: calls.append(1) or 2.5)
    assert not calls and "not summed yet" in repr(lab)
    assert lab.energy == 2.5 and lab.energy == 2.5 and calls == [1]
    assert Labeling(np.array([True]), 1.0).energy == 1.0
