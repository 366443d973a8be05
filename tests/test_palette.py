"""The plane palette: distinct colours, stable per id, and importable without OpenCV."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from monoplane.palette import NON_PLANAR, label_colors, plane_palette

#: plane_palette(31) as OpenCV's COLOR_HSV2RGB drew it before the palette moved off OpenCV.
OPENCV_COLOURS = [
    [242, 99, 37], [85, 85, 242], [81, 242, 12], [204, 31, 135], [72, 191, 204],
    [204, 172, 10], [100, 25, 165], [58, 165, 83], [165, 8, 19], [37, 105, 242],
    [185, 242, 85], [242, 12, 227], [31, 204, 164], [204, 138, 72], [49, 10, 204],
    [39, 165, 25], [165, 58, 101], [8, 113, 165], [235, 242, 37], [200, 85, 242],
    [12, 242, 112], [204, 60, 31], [72, 90, 204], [94, 204, 10], [165, 25, 128],
    [58, 165, 165], [165, 118, 8], [119, 37, 242], [85, 242, 101], [242, 12, 51],
    [31, 112, 204],
]


def test_palette_keeps_the_colours_opencv_drew() -> None:
    assert plane_palette(31).tolist() == OPENCV_COLOURS


def test_an_id_keeps_its_colour_whatever_the_number_of_planes() -> None:
    # OpenCV rounded short rows and truncated long ones, so ids changed colour past 31 planes
    big = plane_palette(200)
    for n in (1, 5, 31, 32, 64, 199):
        np.testing.assert_array_equal(plane_palette(n), big[:n])
    assert plane_palette(0).shape == (0, 3) and big.dtype == np.uint8


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


def test_the_palette_loads_without_opencv() -> None:
    code = "import sys, monoplane.palette; print('cv2' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
