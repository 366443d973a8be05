"""Plane regions triangulated with their holes: closed-form areas, occluders left uncovered."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.datamodel import Frame, Reconstruction, intrinsics_matrix
from monoplane.geometry.polygons import (
    PlaneMesh,
    mask_outlines,
    mask_plane_mesh,
    points_plane_mesh,
    reconstruction_mesh,
    triangulate_outline,
)


def _areas_2d(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    ab, ac = b - a, c - a
    return 0.5 * (ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])


def _areas_3d(vertices: np.ndarray, triangles: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Signed areas along ``normal``: positive when the winding follows it."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return 0.5 * np.cross(b - a, c - a) @ normal


@pytest.mark.parametrize("flip", [False, True])
def test_concave_outline_with_a_hole_has_the_shoelace_area(flip: bool) -> None:
    outer = np.array([[0, 0], [4, 0], [4, 1], [1, 1], [1, 3], [3, 3], [3, 4], [0, 4]], float)
    hole = np.array([[0.25, 1.5], [0.75, 1.5], [0.75, 2.5], [0.25, 2.5]])
    if flip:
        outer, hole = outer[::-1], hole[::-1]
    vertices, tris = triangulate_outline(outer, [hole])
    areas = _areas_2d(vertices, tris)
    assert np.all(areas > 0)  # counter-clockwise, whatever the input winding
    assert areas.sum() == pytest.approx(9.0 - 0.5)


def test_mask_outlines_find_holes_and_islands() -> None:
    mask = np.zeros((40, 40), bool)
    mask[5:35, 5:35] = True
    mask[12:28, 12:28] = False   # a hole
    mask[18:22, 18:22] = True    # an island inside the hole
    outlines = mask_outlines(mask)
    assert sorted(len(holes) for _, holes in outlines) == [0, 1]
    ring = next(o for o in outlines if o[1])
    # Contours run through boundary pixel centres: the outer square spans 5..34.
    np.testing.assert_array_equal(ring[0].min(axis=0), [5, 5])
    np.testing.assert_array_equal(ring[0].max(axis=0), [34, 34])
    np.testing.assert_array_equal(ring[1][0].min(axis=0), [11, 11])
    np.testing.assert_array_equal(ring[1][0].max(axis=0), [28, 28])
    assert mask_outlines(np.zeros((5, 5), bool)) == []


def _wall_with_box() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A fronto-parallel wall at z = 4 filling the image, a box in front of it in the middle."""
    K = intrinsics_matrix(100.0, 100.0, 49.5, 39.5)
    wall = np.array([0.0, 0.0, -1.0, 4.0])
    labels = np.ones((80, 100), np.int32)
    box = np.zeros_like(labels, bool)
    box[25:55, 30:70] = True
    labels[box] = 2
    return K, wall, labels, box


def test_wall_surface_leaves_the_box_in_front_of_it_open() -> None:
    K, wall, labels, box = _wall_with_box()
    vertices, tris = mask_plane_mesh(labels == 1, wall, K, tolerance_px=0.5)
    np.testing.assert_allclose(vertices @ wall[:3] + wall[3], 0.0, atol=1e-9)
    areas = _areas_3d(vertices, tris, wall[:3])
    assert np.all(areas > 0)  # right-hand normals along the plane normal (towards the camera)
    # Pixel-centre outlines: the wall spans 99 x 79 pixel steps; the hole runs through the wall
    # pixels around the box, 41 x 31 steps, with its corners cut diagonally (the corner pixels
    # touch the box only diagonally), 4 x 0.5 px². One pixel step is 4/100 at z = 4.
    px = 4.0 / 100.0
    assert areas.sum() == pytest.approx((99 * 79 - (41 * 31 - 2)) * px * px, rel=1e-9)
    # No wall triangle covers a box pixel: project centroids back into the image.
    centroids = vertices[tris].mean(axis=1)
    uv = centroids @ K.T
    uv = np.round(uv[:, :2] / uv[:, 2:]).astype(int)
    assert not np.any(box[uv[:, 1], uv[:, 0]])


def test_points_on_a_plane_with_a_hole() -> None:
    # A 2 m x 2 m square of samples every 2 cm on a tilted plane, with a 1 m x 1 m hole.
    n = np.array([0.0, -0.6, -0.8])
    plane = np.array([*n, 3.0])
    e1 = np.array([1.0, 0.0, 0.0])
    e2 = np.cross(n, e1)
    s = np.arange(-1.0, 1.0 + 1e-9, 0.02)
    a, b = (g.ravel() for g in np.meshgrid(s, s))
    keep = ~((np.abs(a) < 0.5) & (np.abs(b) < 0.5))
    pts = -plane[3] * n + a[keep, None] * e1 + b[keep, None] * e2
    vertices, tris = points_plane_mesh(pts, plane * 2.0, cell=0.02)  # any scale of (n, d)
    np.testing.assert_allclose(vertices @ n + plane[3], 0.0, atol=1e-9)
    areas = _areas_3d(vertices, tris, n)
    assert np.all(areas > 0)
    assert areas.sum() == pytest.approx(4.0 - 1.0, rel=0.05)
    centroids = vertices[tris].mean(axis=1) + plane[3] * n
    inside = (np.abs(centroids @ e1) < 0.45) & (np.abs(centroids @ e2) < 0.45)
    assert not np.any(inside)


def test_points_plane_mesh_of_nothing_is_empty() -> None:
    v, t = points_plane_mesh(np.zeros((0, 3)), np.array([0.0, 0.0, -1.0, 1.0]), 0.1)
    assert v.shape == (0, 3) and t.shape == (0, 3)


def test_reconstruction_mesh_tags_faces_with_their_planes() -> None:
    K, wall, labels, _ = _wall_with_box()
    front = np.array([0.0, 0.0, -1.0, 2.0])
    frame = Frame(rgb=np.zeros((*labels.shape, 3), np.uint8), K=K)
    rec = Reconstruction(frame=frame, labels=labels, planes=np.stack([wall, front]))
    mesh = reconstruction_mesh(rec)
    assert set(mesh.plane_ids.tolist()) == {1, 2}
    for pid, plane in ((1, wall), (2, front)):
        corners = mesh.vertices[mesh.triangles[mesh.plane_ids == pid]]
        np.testing.assert_allclose(corners @ plane[:3] + plane[3], 0.0, atol=1e-9)
    assert PlaneMesh.concatenate([]).triangles.shape == (0, 3)
