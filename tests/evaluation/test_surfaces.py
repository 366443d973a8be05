"""Surface-truth scores: curved pixels labelled planar, false planes, purity."""

from __future__ import annotations

import numpy as np

from monoplane.evaluation.surfaces import SurfaceCounts, pooled, surface_counts
from monoplane.synth import generate


def test_counts_on_a_3x3_map_by_hand() -> None:
    pred = np.array([[1, 1, 2], [1, 2, 2], [0, 0, 3]])
    faces = np.array([[1, 1, 1], [2, 0, 0], [0, 2, 2]])
    # Plane 1: two pixels on face 1, one on face 2 -> 2 pure. Plane 2: one on face 1, two on
    # curved surface -> false, 1 pure. Plane 3: one pixel on face 2 -> 1 pure.
    c = surface_counts(pred, faces, faces == 0)
    assert c == SurfaceCounts(curved_px=3, curved_planar_px=2, false_planes=1, planar_px=7,
                              pure_px=4)
    assert surface_counts(np.zeros((3, 3), int), faces, faces == 0) == SurfaceCounts(3, 0, 0, 0, 0)


def test_pooled_over_frames() -> None:
    s = pooled([SurfaceCounts(10, 5, 1, 100, 90), SurfaceCounts(30, 5, 0, 100, 100)])
    assert s == {"curved_planar": 0.25, "false_planes": 0.5, "purity": 0.95}
    assert np.isnan(pooled([])["purity"])


def test_generator_gives_every_face_and_the_curved_mask() -> None:
    view = generate(3, "mild").views[0]
    labelled = view.gt_labels > 0
    np.testing.assert_array_equal(view.gt_faces[labelled], view.gt_labels[labelled])
    np.testing.assert_array_equal(view.gt_faces == 0, view.gt_curved)
    assert view.gt_curved.any()
    # Faces below the area threshold have their own ids after the labelled ones.
    small = (view.gt_faces > 0) & ~labelled
    if small.any():
        assert view.gt_faces[small].min() > view.gt_labels.max()
    # The truth scores itself perfectly.
    c = surface_counts(view.gt_faces, view.gt_faces, view.gt_curved)
    assert c.curved_planar_px == 0 and c.false_planes == 0 and c.pure_px == c.planar_px
