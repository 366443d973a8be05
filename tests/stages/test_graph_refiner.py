"""The graph-crf refiner: a crease relabelled, separate coplanar parts split, image use."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane import Pipeline
from monoplane.contracts import RansacParams
from monoplane.errors import ConfigError
from monoplane.evaluation.segcomp import segcomp
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.graph import NeighbourGraph
from monoplane.stages.graph_refiner import (
    GraphCrfConfig,
    GraphCrfRefiner,
    _stable_order,
    _touching_pairs,
    lattice_cloud,
    pixel_graph,
)
from monoplane.testing import box_frame, check_work_ahead

#: The pipeline's shared thresholds at their defaults.
PARAMS = RansacParams()


def crease_cloud() -> tuple[PlaneCloud, np.ndarray]:
    """A floor (z = 0) meeting a wall (x = 0) at a right angle, normalised frame units."""
    s = np.arange(0.0, 0.5, 0.01)
    a, b = np.meshgrid(s, s)
    floor = np.stack([a.ravel() + 0.005, b.ravel(), np.zeros(a.size)], axis=1)
    wall = np.stack([np.zeros(a.size), b.ravel(), a.ravel() + 0.005], axis=1)
    points = np.vstack([floor, wall])
    normals = np.vstack([np.tile([0, 0, 1.0], (a.size, 1)), np.tile([1.0, 0, 0], (a.size, 1))])
    truth = np.repeat([1, 2], a.size).astype(np.int32)
    n = len(points)
    cloud = PlaneCloud(points=points, normals=normals, colors=None, pixels=np.arange(n),
                       center=np.zeros(3), scale=1.0, shape=(1, n), all_points=points,
                       all_pixels=np.arange(n))
    return cloud, truth


def test_crease_points_go_back_to_their_plane():
    cloud, truth = crease_cloud()
    graph = NeighbourGraph.build(cloud.points, 8)
    planes = np.array([[0, 0, 1.0, 0], [1.0, 0, 0, 0]])
    start = truth.copy()
    # RANSAC-like greedy errors: the floor took a strip of the wall near the crease, and a
    # few floor points were left non-planar.
    near_wall = (truth == 2) & (cloud.points[:, 2] < 0.03)
    start[near_wall] = 1
    start[(truth == 1) & (cloud.points[:, 0] > 0.4) & (cloud.points[:, 1] < 0.05)] = 0
    labels, refit = GraphCrfRefiner().refine_cloud(cloud, graph, start, planes, PARAMS)
    assert segcomp(labels, truth).correct == 2
    # Refined labels are renumbered by region size: compare through each region's majority.
    for g in (1, 2):
        values, counts = np.unique(labels[truth == g], return_counts=True)
        assert values[np.argmax(counts)] > 0 and counts.max() == counts.sum()
    assert refit.shape == (2, 4)


def test_separate_coplanar_parts_become_separate_planes():
    cloud, truth = crease_cloud()
    # Move half of the floor far away along its own plane: same plane, two parts.
    pts = cloud.points.copy()
    far = (truth == 1) & (pts[:, 1] > 0.25)
    pts[far, 0] += 2.0
    moved = PlaneCloud(points=pts, normals=cloud.normals, colors=None, pixels=cloud.pixels,
                       center=cloud.center, scale=1.0, shape=cloud.shape, all_points=pts,
                       all_pixels=cloud.all_pixels)
    graph = NeighbourGraph.build(pts, 8)
    labels, planes = GraphCrfRefiner().refine_cloud(
        moved, graph, truth, np.array([[0, 0, 1.0, 0], [1.0, 0, 0, 0]]), PARAMS)
    assert labels.max() == 3 and len(planes) == 3
    assert len(np.unique(labels[far])) == 1 and labels[far][0] not in labels[truth == 2]


def test_image_refinement_recovers_the_box():
    frame, true_labels = box_frame()
    pipe = Pipeline.from_preset("range")
    rec = pipe.run(frame)
    assert segcomp(rec.labels, true_labels).correct == 3


def test_bad_config():
    with pytest.raises(ConfigError, match="temperature"):
        GraphCrfConfig(temperature=0)


def test_noise_based_distance_scale_is_three_sigma():
    cloud, truth = crease_cloud()
    rng = np.random.default_rng(0)
    sigma = 0.001
    pts = cloud.points.copy()
    pts[truth == 1, 2] += rng.normal(0, sigma, (truth == 1).sum())
    pts[truth == 2, 0] += rng.normal(0, sigma, (truth == 2).sum())
    noisy = PlaneCloud(points=pts, normals=cloud.normals, colors=None, pixels=cloud.pixels,
                       center=cloud.center, scale=1.0, shape=cloud.shape, all_points=pts,
                       all_pixels=cloud.all_pixels)
    planes = np.array([[0, 0, 1.0, 0], [1.0, 0, 0, 0]])
    refiner = GraphCrfRefiner(GraphCrfConfig(noise_factor=3.0))
    assert refiner.distance_scale(noisy, truth, planes, PARAMS) == pytest.approx(3 * sigma, rel=0.1)
    # Never above the RANSAC's epsilon, and off by default.
    assert GraphCrfRefiner(GraphCrfConfig(noise_factor=1e3)).distance_scale(
        noisy, truth, planes, PARAMS) == 0.02
    assert GraphCrfRefiner().distance_scale(noisy, truth, planes, PARAMS) == 0.02


def test_refit_rounds_give_a_shallow_crease_strip_back():
    # A floor (z = 0, x < 0) meets a ramp rising at 30 deg (x > 0). The search gave the floor
    # a 0.2-wide strip of the ramp and fitted the floor's plane to both, tilted towards the
    # ramp. One mean-field round on those planes returns under half the strip; each later
    # round starts from planes refit to the labels so far and returns more.
    s = np.arange(0.0, 0.5, 0.01)
    a, b = (m.ravel() for m in np.meshgrid(s, s))
    tilt = np.radians(30)
    floor = np.stack([-a - 0.005, b, np.zeros(a.size)], axis=1)
    ramp = np.stack([a + 0.005, b, (a + 0.005) * np.tan(tilt)], axis=1)
    points = np.vstack([floor, ramp])
    normals = np.vstack([np.tile([0, 0, 1.0], (a.size, 1)),
                         np.tile([-np.sin(tilt), 0, np.cos(tilt)], (a.size, 1))])
    n = len(points)
    cloud = PlaneCloud(points=points, normals=normals, colors=None, pixels=np.arange(n),
                       center=np.zeros(3), scale=1.0, shape=(1, n), all_points=points,
                       all_pixels=np.arange(n))
    truth = np.repeat([1, 2], a.size).astype(np.int32)
    start = truth.copy()
    strip = (truth == 2) & (points[:, 0] < 0.2)
    start[strip] = 1
    from monoplane.geometry.planes import fit_planes_per_label

    planes = fit_planes_per_label(points, start, 2)[0]
    graph = NeighbourGraph.build(points, 8)
    returned = []
    for rounds in (1, 3):
        refiner = GraphCrfRefiner(GraphCrfConfig(rounds=rounds, normal_weight=0.0))
        labels, _ = refiner.refine_cloud(cloud, graph, start, planes, PARAMS)
        ramp_label = np.bincount(labels[truth == 2]).argmax()
        returned.append(np.mean(labels[strip] == ramp_label))
    assert returned[0] < 0.5 and returned[1] >= 0.75


def test_rounds_must_be_positive():
    with pytest.raises(ConfigError, match="rounds"):
        Pipeline.from_preset("range", overrides=["refiner.rounds=0"])


def test_pixel_graph_links_the_8_neighbours_within_the_jump():
    # A 6x7 frame: two fronto-parallel planes at 2 m and 3 m side by side, two holes.
    depth = np.full((6, 7), 2.0, dtype=np.float32)
    depth[:, 4:] = 3.0
    depth[1, 1] = depth[4, 5] = 0.0
    normals = np.zeros((6, 7, 3), dtype=np.float32)
    normals[..., 2] = -1.0
    frame = box_frame()[0].with_(depth=depth, normals=normals, rgb=None,
                                 K=np.array([[5.0, 0, 3], [0, 5.0, 2.5], [0, 0, 1]]))
    cloud = PlaneCloud.from_frame(frame)
    graph = pixel_graph(cloud, 0.05)
    # Brute force: every pair of 8-neighbouring valid pixels closer in 3D than 5 % of the
    # first pixel's (in raster order) distance from the camera.
    node = {int(p): i for i, p in enumerate(cloud.pixels)}
    pts = cloud.points * cloud.scale + cloud.center
    expected = set()
    for p, i in node.items():
        v, u = divmod(p, 7)
        for dv, du in ((0, 1), (1, -1), (1, 0), (1, 1)):
            q = (v + dv) * 7 + u + du
            if v + dv < 6 and 0 <= u + du < 7 and q in node:
                j = node[q]
                if np.linalg.norm(pts[i] - pts[j]) <= 0.05 * np.linalg.norm(pts[i]):
                    expected.add((i, j))
    assert [tuple(e) for e in graph.edges] == sorted(expected)
    # Nothing links the 2 m plane to the 3 m one.
    far = cloud.points[:, 2] * cloud.scale + cloud.center[2] > 2.5
    assert not np.any(far[graph.edges[:, 0]] != far[graph.edges[:, 1]])
    for i in range(cloud.size):  # the adjacency lists each edge at both ends
        row = graph.indices[graph.indptr[i]:graph.indptr[i + 1]]
        assert sorted(row) == sorted({b for a, b in expected if a == i}
                                     | {a for a, b in expected if b == i})


def test_a_lattice_clouds_graph_links_its_8_lattice_neighbours():
    frame, _ = box_frame(width=64, height=48)
    # 3072 pixels: a lattice of step 2 has 768, of step 3 336.
    cloud = lattice_cloud(frame, 400)
    assert cloud.stride == 3 and np.all(cloud.pixels // 64 % 3 == 1)
    graph = pixel_graph(cloud, 0.05)
    pts = cloud.points * cloud.scale + cloud.center
    node = {int(p): i for i, p in enumerate(cloud.pixels)}
    expected = set()
    for p, i in node.items():
        v, u = divmod(p, 64)
        for dv, du in ((0, 3), (3, -3), (3, 0), (3, 3)):
            j = node.get((v + dv) * 64 + u + du) if 0 <= u + du < 64 else None
            if j is not None and (np.linalg.norm(pts[i] - pts[j])
                                  <= 0.05 * np.linalg.norm(pts[i])):
                expected.add((i, j))
    assert [tuple(e) for e in graph.edges] == sorted(expected)


def test_refinement_on_a_lattice_labels_every_pixel_like_the_full_one():
    # A lattice step of 2 pixels must stay well below the depth-jump cut on the box's
    # slanted faces: a finer image than box_frame's default.
    frame, true_labels = box_frame(width=256, height=192, focal=160.0)
    rec = Pipeline.from_preset("range", overrides=["refiner.plugin=none"]).run(frame)
    full = GraphCrfRefiner(GraphCrfConfig()).refine(rec, PARAMS)
    # 49 152 pixels, 12 288 on a lattice of step 2.
    coarse = GraphCrfRefiner(GraphCrfConfig(max_points=20000)).refine(rec, PARAMS)
    assert segcomp(coarse.labels, true_labels).correct == 3
    # Off the lattice too: the box's pixels get the labels of the full-resolution CRF
    # (up to the regions' numbering, which is by size in both).
    assert np.mean(coarse.labels == full.labels) > 0.99


def test_the_threaded_mean_field_does_not_depend_on_the_threads(monkeypatch):
    frame, _ = box_frame(width=160, height=120)
    rec = Pipeline.from_preset("range", overrides=["refiner.plugin=none"]).run(frame)
    refiner = GraphCrfRefiner(GraphCrfConfig())
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    one = refiner.refine(rec, PARAMS)
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    two = refiner.refine(rec, PARAMS)
    np.testing.assert_array_equal(one.labels, two.labels)
    np.testing.assert_array_equal(one.planes, two.planes)


def test_graph_prepared_in_the_background_changes_nothing(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    frame, _ = box_frame(width=160, height=120)
    rec = Pipeline.from_preset("range", overrides=["refiner.plugin=none"]).run(frame)
    config = GraphCrfConfig(max_points=10000)  # on a lattice of step 2
    check_work_ahead(lambda: GraphCrfRefiner(config), frame, box_frame(width=128, height=96)[0],
                     rec, PARAMS, monkeypatch)


def test_touching_pairs_and_label_order_match_numpy():
    rng = np.random.default_rng(3)
    labels = rng.integers(0, 9, 2000)
    edges = np.sort(rng.integers(0, 2000, (6000, 2)), axis=1)
    a, b = labels[edges[:, 0]], labels[edges[:, 1]]
    touch = (a > 0) & (b > 0) & (a != b)
    want = np.unique(np.sort(np.stack([a[touch], b[touch]], axis=1), axis=1), axis=0)
    np.testing.assert_array_equal(_touching_pairs(labels, edges, 8), want)
    np.testing.assert_array_equal(_stable_order(labels, np.bincount(labels, minlength=9)),
                                  np.argsort(labels, kind="stable"))
