from dataclasses import replace

import numpy as np
import pytest

from monoplane.datamodel import (
    RESULT_KINDS,
    Camera,
    CloudResult,
    Frame,
    PlaneSet,
    Reconstruction,
    Scene,
    default_intrinsics,
    intrinsics_matrix,
    orient_towards_camera,
    pixel_rays,
    plane_to_camera,
    plane_to_world,
)
from monoplane.errors import InvalidInput
from monoplane.testing import CORNER_PLANES, box_frame


def frame(**kw):
    corner, _ = box_frame(64, 48, CORNER_PLANES, focal=50.0)
    depth = corner.depth
    args = dict(rgb=np.zeros((*depth.shape, 3), np.uint8), K=corner.K, depth=depth)
    args.update(kw)
    return Frame(**args)


def test_pixel_rays_have_unit_z_and_hit_principal_point():
    K = intrinsics_matrix(100, 80, 10, 5)
    rays = pixel_rays(K, 12, 20)
    assert np.allclose(rays[..., 2], 1)
    assert np.allclose(rays[5, 10], [0, 0, 1])
    assert np.allclose(rays[5, 11], [1 / 100, 0, 1])


def test_default_intrinsics_has_60_degree_fov():
    K = default_intrinsics(640, 480)
    assert np.isclose(2 * np.degrees(np.arctan(320 / K[0, 0])), 60)


@pytest.mark.parametrize("kw, match", [
    (dict(depth=np.zeros((48, 64), np.float32)), "no valid"),
    (dict(depth=np.full((48, 64), np.nan, np.float32)), "NaN or inf"),
    (dict(depth=np.ones((40, 64), np.float32)), "differs from image size"),
    (dict(normals=np.ones((48, 64, 2), np.float32)), r"shape \(H, W, 3\)"),
    (dict(normals=np.full((48, 64, 3), 0.9, np.float32)), "unit length"),
    (dict(K=np.eye(2)), "3x3"),
    (dict(K=np.diag([0.0, 1.0, 1.0])), "positive"),
    (dict(rgb=np.zeros((48, 64, 3), np.float32)), "uint8"),
    (dict(depth_kind="metres"), "depth_kind"),
])
def test_frame_validation(kw, match):
    with pytest.raises(InvalidInput, match=match):
        frame(**kw)


def test_frame_points_unproject_depth():
    f = frame()
    pts = f.points()
    assert np.allclose(pts[..., 2], f.depth)
    u, v = 7, 30
    assert np.allclose(f.K @ (pts[v, u] / pts[v, u, 2]), [u, v, 1])


def test_grey_image_has_no_colour():
    assert not frame(rgb=np.full((48, 64, 3), 90, np.uint8)).has_color
    assert not frame(rgb=None).has_color


def test_orientation_makes_offset_positive():
    p = orient_towards_camera(np.array([[0, 2, 0, -4.0]]))
    assert np.allclose(p, [[0, -1, 0, 2]])


def test_planar_depth_reproduces_exact_depth():
    corner, labels = box_frame(64, 48, CORNER_PLANES, focal=50.0)
    depth = corner.depth
    rec = Reconstruction(frame=frame(), labels=labels, planes=CORNER_PLANES)
    assert np.allclose(rec.planar_depth(), depth, rtol=1e-5)
    assert rec.area_px.sum() == depth.size
    assert rec.support.tolist() == rec.area_px.tolist()


def test_reconstruction_rejects_labels_beyond_planes():
    with pytest.raises(InvalidInput, match="labels must lie"):
        Reconstruction(frame=frame(), labels=np.full((48, 64), 2), planes=np.zeros((1, 4)) + 1)


def test_plane_world_round_trip():
    rng = np.random.default_rng(1)
    R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    R *= np.sign(np.linalg.det(R))
    t = rng.normal(size=3)
    cam = Camera(K=intrinsics_matrix(100, 100, 50, 50), R=R, t=t, width=100, height=100)
    plane_c = orient_towards_camera(np.array([0.2, -0.9, 0.1, 1.3]))
    x_c = -plane_c[3] * plane_c[:3]  # the foot of the perpendicular, on the plane
    x_w = R.T @ (x_c - t)
    plane_w = plane_to_world(plane_c, R, t)[0]
    assert np.isclose(plane_w[:3] @ x_w + plane_w[3], 0)
    assert np.allclose(plane_to_camera(plane_w, R, t)[0], plane_c)
    assert np.allclose(cam.center, R.T @ -t)


def test_data_model_imports_nothing_of_the_project_but_errors_jit_and_the_aliases() -> None:
    import subprocess
    import sys

    code = ("import sys, monoplane.datamodel; "
            "print(sorted(m for m in sys.modules if m.startswith('monoplane') "
            "and not m.startswith('monoplane.datamodel.'))); "
            "print('cv2' in sys.modules, 'pluggy' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded = ("['monoplane', 'monoplane.datamodel', 'monoplane.errors', 'monoplane.jit', "
              "'monoplane.moved_modules']")
    assert out.stdout.split("\n")[:2] == [loaded, "False False False"]


def test_a_single_view_run_imports_no_scipy_submodule_it_does_not_use() -> None:
    # Each costs 0.1-0.15 s of start-up in every command and batch driver.
    import subprocess
    import sys

    code = ("import sys, numpy as np; from monoplane.host.pipeline import Pipeline; "
            "from monoplane.datamodel import Frame; "
            "v, u = np.mgrid[0:72, 0:96]; "
            "depth = np.where(u < 48, 2.0, 1.5 + 0.01 * u).astype(np.float32); "
            "normals = np.zeros((72, 96, 3), np.float32); normals[..., 2] = -1; "
            "rgb = (np.random.default_rng(0).random((72, 96, 3)) * 255).astype(np.uint8); "
            "K = np.array([[80.0, 0, 48], [0, 80.0, 36], [0, 0, 1]]); "
            "Pipeline.from_preset('monoplane').run(Frame(rgb=rgb, K=K, depth=depth, "
            "normals=normals)); "
            "print(sorted(m for m in ('scipy.sparse', 'scipy.spatial', 'scipy.optimize', "
            "'scipy.ndimage') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_package_names_load_on_first_use() -> None:
    import monoplane
    from monoplane.host.pipeline import Pipeline

    assert monoplane.Pipeline is Pipeline and "Pipeline" in dir(monoplane)
    assert set(monoplane.__all__) <= set(dir(monoplane))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        _ = monoplane.nope


def test_validation_kernels_count_as_the_numpy_checks() -> None:
    from monoplane.datamodel.frame import _depth_counts, _normal_counts

    rng = np.random.default_rng(5)
    depth = rng.normal(1.0, 1.0, size=(20, 30)).astype(np.float32)
    depth[0, :3] = [np.nan, np.inf, 0.0]
    assert _depth_counts(depth) == (int((~np.isfinite(depth)).sum()),
                                    int((depth[np.isfinite(depth)] < 0).sum()),
                                    int((depth[np.isfinite(depth)] > 0).sum()))
    normals = rng.normal(size=(20, 30, 3)).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    normals[1] *= np.float32(1.0 + np.linspace(-0.02, 0.02, 30, dtype=np.float32))[:, None]
    normals[2, :4] = [np.nan, 0.0, 0.0]
    normals[3, :4] = 0.0
    finite = np.isfinite(normals).all(axis=-1)
    norm = np.linalg.norm(np.where(finite[..., None], normals, 0), axis=-1)
    bad = finite & (norm > 0) & (np.abs(norm - 1.0) > 1e-2)
    assert _normal_counts(normals) == (int((~finite).sum()), int(bad.sum()))
    assert 0 < bad.sum() < 30


def test_valid_mask_is_positive_depth_and_a_non_zero_normal() -> None:
    rng = np.random.default_rng(6)
    depth = rng.uniform(0.5, 3.0, size=(20, 30)).astype(np.float32)
    depth[0, :5] = 0.0
    normals = rng.normal(size=(20, 30, 3)).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    normals[1, :6] = 0.0
    normals[2, :3] = [[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]  # one axis left
    normals[0, 3] = 0.0  # invalid in both
    frame = Frame(rgb=None, K=default_intrinsics(30, 20), depth=depth, normals=normals)
    expected = (depth > 0) & np.any(normals != 0, axis=-1)
    assert frame.valid.dtype == bool and np.array_equal(frame.valid, expected)
    assert expected.sum() == 20 * 30 - 5 - 6
    assert np.array_equal(frame.with_(normals=None).valid, depth > 0)


def test_every_result_is_a_plane_set_with_planes_ids_and_support() -> None:
    _, labels = box_frame(64, 48, CORNER_PLANES, focal=50.0)
    rec = Reconstruction(frame=frame(), labels=labels, planes=CORNER_PLANES)
    P = len(CORNER_PLANES)
    assert isinstance(rec, PlaneSet) and rec.result_kind == "frame"
    assert rec.planes.shape == (P, 4) and rec.ids.tolist() == list(range(1, P + 1))
    cam = Camera(K=frame().K, R=np.eye(3), t=np.zeros(3), width=64, height=48)
    # both views' plane 1 is global plane 0; the second view's plane 2 is global plane 1
    scene = Scene(cameras=[cam, cam], views=[rec, rec], planes=rec.planes[:2],
                  links=[{1: 0}, {1: 0, 2: 1}])
    assert isinstance(scene, PlaneSet) and scene.result_kind == "scene"
    assert scene.ids.tolist() == [0, 1]
    assert scene.support.tolist() == [2 * rec.area_px[0], rec.area_px[1]]
    cloud = CloudResult(points=np.eye(3), labels=[1, 1, 0], planes=[0, 0, 1, 0.0],
                        rmse=[0.0])
    assert cloud.result_kind == "cloud" and cloud.planes.shape == (1, 4)
    assert cloud.support.tolist() == [2] and cloud.ids.tolist() == [1]
    assert sorted({rec.result_kind, scene.result_kind, cloud.result_kind}) == \
        sorted(RESULT_KINDS[:3])


def test_the_former_attribute_names_still_work_with_a_warning() -> None:
    _, labels = box_frame(64, 48, CORNER_PLANES, focal=50.0)
    with pytest.warns(DeprecationWarning, match=r"Reconstruction\.planes"):
        rec = Reconstruction(frame=frame(), labels=labels, params=CORNER_PLANES)
    with pytest.warns(DeprecationWarning, match=r"Reconstruction\.planes"):
        assert rec.params is rec.planes
    with pytest.warns(DeprecationWarning):
        moved = replace(rec, params=rec.planes * 2)  # the old keyword wins over the field
    np.testing.assert_allclose(moved.planes, rec.planes)  # re-normalised on the way in
    with pytest.warns(DeprecationWarning, match=r"CloudResult\.support"):
        cloud = CloudResult(np.eye(3), [1, 1, 0], [0, 0, 1, 0.0], [0.0], num_points=[2])
    assert cloud.support.tolist() == [2]


def test_results_reject_malformed_planes_in_one_line() -> None:
    with pytest.raises(InvalidInput, match="4 values per plane"):
        CloudResult(np.eye(3), [1, 1, 0], [0, 0, 1], [0.0])
    with pytest.raises(InvalidInput, match="must have 1 rows"):
        CloudResult(np.eye(3), [1, 1, 0], [0, 0, 1, 0.0], [0.0, 1.0])
