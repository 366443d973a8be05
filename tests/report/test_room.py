"""Cloud reports of a room: "up" from the floor, not from the largest plane; the bird's eye view
with the ceiling cut away; views from inside.

The room is a synthetic box in a camera frame (x right, y down, z forward), scanned from the
origin: 8 m wide, 2 m deep, 2.5 m high, so the back wall (20 m²) is larger than the floor
(16 m²) and a largest-plane rule would take the wall for the floor. A table top stands on the
floor. The front wall, behind the sensor, was never seen.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from monoplane.datamodel import CloudResult
from monoplane.geometry.cloud_mesh import cloud_mesh
from monoplane.report.cloud import CAMERA_UP, CUT_SHARE, cloud_views, room_frame
from monoplane.report.colors import plane_palette, shade
from monoplane.report.render3d import Mesh
from monoplane.report.room import estimate_room_frame, section_below

FLOOR_Y, CEILING_Y = 1.2, -1.3          # y is down: the floor is below the sensor
X0, X1, Z0, Z1 = -4.0, 4.0, 1.0, 3.0
STEP = 0.1                              # point spacing, metres

# name -> (normal facing the sensor, offset d with n . x + d = 0)
PLANES = {
    "floor": ([0.0, -1.0, 0.0], FLOOR_Y),
    "ceiling": ([0.0, 1.0, 0.0], -CEILING_Y),
    "back": ([0.0, 0.0, -1.0], Z1),
    "left": ([1.0, 0.0, 0.0], -X0),
    "right": ([-1.0, 0.0, 0.0], X1),
    "table": ([0.0, -1.0, 0.0], FLOOR_Y - 0.75),
}


def grid(a0: float, a1: float, b0: float, b1: float) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.meshgrid(np.arange(a0 + STEP / 2, a1, STEP), np.arange(b0 + STEP / 2, b1, STEP))
    return a.ravel(), b.ravel()


def room_points() -> dict[str, np.ndarray]:
    """(N, 3) points of each surface."""
    out = {}
    x, z = grid(X0, X1, Z0, Z1)
    out["floor"] = np.stack([x, np.full_like(x, FLOOR_Y), z], 1)
    out["ceiling"] = np.stack([x, np.full_like(x, CEILING_Y), z], 1)
    x, y = grid(X0, X1, CEILING_Y, FLOOR_Y)
    out["back"] = np.stack([x, y, np.full_like(x, Z1)], 1)
    z, y = grid(Z0, Z1, CEILING_Y, FLOOR_Y)
    out["left"] = np.stack([np.full_like(z, X0), y, z], 1)
    out["right"] = np.stack([np.full_like(z, X1), y, z], 1)
    x, z = grid(-1.0, 1.0, 1.5, 2.5)
    out["table"] = np.stack([x, np.full_like(x, FLOOR_Y - 0.75), z], 1)
    return out


def room_result(rotation: np.ndarray | None = None) -> CloudResult:
    """The room as a detection result, optionally turned by ``rotation`` (3, 3)."""
    R = np.eye(3) if rotation is None else rotation
    parts = room_points()
    names = list(PLANES)
    points = np.concatenate([parts[n] for n in names]) @ R.T
    labels = np.concatenate([np.full(len(parts[n]), i + 1, np.int32)
                             for i, n in enumerate(names)])
    planes = np.array([[*(R @ PLANES[n][0]), PLANES[n][1]] for n in names])
    counts = np.array([len(parts[n]) for n in names], np.int64)
    centroids = np.array([parts[n].mean(0) @ R.T for n in names])
    return CloudResult(points=points, labels=labels, planes=planes,
                            rmse=np.zeros(len(names)), support=counts, centroids=centroids)


def test_the_largest_plane_is_a_wall_but_up_comes_from_the_floor() -> None:
    result = room_result()
    names = list(PLANES)
    assert names[int(np.argmax(result.support))] == "back"   # the old rule's choice
    frame = room_frame(result)                                   # camera-frame hint (0, -1, 0)
    np.testing.assert_allclose(frame.up, [0.0, -1.0, 0.0], atol=1e-9)
    assert names[frame.floor] == "floor" and names[frame.ceiling] == "ceiling"
    assert frame.floor_height == pytest.approx(-FLOOR_Y)
    assert frame.top_height - frame.floor_height == pytest.approx(FLOOR_Y - CEILING_Y)
    heights = frame.heights(room_points()["table"])
    np.testing.assert_allclose(heights, 0.75, atol=1e-9)


def test_a_z_up_room_with_a_z_up_hint() -> None:
    # Turn the camera-frame room so that up (-y) becomes +z.
    R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    result = room_result(R)
    frame = room_frame(result, up_hint=(0.0, 0.0, 1.0))
    np.testing.assert_allclose(frame.up, [0.0, 0.0, 1.0], atol=1e-9)
    assert list(PLANES)[frame.floor] == "floor"


def test_a_rough_hint_is_enough_and_the_plane_decides() -> None:
    result = room_result()
    frame = room_frame(result, up_hint=(0.3, -1.0, 0.4))   # 27 degrees off
    np.testing.assert_allclose(frame.up, [0.0, -1.0, 0.0], atol=1e-9)


def test_without_a_hint_things_standing_on_the_floor_decide() -> None:
    # More furniture tops than the wall has parallel faces: the floor wins on evidence alone.
    result = room_result()
    tops = np.array([[x, FLOOR_Y - 0.45, z] for x in np.arange(-3.5, 3.5, 0.1)
                     for z in np.arange(1.2, 1.8, 0.1)])
    result = CloudResult(
        points=np.concatenate([result.points, tops]),
        labels=np.concatenate([result.labels, np.full(len(tops), 7, np.int32)]),
        planes=np.vstack([result.planes, [0.0, -1.0, 0.0, FLOOR_Y - 0.45]]),
        rmse=np.zeros(7), support=np.append(result.support, len(tops)),
        centroids=np.vstack([result.centroids, tops.mean(0)]))
    frame = room_frame(result, up_hint=None)
    assert list(PLANES)[frame.floor] == "floor"


def test_a_plane_inside_the_cloud_is_no_floor() -> None:
    # The table top has points on both sides (floor below, walls and ceiling above).
    result = room_result()
    keep = result.labels != 1
    frame = estimate_room_frame(result.points[keep], result.planes[1:], result.support[1:],
                                np.array(CAMERA_UP))
    assert list(PLANES)[1:][frame.floor] != "table"


def test_section_below_cuts_walls_at_the_height() -> None:
    result = room_result()
    frame = room_frame(result)
    mesh = cloud_mesh(result)
    colors = np.zeros((len(mesh.vertices), 3))
    cut, planes = section_below(Mesh(mesh.vertices, mesh.triangles, colors),
                                mesh.plane_ids - 1, frame, 2.0)
    heights = frame.heights(cut.points[cut.indices.reshape(-1)])
    assert heights.max() == pytest.approx(2.0, abs=1e-9)
    names = np.array(list(PLANES))[planes]
    assert "ceiling" not in names and {"floor", "back", "left", "table"} <= set(names)


def _pixels_of(image: np.ndarray, rgb: np.ndarray) -> int:
    """Pixels within 2 levels of a colour (anti-aliased edges blend, plane interiors do not)."""
    return int(np.count_nonzero(np.all(np.abs(image.astype(int) - rgb) <= 2, axis=2)))


def test_birdseye_view_has_no_ceiling_and_inside_views_exist(tmp_path: Path) -> None:
    result = room_result()
    figures, rendered = cloud_views(result, tmp_path)
    names = {f.src for f in figures}
    assert names == {f"cloud3d_{n}.png" for n in
                     ("birdseye", "oblique", "oblique_right", "inside_left", "inside_right")}
    palette = plane_palette(result.num_planes) / 255.0
    index = {n: i for i, n in enumerate(PLANES)}

    def colour(name: str) -> np.ndarray:
        i = index[name]
        return np.rint(shade(palette[i][None], result.planes[i, :3][None])[0] * 255)

    bird = cv2.imread(str(rendered.paths["cloud3d_birdseye"]))[..., ::-1]
    assert _pixels_of(bird, colour("ceiling")) == 0
    assert _pixels_of(bird, colour("floor")) > 0.05 * bird.shape[0] * bird.shape[1]
    assert _pixels_of(bird, colour("table")) > 0
    # The cut is what hides the ceiling: the same camera over the uncut room sees it.
    from monoplane.report.render3d import Shot, render_image
    from monoplane.report.viewpoints import orbit_viewpoints

    frame = room_frame(result)
    mesh = cloud_mesh(result)
    vp = orbit_viewpoints(mesh.vertices, frame.up, np.array([0.0, 0, 1]), 320, 240)[0]
    vertex_plane = np.zeros(len(mesh.vertices), np.int64)
    vertex_plane[mesh.triangles.reshape(-1)] = np.repeat(mesh.plane_ids - 1, 3)
    full = Mesh(mesh.vertices, mesh.triangles,
                shade(palette[vertex_plane], result.planes[vertex_plane, :3]))
    uncut = render_image([full], [], Shot("x", vp.K, vp.world_to_cam, {0: None}), 320, 240)
    assert _pixels_of(uncut, colour("ceiling")) > 0.05 * 320 * 240
    # Inside, the eye stands between floor and ceiling, within the walls.
    for name in ("inside_left", "inside_right"):
        inside = cv2.imread(str(rendered.paths[f"cloud3d_{name}"]))[..., ::-1]
        assert _pixels_of(inside, colour("floor")) > 0.1 * inside.shape[0] * inside.shape[1]
        assert _pixels_of(inside, colour("back")) > 0.05 * inside.shape[0] * inside.shape[1]
    assert 0 < CUT_SHARE < 1
