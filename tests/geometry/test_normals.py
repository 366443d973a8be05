"""Normals from depth: exact on planes, no smearing across edges, holes stay invalid."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from monoplane.datamodel import default_intrinsics, intrinsics_matrix, pixel_rays, ray_plane_depth
from monoplane.errors import InvalidInput
from monoplane.geometry.normals import normals_from_depth
from monoplane.testing import CORNER_PLANES, box_frame

LIVINGROOM = Path("/work/shared/data/rgbd-livingroom")
METHODS = ["gated", "box"]


def plane_depth(K: np.ndarray, h: int, w: int, plane: np.ndarray) -> np.ndarray:
    """Exact z-depth of the plane (n, d) on every pixel (camera frame, OpenCV axes)."""
    return ray_plane_depth(pixel_rays(K, h, w), plane).astype(np.float32)


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def angles_deg(normals: np.ndarray, n: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(normals @ n, -1.0, 1.0)))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("radius,stride", [(3, 1), (6, 2), (9, 3)])
def test_exact_plane_gives_plane_normal(radius: int, stride: int, method: str) -> None:
    h, w = 96, 128
    K = default_intrinsics(w, h)
    n = unit([0.3, -0.5, -0.8])
    depth = plane_depth(K, h, w, np.r_[n, 2.0])
    normals = normals_from_depth(depth, K, radius=radius, stride=stride, method=method)
    assert normals.shape == (h, w, 3) and normals.dtype == np.float32
    assert np.all(np.linalg.norm(normals, axis=-1) > 0.999)
    assert angles_deg(normals.reshape(-1, 3), n).max() < 0.5


def test_box_fits_are_exact_on_wide_images() -> None:
    # 2000 pixels wide, a 41x41 window: the fixed-point samples get fewer bits (22) so that
    # the row's int64 prefix sums stay in range, and the fits are still exact.
    h, w = 60, 2000
    K = default_intrinsics(w, h)
    n = unit([0.2, -0.3, -0.9])
    normals = normals_from_depth(plane_depth(K, h, w, np.r_[n, 2.0]), K, method="box")
    assert angles_deg(normals.reshape(-1, 3), n).max() < 0.5


@pytest.mark.parametrize("method", METHODS)
def test_normals_face_the_camera_and_ignore_depth_scale(method: str) -> None:
    h, w = 48, 64
    K = default_intrinsics(w, h)
    n = unit([-0.2, 0.1, -1.0])
    depth = plane_depth(K, h, w, np.r_[n, 1.5])
    normals = normals_from_depth(depth, K, method=method)
    rays = pixel_rays(K, h, w)
    assert np.all(np.sum(normals * rays, axis=-1) < 0)
    # Only depth ratios matter: relative depth gives the same normals.
    np.testing.assert_allclose(normals_from_depth(depth * 37.0, K, method=method), normals,
                               atol=1e-4)


@pytest.mark.parametrize("method", METHODS)
def test_no_smearing_across_a_depth_discontinuity(method: str) -> None:
    h, w = 60, 80
    K = intrinsics_matrix(70.0, 70.0, 39.5, 29.5)
    near = unit([0.5, 0.0, -1.0])
    far = unit([-0.4, -0.3, -1.0])
    d_near = plane_depth(K, h, w, np.r_[near, 1.0])
    d_far = plane_depth(K, h, w, np.r_[far, 3.0])
    depth = d_far.copy()
    depth[:, :40] = d_near[:, :40]          # vertical occluding edge between columns 39 and 40
    assert np.all(d_far[:, 40] > 1.2 * d_near[:, 39])
    normals = normals_from_depth(depth, K, method=method)
    left, right = normals[:, :40].reshape(-1, 3), normals[:, 40:].reshape(-1, 3)
    # Every pixel, including the ones touching the edge, keeps its own plane's normal.
    assert angles_deg(left, near).max() < 0.5
    assert angles_deg(right, far).max() < 0.5


@pytest.mark.parametrize("method", METHODS)
def test_holes_stay_invalid_and_do_not_bias_neighbours(method: str) -> None:
    h, w = 48, 64
    K = default_intrinsics(w, h)
    n = unit([0.1, -0.6, -0.8])
    depth = plane_depth(K, h, w, np.r_[n, 2.0])
    depth[10:20, 10:30] = 0.0
    depth[30:35, 40:50] = np.nan
    depth[5, 50] = np.inf
    normals = normals_from_depth(depth, K, method=method)
    holes = ~(np.isfinite(depth) & (depth > 0))
    assert np.all(normals[holes] == 0)
    assert angles_deg(normals[~holes], n).max() < 0.5


@pytest.mark.parametrize("method", METHODS)
def test_isolated_specks_get_no_normal(method: str) -> None:
    h, w = 32, 32
    K = default_intrinsics(w, h)
    depth = np.zeros((h, w), np.float32)
    depth[16, 10:20] = 2.0                  # a one-pixel-high line: no plane is defined
    depth[5, 5] = 1.0
    normals = normals_from_depth(depth, K, method=method)
    assert np.all(normals == 0)


@pytest.mark.parametrize("method", METHODS)
def test_noisy_plane_is_smooth_enough_for_ransac(method: str) -> None:
    rng = np.random.default_rng(0)
    h, w = 120, 160
    K = default_intrinsics(w, h)
    n = unit([0.2, -0.4, -0.9])
    depth = plane_depth(K, h, w, np.r_[n, 2.0])
    depth *= 1.0 + 0.002 * rng.standard_normal(depth.shape).astype(np.float32)
    normals = normals_from_depth(depth, K, method=method)
    ang = angles_deg(normals.reshape(-1, 3), n)
    assert np.percentile(ang, 90) < 10.0    # RANSAC's normal threshold ε_n


@pytest.mark.parametrize("kwargs", [{"radius": 0}, {"radius": 2, "stride": 3},
                                    {"max_jump": 0.0}, {"method": "integral"}])
def test_bad_parameters_are_rejected(kwargs: dict) -> None:
    with pytest.raises(InvalidInput):
        normals_from_depth(np.ones((8, 8), np.float32), np.eye(3), **kwargs)


def test_bad_shapes_are_rejected() -> None:
    with pytest.raises(InvalidInput, match="depth"):
        normals_from_depth(np.ones((8, 8, 1)), np.eye(3))
    with pytest.raises(InvalidInput, match="K"):
        normals_from_depth(np.ones((8, 8)), np.eye(2))


def _livingroom_depth() -> tuple[np.ndarray, np.ndarray]:
    cv2 = pytest.importorskip("cv2")
    path = LIVINGROOM / "depth_00000.png"
    if not path.is_file():
        pytest.skip(f"{path} not available")
    # README: uint16 millimetres, fx = fy = 525, cx = 319.5, cy = 239.5.
    depth = cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(np.float32) / 1000.0
    return depth, intrinsics_matrix(525.0, 525.0, 319.5, 239.5)


@pytest.mark.parametrize("method", METHODS)
def test_real_rgbd_frame_floor_and_wall(method: str) -> None:
    from monoplane.geometry.planes import fit_plane

    depth, K = _livingroom_depth()
    normals = normals_from_depth(depth, K, method=method)
    valid_depth = depth > 0
    has_normal = np.any(normals != 0, axis=-1)
    assert not np.any(has_normal & ~valid_depth)
    assert has_normal.sum() > 0.99 * valid_depth.sum()
    points = pixel_rays(K, *depth.shape) * depth[..., None]
    # Floor (bottom rows) and the wall above the chair, measured against a plane fit.
    for rows, cols, median_max, p90_max in (((400, 470), (50, 600), 2.0, 5.0),
                                            ((20, 100), (450, 600), 10.0, 20.0)):
        m = np.zeros(depth.shape, bool)
        m[slice(*rows), slice(*cols)] = True
        m &= has_normal
        plane, _ = fit_plane(points[m])
        ang = angles_deg(normals[m], plane[:3])
        assert np.median(ang) < median_max and np.percentile(ang, 90) < p90_max
    floor = normals[440, 320]
    assert floor[1] < -0.95                 # the floor faces up (-y) towards the camera


def test_auto_window_scales_with_the_image() -> None:
    from monoplane.geometry.normals import auto_window

    assert auto_window(480, 640) == (6, 2)
    assert auto_window(192, 256) == (3, 1)
    assert auto_window(48, 64) == (1, 1)


@pytest.mark.parametrize("method", METHODS)
def test_small_images_keep_creases_sharp(method: str) -> None:
    # Room corner at 64x48: floor and two walls meet without depth jumps. The automatic
    # window stays small enough that most pixels keep their own plane's normal.
    corner, labels = box_frame(64, 48, CORNER_PLANES, focal=50.0)
    normals = normals_from_depth(corner.depth, corner.K, method=method)
    own = CORNER_PLANES[labels - 1, :3]
    ang = np.degrees(np.arccos(np.clip(np.sum(normals * own, axis=-1), -1, 1)))
    assert np.mean(ang < 10) > 0.88


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("threads", ["2", "3"])
def test_the_threaded_row_pieces_give_the_same_normals(monkeypatch: pytest.MonkeyPatch,
                                                       method: str, threads: str) -> None:
    # Three planes meeting at depth jumps, with holes: interior, band and rim pixels in every
    # piece of rows, windows cut by the pieces' boundaries, and (at two threads) a jump
    # between rows 99 and 100, where the pieces of the rim test meet.
    h, w = 200, 160
    K = default_intrinsics(w, h)
    depth = plane_depth(K, h, w, np.r_[unit([0.2, -0.7, -0.6]), 2.0])
    depth[:, 80:] = plane_depth(K, h, w, np.r_[unit([-0.3, 0.1, -0.9]), 3.5])[:, 80:]
    depth[100:, 120:] = plane_depth(K, h, w, np.r_[unit([0.1, 0.2, -0.9]), 2.5])[100:, 120:]
    depth[90:110, 20:40] = 0.0
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    one = normals_from_depth(depth, K, method=method)
    monkeypatch.setenv("OMP_NUM_THREADS", threads)
    np.testing.assert_array_equal(normals_from_depth(depth, K, method=method), one)
    assert (np.abs(one).sum(-1) > 0).mean() > 0.95


@pytest.mark.parametrize("method", METHODS)
def test_a_slanted_step_edge_keeps_both_planes_exact(method: str) -> None:
    # Two tilted planes meeting at a slanted occluding edge (a staircase of rim pixels):
    # every pixel on either side, the ones touching the edge included, gets its own plane's
    # exact normal; none mixes the two.
    h, w = 90, 120
    K = intrinsics_matrix(100.0, 100.0, 59.5, 44.5)
    near, far = unit([0.3, 0.4, -1.0]), unit([-0.5, -0.2, -1.0])
    v, u = np.mgrid[0:h, 0:w]
    left = u < 30 + 0.6 * v                 # the near plane, left of a slanted edge
    depth = np.where(left, plane_depth(K, h, w, np.r_[near, 1.2]),
                     plane_depth(K, h, w, np.r_[far, 3.0]))
    assert np.all(depth[~left].min() > 1.3 * depth[left].max())
    normals = normals_from_depth(depth, K, method=method)
    has = np.abs(normals).sum(-1) > 0
    # Only where the edge meets the image border are a few pixels too hemmed in for a fit.
    assert (~has).sum() <= 3 and not np.any(~has[2:-2, 2:-2])
    assert angles_deg(normals[left & has], near).max() < 0.5
    assert angles_deg(normals[~left & has], far).max() < 0.5


def test_box_and_gated_agree_on_a_noisy_real_frame() -> None:
    # Same decisions where it matters: the box method's normals are within a few degrees of
    # the gated ones on the floor and wall of a real frame (test above), and almost every
    # pixel gets one from both.
    depth, K = _livingroom_depth()
    gated = normals_from_depth(depth, K)
    box = normals_from_depth(depth, K, method="box")
    both = (np.abs(gated).sum(-1) > 0) & (np.abs(box).sum(-1) > 0)
    assert both.sum() > 0.99 * (np.abs(gated).sum(-1) > 0).sum()
    assert np.median(np.degrees(np.arccos(np.clip(np.sum(gated * box, -1)[both], -1, 1)))) < 3
