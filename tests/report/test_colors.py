"""Colourisation of depth and normals, and shading."""

from __future__ import annotations

import numpy as np

from monoplane.report.colors import colorize_depth, colorize_normals, depth_range, shade


def test_depth_colours_near_blue_far_red_invalid_black() -> None:
    depth = np.array([[1.0, 2.0, 3.0, 0.0]], np.float32)
    rgb = colorize_depth(depth, 1.0, 3.0).astype(int)
    assert rgb[0, 0, 2] > rgb[0, 0, 0]  # near: blue dominates
    assert rgb[0, 2, 0] > rgb[0, 2, 2]  # far: red dominates
    np.testing.assert_array_equal(rgb[0, 3], 0)
    assert depth_range(np.zeros((2, 2))) == (0.0, 1.0)


def test_normal_colours() -> None:
    n = np.array([[[0.0, 0.0, -1.0], [0.0, -1.0, 0.0], [0.0, 0.0, 0.0]]], np.float32)
    rgb = colorize_normals(n)
    np.testing.assert_array_equal(rgb[0, 0], [128, 128, 255])  # facing the camera: blue
    np.testing.assert_array_equal(rgb[0, 1], [128, 255, 128])  # facing up (floor): green
    np.testing.assert_array_equal(rgb[0, 2], [0, 0, 0])


def test_shade_range() -> None:
    light = np.array([0.0, 1.0, 0.0])
    cols = np.ones((3, 3))
    normals = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    out = shade(cols, normals, light)
    np.testing.assert_allclose(out[:, 0], [1.0, 0.55, 0.775])
