"""The reports' software rasterizer against closed-form answers.

Cameras follow OpenCV: pixel (u, v) has its centre at integer image coordinates, x right, y
down, z forward. A pixel whose whole footprint is on one side of a triangle's (or line's)
image must come out exactly in that colour, or white; only pixels the boundary passes through
(within :data:`BOUNDARY` pixels of their centre, half the footprint's diagonal) are blends, the
anti-aliasing.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from monoplane.geometry.mesh import planar_mesh
from monoplane.report.colors import plane_palette, shade
from monoplane.report.render3d import Lines, Mesh, Shot, render, render_image
from monoplane.report.viewpoints import facing_triangles, orbit_viewpoints

W, H = 80, 60
K = np.array([[60.0, 0.0, 39.5], [0.0, 60.0, 29.5], [0.0, 0.0, 1.0]])
#: Farther than this from a boundary, a pixel's footprint lies on one side of it.
BOUNDARY = 0.75
WHITE = np.array([255, 255, 255])


def _shot(meshes: dict | None = None, lines: list | None = None, name: str = "shot") -> Shot:
    return Shot(name, K, np.eye(4), meshes or {}, lines or [])


def _project(points: np.ndarray) -> np.ndarray:
    """(N, 3) camera points in front -> (N, 2) pixel coordinates."""
    uvw = np.asarray(points, float) @ K.T
    return uvw[:, :2] / uvw[:, 2:]


def _centres() -> np.ndarray:
    """(H, W, 2) pixel centres (u, v)."""
    v, u = np.mgrid[0:H, 0:W]
    return np.stack([u, v], axis=-1).astype(float)


def _barycentric(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(..., 3) barycentric coordinates of 2D points ``p`` (..., 2) in the triangle (3, 2)."""
    a, b, c = tri
    m = np.array([b - a, c - a]).T
    st = np.linalg.solve(m, (p - a)[..., None])[..., 0]
    return np.concatenate([1.0 - st.sum(-1, keepdims=True), st], axis=-1)


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance from 2D points ``p`` (..., 2) to the segment a-b."""
    t = np.clip(((p - a) @ (b - a)) / ((b - a) @ (b - a)), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[..., None] * (b - a)), axis=-1)


def _triangle_pixels(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels certainly inside, certainly outside, and the barycentric coordinates of every
    pixel centre, for the image triangle ``tri`` (3, 2)."""
    p = _centres()
    bary = _barycentric(p, tri)
    edge = np.min([_segment_distance(p, tri[i], tri[(i + 1) % 3]) for i in range(3)], axis=0)
    inside = np.all(bary >= 0.0, axis=-1)
    return inside & (edge > BOUNDARY), ~inside & (edge > BOUNDARY), bary


def test_a_triangle_covers_the_pixels_whose_centres_project_inside_it() -> None:
    corners = np.array([[-1.0, -0.7, 3.0], [1.3, -0.4, 4.5], [0.2, 0.9, 2.5]])  # not frontal
    colour = np.array([0.2, 0.4, 0.6])
    mesh = Mesh(corners, np.array([[0, 1, 2]]), np.tile(colour, (3, 1)))
    img = render_image([mesh], [], _shot({0: None}), W, H).astype(int)
    inside, outside, _ = _triangle_pixels(_project(corners))
    assert inside.sum() > 400 and outside.sum() > 1000
    assert np.abs(img[inside] - np.rint(255 * colour)).max() <= 1
    assert np.all(img[outside] == WHITE)
    # The other winding is drawn too (both sides).
    flipped = Mesh(corners, np.array([[0, 2, 1]]), mesh.colors)
    assert np.array_equal(render_image([flipped], [], _shot({0: None}), W, H), img)


def test_the_nearer_triangle_hides_the_farther_where_they_overlap() -> None:
    # Two frontal triangles, the far one twice as far and twice as large: overlapping images.
    near = np.array([[-0.5, -0.4, 2.0], [0.6, -0.3, 2.0], [0.0, 0.5, 2.0]])
    far = np.array([[-0.4, -1.1, 4.0], [1.6, 0.2, 4.0], [-1.4, 0.9, 4.0]])
    red, blue = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    meshes = [Mesh(near, np.array([[0, 1, 2]]), np.tile(red, (3, 1))),
              Mesh(far, np.array([[0, 1, 2]]), np.tile(blue, (3, 1)))]
    in_near, _, _ = _triangle_pixels(_project(near))
    in_far, out_far, _ = _triangle_pixels(_project(far))
    _, out_near, _ = _triangle_pixels(_project(near))
    assert (in_near & in_far).sum() > 100 and (in_far & out_near).sum() > 100
    for order in ({0: None, 1: None}, {1: None, 0: None}):  # the depth test, not the order
        img = render_image(meshes, [], _shot(order), W, H).astype(int)
        assert np.all(img[in_near & in_far] == [255, 0, 0])
        assert np.all(img[in_far & out_near] == [0, 0, 255])


def test_vertex_colours_interpolate_linearly_on_a_frontal_triangle() -> None:
    # Corners A and B project onto pixel row 6, C near the bottom: the edge AB is horizontal.
    z = 2.0
    corner_px = np.array([[4.0, 6.0], [75.0, 6.0], [30.0, 55.0]])
    corners = np.column_stack([(corner_px - K[:2, 2]) / K[0, 0] * z, np.full(3, z)])
    colours = np.eye(3)  # A red, B green, C blue
    img = render_image([Mesh(corners, np.array([[0, 1, 2]]), colours)], [], _shot({0: None}),
                       W, H).astype(float)
    inside, outside, bary = _triangle_pixels(corner_px)
    # Frontal, so perspective-correct colours are affine in the image: the barycentric
    # coordinates of each pixel centre.
    assert np.abs(img[inside] - 255 * bary[inside]).max() <= 1
    assert np.all(img[outside] == 255)
    # At the corners, the corner colours.
    for k in range(3):
        near_corner = np.linalg.norm(_centres() - corner_px[k], axis=-1) < 4.0
        assert (inside & near_corner).any()
        assert np.abs(img[inside & near_corner] - 255 * colours[k]).max() < 0.2 * 255
    # Along the edge AB, one row inside it, red falls and green rises linearly in u; blue is
    # the row's constant share of C.
    row = img[7, 8:71]
    assert np.abs(np.diff(row[:, 0], 2)).max() <= 1 and np.abs(np.diff(row[:, 1], 2)).max() <= 1
    assert np.all(np.diff(row[:, 0]) < 0) and np.all(np.diff(row[:, 1]) > 0)
    assert np.ptp(row[:, 2]) <= 1


def test_colours_are_perspective_correct_on_a_slanted_triangle() -> None:
    corners = np.array([[-1.5, -0.6, 1.5], [1.2, -0.9, 6.0], [0.3, 1.0, 3.0]])
    colours = np.eye(3)
    img = render_image([Mesh(corners, np.array([[0, 1, 2]]), colours)], [], _shot({0: None}),
                       W, H).astype(float)
    inside, _, screen_bary = _triangle_pixels(_project(corners))
    # Ray-cast each pixel centre: the point X = z (x, y, 1) on the triangle's plane, and its
    # barycentric coordinates on the 3D triangle.
    p = _centres()[inside]
    rays = np.column_stack([(p - K[:2, 2]) / K[0, 0], np.ones(len(p))])
    a, b, c = corners
    normal = np.cross(b - a, c - a)
    hits = rays * ((a @ normal) / (rays @ normal))[:, None]
    bary = np.linalg.lstsq(np.column_stack([a, b, c]), hits.T, rcond=None)[0].T
    want = 255 * bary @ colours
    assert np.abs(img[inside] - want).max() <= 2
    # Affine interpolation in the image would be far off: the test can tell them apart.
    assert np.abs(img[inside] - 255 * screen_bary[inside]).max() > 20


def test_a_triangle_half_behind_the_camera_renders_its_front_part_only() -> None:
    # A floor triangle 1 below the camera (y down), from 2 behind it to 6 ahead.
    corners = np.array([[0.0, 1.0, -2.0], [-3.0, 1.0, 6.0], [3.0, 1.0, 6.0]])
    colour = np.array([0.3, 0.6, 0.3])
    img = render_image([Mesh(corners, np.array([[0, 1, 2]]), np.tile(colour, (3, 1)))], [],
                       _shot({0: None}), W, H).astype(int)

    def on_floor_triangle(p: np.ndarray) -> np.ndarray:
        """Does the ray through image point ``p`` (..., 2) meet the triangle in front?"""
        x, y = (p[..., 0] - K[0, 2]) / K[0, 0], (p[..., 1] - K[1, 2]) / K[1, 1]
        with np.errstate(divide="ignore"):
            z = np.where(y > 0, 1.0 / y, -1.0)  # depth where the ray meets the plane y = 1
        floor = np.stack([x * z, z], axis=-1)  # (x, z) on the floor
        bary = _barycentric(floor, corners[:, [0, 2]])
        return (z > 0) & np.all(bary >= 0.0, axis=-1)

    centre = _centres()
    corner_hits = [on_floor_triangle(centre + d) for d in ((-0.5, -0.5), (0.5, -0.5),
                                                           (-0.5, 0.5), (0.5, 0.5))]
    # The front part's image is convex: a pixel whose four corners hit it is covered; one whose
    # corners all miss it is not, away from the image of the corners in front.
    covered = np.all(corner_hits, axis=0)
    away = np.min([np.linalg.norm(centre - q, axis=-1) for q in _project(corners[1:])],
                  axis=0) > 1.5
    missed = ~np.any(corner_hits, axis=0) & away
    assert covered.sum() > 300 and missed.sum() > 1000
    assert np.abs(img[covered] - np.rint(255 * colour)).max() <= 1
    assert np.all(img[missed] == WHITE)
    assert np.all(img[: int(K[1, 2]) + 1] == WHITE)  # nothing smeared above the horizon


def test_a_triangle_behind_the_camera_is_not_drawn_and_an_empty_shot_is_white() -> None:
    behind = Mesh(np.array([[-1.0, -1.0, -3.0], [1.0, -1.0, -3.0], [0.0, 1.0, -2.0]]),
                  np.array([[0, 1, 2]]), np.zeros((3, 3)))
    for shot in (_shot(), _shot({0: None}), _shot({0: np.zeros(0, int)})):
        img = render_image([behind], [], shot, W, H)
        assert img.shape == (H, W, 3) and img.dtype == np.uint8 and np.all(img == 255)


def test_a_line_segment_lights_the_pixels_along_its_projection() -> None:
    ends = np.array([[-0.9, 0.3, 3.0], [1.0, -0.25, 3.0]])
    line = Lines(ends, np.array([[0, 1]]), np.array([[0.0, 0.0, 0.0]]))
    img = render_image([], [line], _shot(lines=[0]), W, H).astype(int)
    a, b = _project(ends)
    p = _centres()
    distance = _segment_distance(p, a, b)
    along = ((p - a) @ (b - a)) / np.linalg.norm(b - a)
    # 2 px wide: a pixel within 0.5 px of the projection is all line, one 2 px away all white.
    on = (distance < 0.5) & (along > 1.5) & (along < np.linalg.norm(b - a) - 1.5)
    assert on.sum() > 25
    assert np.all(img[on] == 0)
    assert np.all(img[distance > 2.0] == 255)


def test_a_line_is_hidden_where_a_nearer_triangle_covers_it() -> None:
    # A horizontal line at depth 4 on the optical axis' row (cy = 29.5: rows 29 and 30), from
    # u = 9.5 to 69.5, and a grey square over u, v = c +- 18 at depth 2 or 6.
    line = Lines(np.array([[-2.0, 0.0, 4.0], [2.0, 0.0, 4.0]]), np.array([[0, 1]]),
                 np.array([[0.0, 0.0, 1.0]]))
    square = np.array([[-0.3, -0.3, 1.0], [0.3, -0.3, 1.0], [0.3, 0.3, 1.0], [-0.3, 0.3, 1.0]])
    u = np.arange(W)
    behind_square = (u > 23) & (u < 56)
    beside_square = ((u > 11) & (u < 20)) | ((u > 59) & (u < 68))
    for depth, hidden in ((2.0, True), (6.0, False)):
        mesh = Mesh(square * [depth, depth, depth], np.array([[0, 1, 2], [0, 2, 3]]),
                    np.full((4, 3), 0.5))
        img = render_image([mesh], [line], _shot({0: None}, [0]), W, H).astype(int)
        rows = img[[29, 30]]
        assert np.all(rows[:, beside_square] == [0, 0, 255])
        assert np.all(rows[:, behind_square] == (128 if hidden else [0, 0, 255]))


def test_a_line_crossing_the_near_plane_is_drawn_in_front_only() -> None:
    # A line from behind the camera to 5 ahead, 0.2 below the optical axis: in front of the
    # camera it projects onto the column u = cx, from v = cy + 0.2 fy / 5 down (and off the
    # picture as it nears the camera).
    line = Lines(np.array([[0.0, 0.2, -1.0], [0.0, 0.2, 5.0]]), np.array([[0, 1]]),
                 np.array([[0.0, 0.0, 1.0]]))
    img = render_image([], [line], _shot(lines=[0]), W, H).astype(int)
    top = K[1, 2] + 0.2 * K[1, 1] / 5.0
    column = img[:, [39, 40]]  # cx = 39.5: the 2 px line covers both columns
    assert np.all(column[int(top) + 2:] == [0, 0, 255])
    assert np.all(column[: int(top) - 1] == 255)
    assert np.all(img[:, :38] == 255) and np.all(img[:, 42:] == 255)


def test_a_run_writes_one_png_per_shot(tmp_path: Path) -> None:
    corners = np.array([[-1.0, -0.7, 3.0], [1.3, -0.4, 4.5], [0.2, 0.9, 2.5]])
    mesh = Mesh(corners, np.array([[0, 1, 2]]), np.tile([1.0, 0.0, 0.0], (3, 1)))
    shots = [_shot({0: None}, name="a"), _shot(name="b"), _shot({0: None}, name="c")]
    result = render([mesh], [], shots, tmp_path, W, H)
    assert result.reason is None and result.seconds > 0
    assert result.paths == {n: tmp_path / f"{n}.png" for n in "abc"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.png", "b.png", "c.png"]
    img = cv2.imread(str(result.paths["a"]))[..., ::-1]  # OpenCV reads BGR
    assert np.array_equal(img, render_image([mesh], [], shots[0], W, H))
    inside, _, _ = _triangle_pixels(_project(corners))
    assert np.all(img[inside] == [255, 0, 0])


def test_a_png_that_cannot_be_written_is_a_reason_not_an_exception(tmp_path: Path) -> None:
    result = render([], [], [_shot(name="a"), _shot(name="b")], tmp_path / "missing", W, H)
    assert result.paths == {}
    assert result.reason == "could not write a.png, b.png"


@pytest.fixture
def room_job(room):
    """The test room's planar mesh, coloured by plane, from the input camera and from above."""
    w, h = 320, 240
    v, t, _, ids = planar_mesh(room, step=1)
    expected = shade(plane_palette(room.num_planes)[ids - 1] / 255.0,
                     room.planes[ids - 1, :3])
    K_room = room.frame.K.copy()
    K_room[:2] *= w / room.frame.width
    bird = orbit_viewpoints(v, np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0]), w, h)[0]
    keep = facing_triangles(ids[t[:, 0]] - 1, room.planes, bird.eye)
    shots = [Shot("frontal", K_room, np.eye(4), {0: None}),
             Shot("bird", bird.K, bird.world_to_cam, {0: keep})]
    return [Mesh(v, t, expected)], shots, w, h


def test_rendered_planes_match_labels_and_colours(room, room_job, tmp_path: Path) -> None:
    meshes, shots, w, h = room_job
    result = render(meshes, [], shots, tmp_path, w, h)
    assert result.reason is None
    img = cv2.imread(str(result.paths["frontal"]))[..., ::-1].astype(int)
    assert img.shape == (h, w, 3)
    # The frontal view uses the input camera, so each plane lands on its labelled pixels, in
    # exactly its shaded colour.
    labels = cv2.resize(room.labels.astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST)
    palette = plane_palette(room.num_planes) / 255.0
    found = 0
    for i in range(room.num_planes):
        inner = cv2.erode((labels == i + 1).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
        if inner.sum() < 50:
            continue
        want = np.rint(255 * shade(palette[i][None], room.planes[i, :3][None])[0])
        assert np.abs(np.median(img[inner], axis=0) - want).max() <= 1, (i + 1, want)
        found += 1
    assert found >= 6
    # The bird's eye view shows several planes and some background.
    bird = cv2.imread(str(result.paths["bird"]))[..., ::-1].astype(int)
    white = np.all(bird == 255, axis=-1).mean()
    assert 0.05 < white < 0.9
    colours = {tuple(c) for c in (bird[~np.all(bird > 245, axis=-1)] // 16).tolist()}
    assert len(colours) >= 4
