"""Graceful registration: fallback pose, left-out views, --strict; N-view fusion outputs."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.evaluation.twoview import ground_truth_sfm, relative_pose_error
from monoplane.multiview import reconstruct_multiview, save_scene
from monoplane.pipeline import Pipeline
from monoplane.synth.sequence import generate_sequence

OVERRIDES = ["cues.plugin=given", "refiner.plugin=none"]


@pytest.fixture(scope="module")
def star():
    return generate_sequence(1, 3, "star", level="clean")


def _sfm_without(synth, missing: int):
    sfm = ground_truth_sfm(synth)
    registration = [{"method": "none"} if v == missing else {"method": "sfm"}
                    for v in range(len(synth.views))]
    keypoints = [k if v != missing else np.zeros((0, 2)) for v, k in enumerate(sfm.keypoints)]
    ids = [p if v != missing else np.zeros(0, np.int64) for v, p in enumerate(sfm.point_ids)]
    matches = {k: m for k, m in sfm.matches.items() if missing not in k}
    return replace(sfm, keypoints=keypoints, point_ids=ids, matches=matches,
                   registration=registration)


def test_unregistered_view_is_placed_by_the_fallback(star, tmp_path: Path) -> None:
    pipe = Pipeline.from_preset("monoplane", overrides=OVERRIDES)
    frames = [v.frame for v in star.views]
    out = reconstruct_multiview(frames, pipe, sfm=_sfm_without(star, 2), workers=1)
    assert out.frame_indices == [0, 1, 2] and out.unregistered == []
    assert out.registration[2]["method"] == "fallback"
    assert out.registration[2]["inliers"] >= 15
    v0, v2 = star.views[0], star.views[2]
    placed = out.scene.cameras  # the fallback's pose, refined with the planes by the adjuster
    rot, trans = relative_pose_error(placed[0], placed[2], v0.R, v0.t, v2.R, v2.t)
    assert rot < 2.0 and trans < 20.0  # coarse, see docs/multiview.md
    # Metric (clean) depth: the fallback's baseline comes out in metres, coarsely (the
    # length hangs on the depth at keypoints, often on edges).
    c_pred = -placed[2].R.T @ placed[2].t
    c_true = -v2.R.T @ v2.t
    assert np.linalg.norm(c_pred - c_true) < 0.5 * np.linalg.norm(c_true - (-v0.R.T @ v0.t))
    saved = save_scene(out, tmp_path / "scene")
    cams = json.loads((saved / "cameras.json").read_text())["cameras"]
    assert cams[2]["registration"]["method"] == "fallback"
    assert cams[2]["registration"]["inliers"] == out.registration[2]["inliers"]
    for v in range(3):
        import cv2

        glob = cv2.imread(str(saved / f"view_{v:03d}" / "labels_global.png"),
                          cv2.IMREAD_UNCHANGED)
        rec = out.scene.views[v]
        for local, g in out.scene.links[v].items():
            assert np.all(glob[rec.labels == local] == g + 1)
        assert np.all(glob[rec.labels == 0] == 0)


def test_view_that_cannot_be_placed_is_left_out_and_named(star, tmp_path: Path) -> None:
    pipe = Pipeline.from_preset("monoplane", overrides=OVERRIDES)
    frames = [v.frame for v in star.views]
    # A blank image has no features: the fallback fails too.
    frames[2] = frames[2].with_(rgb=np.full_like(frames[2].rgb, 128))
    sfm = _sfm_without(star, 2)
    out = reconstruct_multiview(frames, pipe, sfm=sfm, workers=1)
    assert out.frame_indices == [0, 1]
    assert out.unregistered == [frames[2].name]
    saved = save_scene(out, tmp_path / "scene")
    doc = json.loads((saved / "scene.json").read_text())
    assert doc["unregistered"] == [frames[2].name]
    assert len(doc["cameras"]) == 2
    with pytest.raises(InvalidInput, match=f"could not register 1 of 3 images: {frames[2].name}"):
        reconstruct_multiview(frames, pipe, sfm=sfm, strict=True, workers=1)


def test_no_global_plane_holds_two_planes_of_one_view(star) -> None:
    pipe = Pipeline.from_preset("monoplane", overrides=OVERRIDES)
    out = reconstruct_multiview([v.frame for v in star.views], pipe,
                                sfm=ground_truth_sfm(star), workers=1)
    members: dict[int, list[int]] = {}
    for v, table in enumerate(out.scene.links):
        for glob in table.values():
            members.setdefault(glob, []).append(v)
    assert all(len(vs) == len(set(vs)) for vs in members.values())
    assert any(len(vs) == 3 for vs in members.values())  # some plane is seen in all views
    adj = out.adjustment
    assert adj["after"]["cost"] <= adj["before"]["cost"]
    # Exact SfM points: the ones seen inside planes end on their planes.
    assert adj["before"]["sfm_points_on_planes"] > 50
    assert adj["after"]["sfm_point_plane_median_rel"] < 0.005
