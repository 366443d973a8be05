"""Orienting estimated cloud normals: viewpoint where it sees, along the surface elsewhere."""

from __future__ import annotations

import numpy as np

from monoplane.geometry.orientation import orient_normals


def _unit_cube_faces(n: int, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points on the six faces of [0, 1]^3 (a corner at the origin), exact normals with random
    signs, and each point's face (axis * 2 + side)."""
    rng = np.random.default_rng(seed)
    face = rng.integers(0, 6, n)
    axis, side = face // 2, face % 2
    p = rng.uniform(0, 1, (n, 3))
    p[np.arange(n), axis] = side
    normals = np.zeros((n, 3))
    normals[np.arange(n), axis] = rng.choice([-1.0, 1.0], n)
    return p, normals, face


def test_faces_through_the_viewpoint_come_out_consistent() -> None:
    points, normals, face = _unit_cube_faces(6000, 0)
    out = orient_normals(points, normals, np.zeros(3))
    for f in range(6):
        signs = out[face == f].sum(axis=1)  # the one non-zero component of each normal
        assert np.all(signs == signs[0]), f"face {f} has both orientations"
    # Faces the viewpoint sees (x, y, z = 1) turn towards it, i.e. into the cube.
    for axis in range(3):
        assert np.all(out[face == axis * 2 + 1, axis] < 0)


def test_a_scan_the_viewpoint_sees_everywhere_is_oriented_by_the_viewpoint_alone() -> None:
    rng = np.random.default_rng(1)
    points = np.stack([rng.uniform(-1, 1, 3000), rng.uniform(-1, 1, 3000),
                       np.full(3000, 4.0)], 1)
    normals = np.tile([0.0, 0.0, 1.0], (3000, 1)) * rng.choice([-1.0, 1.0], (3000, 1))
    out = orient_normals(points, normals, np.zeros(3))
    np.testing.assert_array_equal(out, np.tile([0.0, 0.0, -1.0], (3000, 1)))


def test_a_part_that_sees_no_viewpoint_is_oriented_along_itself() -> None:
    # A plane through the viewpoint (z = 0 with the viewpoint at its centre): no point sees it
    # clearly, yet all come out with one sign.
    rng = np.random.default_rng(2)
    points = np.stack([rng.uniform(-1, 1, 2000), rng.uniform(-1, 1, 2000), np.zeros(2000)], 1)
    normals = np.tile([0.0, 0.0, 1.0], (2000, 1)) * rng.choice([-1.0, 1.0], (2000, 1))
    out = orient_normals(points, normals, np.zeros(3))
    assert abs(out[:, 2].sum()) == 2000
