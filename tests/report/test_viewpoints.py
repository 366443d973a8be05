"""Virtual cameras: look-at conventions, orbit placement, zoom-to-fit, back-face culling."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.geometry.camera import look_at
from monoplane.report.viewpoints import facing_triangles, orbit_viewpoints, zoom_to_fit


def test_look_at_opencv_axes() -> None:
    R, t = look_at(np.array([0.0, -5.0, 0.0]), np.zeros(3), up=np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R @ np.zeros(3) + t, [0.0, 0.0, 5.0])  # target on the axis
    # World "up" (+z) points up in the picture, i.e. to camera -y.
    np.testing.assert_allclose(R @ np.array([0.0, 0.0, 1.0]), [0.0, -1.0, 0.0], atol=1e-12)
    with pytest.raises(ValueError):
        look_at(np.zeros(3), np.array([0.0, 1.0, 0.0]), up=np.array([0.0, 1.0, 0.0]))


def test_look_at_roll_turns_the_picture() -> None:
    eye, target, up = np.zeros(3), np.array([0.0, 0.0, 4.0]), np.array([0.0, -1.0, 0.0])
    R0, _ = look_at(eye, target, up)
    np.testing.assert_allclose(R0, np.eye(3), atol=1e-12)  # OpenCV axes already
    R, t = look_at(eye, target, up, roll_deg=90.0)
    # Camera x now points along the old camera y (world down), camera y along world -x.
    np.testing.assert_allclose(R @ [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(R @ [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(t, 0.0)


def test_orbit_views_look_at_the_model_and_zoom_fits() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform(-1, 1, (500, 3)) + np.array([0.0, 0.0, 4.0])
    views = orbit_viewpoints(pts, np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0]), 320,
                             240)
    assert [v.name for v in views] == ["birdseye", "oblique", "oblique_right"]
    bird = views[0]
    assert bird.eye[1] < -1.0  # above the model (y is down)
    for vp in views:
        fitted = zoom_to_fit(vp, pts, 320, 240, margin=0.05)
        cam = pts @ fitted.world_to_cam[:3, :3].T + fitted.world_to_cam[:3, 3]
        uv = cam[:, :2] / cam[:, 2:] * np.diag(fitted.K)[:2] + fitted.K[:2, 2]
        lo, hi = np.percentile(uv, [0.5, 99.5], axis=0)
        size = np.array([320.0, 240.0])
        assert np.all(lo >= 0.05 * size - 1) and np.all(hi <= 0.95 * size + 1)
        # Fills the picture along at least one axis.
        assert max((hi[0] - lo[0]) / 320, (hi[1] - lo[1]) / 240) > 0.85


def test_facing_triangles_cuts_away_planes_seen_from_behind() -> None:
    planes = np.array([[0.0, -1.0, 0.0, 1.0],   # floor at y = 1, seen from above (y < 1)
                       [0.0, 1.0, 0.0, 1.0]])   # ceiling at y = -1, seen from below
    tri_planes = np.array([0, 0, 1])
    from_above = facing_triangles(tri_planes, planes, np.array([0.0, -5.0, 0.0]))
    np.testing.assert_array_equal(from_above, [0, 1])
    inside = facing_triangles(tri_planes, planes, np.zeros(3))
    np.testing.assert_array_equal(inside, [0, 1, 2])
