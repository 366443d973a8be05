"""Palette distinctness and colourisation of depth and normals."""

from __future__ import annotations

import numpy as np

from monoplane.report.colors import (
    NON_PLANAR,
    colorize_depth,
    colorize_normals,
    depth_range,
    label_colors,
    plane_palette,
    shade,
)


def test_palette_colours_are_distinct() -> None:
    pal = plane_palette(24).astype(float)
    dist = np.linalg.norm(pal[:, None] - pal[None], axis=-1)
    np.fill_diagonal(dist, np.inf)
    assert dist.min() > 25.0
    # Neighbouring ids (often adjacent planes) differ strongly.
    assert np.linalg.norm(np.diff(pal, axis=0), axis=1).min() > 80.0


def test_label_colors_maps_zero_to_non_planar() -> None:
    labels = np.array([[0, 1], [2, 3]])
    rgb = label_colors(labels)
    np.testing.assert_array_equal(rgb[0, 0], NON_PLANAR)
    np.testing.assert_array_equal(rgb[1, 1], plane_palette(3)[2])


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
