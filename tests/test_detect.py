"""detect_planes on exact analytic clouds, degenerate input and both Open3D cloud types."""

from __future__ import annotations

import numpy as np
import open3d as o3d
import pytest

from monoplane.contracts import Refiner, Sampler
from monoplane.datamodel import CloudResult
from monoplane.errors import ConfigError, InvalidInput, StageError
from monoplane.geometry.cloud_mesh import cloud_mesh
from monoplane.geometry.open3d_objects import cloud_plane_meshes, cloud_to_open3d
from monoplane.hookspecs import hookimpl
from monoplane.host.detect import CloudPlaneResult, detect_planes
from monoplane.host.pipeline import Pipeline
from monoplane.host.registry import get_plugin_manager
from monoplane.testing import box_frame


def grid(x0: float, x1: float, y0: float, y1: float, z: float, step: float) -> np.ndarray:
    """Points of a regular grid on the horizontal rectangle at height z."""
    xs, ys = np.meshgrid(np.arange(x0, x1 + 1e-9, step), np.arange(y0, y1 + 1e-9, step))
    return np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, z)], axis=1)


def two_coplanar_tops() -> tuple[np.ndarray, np.ndarray]:
    """A floor and two separate box tops 0.4 above it at the same height, shuffled.

    Returns the points (N, 3) and their true group (N,) 0 = floor, 1, 2 = the two tops. The
    sensor sits at (0, 0, 3) above the scene.
    """
    floor = grid(-1.0, 1.0, -1.0, 1.0, 0.0, 0.025)
    top_a = grid(-0.8, -0.3, -0.5, 0.5, 0.4, 0.02)
    top_b = grid(0.3, 0.8, -0.5, 0.5, 0.4, 0.02)
    points = np.vstack([floor, top_a, top_b])
    group = np.repeat([0, 1, 2], [len(floor), len(top_a), len(top_b)])
    order = np.random.default_rng(3).permutation(len(points))
    return points[order], group[order]


VIEW = ["cloud.viewpoint=[0.0, 0.0, 3.0]"]


def check_groups(labels: np.ndarray, group: np.ndarray) -> None:
    """Each true group is one plane, all different: the labels follow the input order."""
    ids = []
    for g in np.unique(group):
        values, counts = np.unique(labels[group == g], return_counts=True)
        assert values[0] > 0 and counts[0] == counts.sum(), f"group {g} got labels {values}"
        ids.append(values[0])
    assert len(set(ids)) == len(ids)


def test_coplanar_separate_tops_stay_two_planes_in_input_order():
    points, group = two_coplanar_tops()
    res = detect_planes(points, overrides=VIEW)
    assert res.labels.shape == (len(points),) and res.labels.dtype == np.int32
    assert res.num_planes == 3
    check_groups(res.labels, group)
    for pid in range(1, 4):
        n, d = res.planes[pid - 1, :3], res.planes[pid - 1, 3]
        z = points[res.labels == pid, 2][0]
        # Horizontal planes at the true height, in the input's units, facing the sensor (+z).
        np.testing.assert_allclose(n, [0, 0, 1], atol=1e-6)
        assert d == pytest.approx(-z, abs=1e-6)
        assert res.rmse[pid - 1] < 1e-6
        assert res.support[pid - 1] == np.sum(res.labels == pid)


def test_legacy_and_tensor_open3d_clouds_agree_with_arrays():
    points, group = two_coplanar_tops()
    legacy = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    tensor = o3d.t.geometry.PointCloud(o3d.core.Tensor(points.astype(np.float32)))
    for cloud in (legacy, tensor):
        res = detect_planes(cloud, overrides=VIEW)
        assert res.num_planes == 3
        check_groups(res.labels, group)


def test_given_normals_and_colours_are_used():
    points, group = two_coplanar_tops()
    legacy = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    legacy.normals = o3d.utility.Vector3dVector(np.tile([0.0, 0.0, 1.0], (len(points), 1)))
    legacy.colors = o3d.utility.Vector3dVector(np.full((len(points), 3), 0.5))
    res = detect_planes(legacy)
    assert not any("estimated" in note for note in res.notes)
    check_groups(res.labels, group)


def test_duplicated_points_share_their_twin_label():
    points, group = two_coplanar_tops()
    doubled = np.vstack([points, points])
    res = detect_planes(doubled, overrides=VIEW)
    n = len(points)
    np.testing.assert_array_equal(res.labels[:n], res.labels[n:])
    check_groups(res.labels[:n], group)
    assert any("duplicate" in note for note in res.notes)


def test_flat_input_is_one_plane():
    points = grid(0.0, 2.0, 0.0, 1.0, 5.0, 0.02)
    res = detect_planes(points)
    assert res.num_planes == 1 and np.all(res.labels == 1)
    assert abs(res.planes[0, 2]) == pytest.approx(1.0)


def test_nan_and_inf_points_are_left_unlabelled():
    points, group = two_coplanar_tops()
    bad = points.copy()
    bad[::50, 0] = np.nan
    bad[1::50, 2] = np.inf
    res = detect_planes(bad, overrides=VIEW)
    broken = ~np.isfinite(bad).all(axis=1)
    assert np.all(res.labels[broken] == 0)
    check_groups(res.labels[~broken], group[~broken])
    assert any("NaN/inf" in note for note in res.notes)


@pytest.mark.parametrize("points", [
    np.zeros((0, 3)), np.zeros((2, 3)), np.ones((100, 3)),
    np.full((10, 3), np.nan), np.array([[0.0, 0, 0], [1, 0, 0], [1, 0, 0], [np.inf, 0, 0]]),
])
def test_fewer_than_three_distinct_points_is_a_clear_error(points):
    with pytest.raises(InvalidInput, match="distinct finite point"):
        detect_planes(points)


def test_too_few_or_collinear_points_give_no_plane():
    for points in (np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]),
                   np.c_[np.linspace(0, 1, 200), np.zeros(200), np.zeros(200)]):
        res = detect_planes(points)
        assert res.num_planes == 0 and np.all(res.labels == 0)


@pytest.mark.parametrize("bad", [np.zeros((5, 2)), "not a cloud", np.zeros((4, 3, 1))])
def test_malformed_input(bad):
    with pytest.raises(InvalidInput):
        detect_planes(bad)


def test_pixel_refiner_is_rejected():
    points, _ = two_coplanar_tops()
    with pytest.raises(ConfigError, match="images only"):
        detect_planes(points, overrides=["refiner.plugin=dense-crf"])


def test_large_cloud_is_subsampled_but_every_point_labelled():
    points, group = two_coplanar_tops()
    res = detect_planes(points, overrides=[*VIEW, "ransac.max_points=2000"])
    assert any("search on 2000" in note for note in res.notes)
    check_groups(res.labels, group)


def test_conversions_to_open3d():
    points, _ = two_coplanar_tops()
    res = detect_planes(points, overrides=VIEW)
    pcd = cloud_to_open3d(res)
    assert len(pcd.points) == len(points) and pcd.has_colors()
    meshes = cloud_plane_meshes(res)
    assert len(meshes) == res.num_planes
    for pid, mesh in enumerate(meshes, start=1):
        v = np.asarray(mesh.vertices)
        assert len(mesh.triangles) > 0
        n, d = res.planes[pid - 1, :3], res.planes[pid - 1, 3]
        np.testing.assert_allclose(v @ n + d, 0.0, atol=1e-9)
        # The outline covers the plane's points: the mesh area matches the rectangle's.
        pts = points[res.labels == pid]
        box = np.ptp(pts[:, 0]) * np.ptp(pts[:, 1])
        assert mesh.get_surface_area() == pytest.approx(box, rel=0.25)


def test_the_result_speaks_the_plane_set_vocabulary_and_the_old_names_warn():
    points, _ = two_coplanar_tops()
    res = detect_planes(points, overrides=VIEW)
    assert isinstance(res, CloudResult) and res.result_kind == "cloud"
    assert res.planes.shape == (3, 4) and res.planes.dtype == np.float64
    assert res.ids.tolist() == [1, 2, 3]
    assert res.support.tolist() == np.bincount(res.labels, minlength=4)[1:].tolist()
    with pytest.warns(DeprecationWarning, match="CloudResult.support"):
        assert res.num_points is res.support
    with pytest.warns(DeprecationWarning, match="cloud_to_open3d"):
        assert len(res.to_open3d().points) == len(points)
    with pytest.warns(DeprecationWarning, match="cloud_mesh"):
        assert len(res.plane_mesh().triangles) == len(cloud_mesh(res).triangles)
    with pytest.warns(DeprecationWarning, match="CloudResult.support"):
        again = CloudPlaneResult(res.points, res.labels, res.planes, res.rmse,
                                 num_points=res.support, centroids=res.centroids)
    assert again.support.tolist() == res.support.tolist()


class _StageLog:
    """A plugin that records every finished stage (the ``monoplane_stage_finished`` hook)."""

    def __init__(self) -> None:
        self.seen: list[tuple[str, str]] = []

    @hookimpl
    def monoplane_stage_finished(self, kind: str, name: str, seconds: float,
                                 frame_name: str) -> None:
        self.seen.append((kind, frame_name))


def test_a_plugin_sees_the_stages_of_a_cloud_run_as_of_an_image_run():
    log = _StageLog()
    pm = get_plugin_manager(autoload=False, extra_plugins=(log,))
    points, _ = two_coplanar_tops()
    detect_planes(points, overrides=VIEW, pm=pm)
    cloud_run = list(log.seen)
    log.seen.clear()
    frame = box_frame()[0]
    Pipeline.from_preset("monoplane-nocrf", pm=pm).run(frame)
    image_run = [kind for kind, name in log.seen if name == frame.name]
    assert cloud_run[:2] == [("ransac", "cloud"), ("refiner", "cloud")]
    assert image_run[:3] == ["cues", "ransac", "refiner"]


class _Failing(Refiner):
    """A pixel-free refiner that fails, as a plugin's bug would."""

    name = "failing"
    needs_pixels = False

    def refine_cloud(self, cloud, graph, labels, planes, params):
        raise RuntimeError("boom")


class _FailingPlugin:
    @hookimpl
    def monoplane_register_refiners(self):
        return [_Failing]


def test_a_failing_stage_of_a_cloud_run_is_a_stage_error():
    pm = get_plugin_manager(autoload=False, extra_plugins=(_FailingPlugin(),))
    points, _ = two_coplanar_tops()
    with pytest.raises(StageError, match="refiner.*failing.*boom"):
        detect_planes(points, overrides=[*VIEW, "refiner.plugin=failing"], pm=pm)


class _BrokenSampler(Sampler):
    """A sampler that fails, as a plugin's bug would; it states no draw, so it is called."""

    name = "broken-sampler"

    def sample(self, cloud, pool, count, rng, params):
        raise RuntimeError("no triplets today")


class _BrokenSamplerPlugin:
    @hookimpl
    def monoplane_register_samplers(self):
        return [_BrokenSampler]


def test_a_failing_sampler_is_named_alike_in_cloud_and_frame_runs():
    # Frames and clouds share the driver and the one StageError wrapper: the innermost
    # failing stage is named, not the RANSAC that called it.
    pm = get_plugin_manager(autoload=False, extra_plugins=(_BrokenSamplerPlugin(),))
    message = "sampler stage 'broken-sampler' failed: no triplets today"
    points, _ = two_coplanar_tops()
    with pytest.raises(StageError, match=message):
        detect_planes(points, overrides=[*VIEW, "sampler.plugin=broken-sampler"], pm=pm)
    with pytest.raises(StageError, match=message):
        Pipeline.from_preset("monoplane-nocrf", overrides=["sampler.plugin=broken-sampler"],
                             pm=pm).run(box_frame()[0])
