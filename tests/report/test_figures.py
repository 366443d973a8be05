"""2D figures: id anchors inside regions, overlays, depth comparison, contact sheet."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monoplane.report import figures as fig
from monoplane.report.colors import plane_palette


def test_anchor_lies_inside_an_l_shaped_region() -> None:
    labels = np.zeros((40, 40), np.int32)
    labels[5:35, 5:12] = 3
    labels[28:35, 5:35] = 3
    (u, v), = fig.label_anchors(labels).values()
    assert labels[v, u] == 3
    assert 0 not in labels[v - 2 : v + 3, u - 2 : u + 3]


def test_overlay_is_enlarged_and_shows_plane_colours(room) -> None:
    out = fig.overlay_labels(room.frame.rgb, room.labels, alpha=1.0, ids=False)
    k = fig.display_scale(room.frame.width)
    assert k == 3 and out.shape == (room.frame.height * k, room.frame.width * k, 3)
    # With alpha 1 a pixel deep inside plane 1 (floor, bottom centre) has the palette colour.
    np.testing.assert_array_equal(out[-10, out.shape[1] // 2], plane_palette(7)[0])


def test_overlay_writes_ids(room) -> None:
    with_ids = fig.overlay_labels(room.frame.rgb, room.labels)
    without = fig.overlay_labels(room.frame.rgb, room.labels, ids=False)
    assert np.any(with_ids != without)


def test_depth_comparison_and_sheet(room, tmp_path: Path) -> None:
    img = fig.depth_comparison(room.frame.depth, room.planar_depth(), "m")
    assert img.dtype == np.uint8 and img.shape[1] > 2 * room.frame.width * 3
    sheet = fig.contact_sheet([(img, "a"), (img, "b"), (img, "c"), (img, "d")], columns=3,
                              width=100)
    assert sheet.shape[1] == 3 * 100 + 2 * 8
    path = fig.save_png(tmp_path / "x.png", sheet)
    np.testing.assert_array_equal(fig.load_png(path), sheet)


def test_input_image_is_the_colour_image_or_grey_enlarged_for_display() -> None:
    rgb = np.zeros((10, 20, 3), dtype=np.uint8)
    rgb[:, :10] = 255
    k = fig.display_scale(20)
    assert k > 1
    shown = fig.input_image(rgb, (10, 20))
    assert shown.shape == (10 * k, 20 * k, 3)
    assert shown[0, 0].tolist() == [255, 255, 255] and shown[-1, -1].tolist() == [0, 0, 0]
    grey = fig.input_image(None, (10, 20))
    assert grey.shape == (10 * k, 20 * k, 3) and np.all(grey == 128)
