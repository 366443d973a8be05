"""Two-view metrics: pose errors, plane AP and its variants."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.datamodel import Camera, Reconstruction, Scene, intrinsics_matrix
from monoplane.evaluation.twoview import (
    average_precision,
    judge_pair,
    judge_scene,
    relative_pose_error,
    rotation_error_deg,
    translation_angle_deg,
)
from monoplane.synth import generate


def _rot_y(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def test_pose_errors_closed_form() -> None:
    assert rotation_error_deg(_rot_y(10), _rot_y(3)) == pytest.approx(7.0)
    assert translation_angle_deg([1, 0, 0], [1, 1, 0]) == pytest.approx(45.0)
    assert translation_angle_deg([2, 0, 0], [5, 0, 0]) == pytest.approx(0.0, abs=1e-6)
    K = intrinsics_matrix(100, 100, 50, 50)
    # The prediction lives in another world frame and scale: errors must not depend on it.
    Rw, s = _rot_y(40), 3.0
    R0, t0 = np.eye(3), np.zeros(3)
    R1, t1 = _rot_y(12), np.array([0.5, 0.0, 0.1])
    cam0 = Camera(K, R0 @ Rw.T, s * t0, 100, 100)
    cam1 = Camera(K, R1 @ Rw.T, s * t1, 100, 100)
    rot, trans = relative_pose_error(cam0, cam1, R0, t0, R1, t1)
    assert rot == pytest.approx(0.0, abs=1e-5) and trans == pytest.approx(0.0, abs=1e-5)


def _masks(*rows) -> np.ndarray:
    return np.array(rows, dtype=bool)[None]  # one view


def test_judge_pair_thresholds_per_variant() -> None:
    gt_masks = _masks([1, 1, 1, 1, 0, 0, 0, 0], [0, 0, 0, 0, 1, 1, 1, 1])
    gt = np.array([[0, 0, 1, 2.0], [1, 0, 0, 3.0]])
    tilt = np.radians(40)
    pred = np.array([[0, 0, 1, 2.5], [np.cos(tilt), np.sin(tilt), 0, 4.5]])
    pred_masks = _masks([1, 1, 1, 0, 0, 0, 0, 0], [0, 0, 0, 0, 1, 1, 1, 1])
    judged = judge_pair(pred_masks, pred, gt_masks, gt, np.array([3.0, 4.0]))
    assert judged.true_positive["all"].tolist() == [True, False]  # 40° and 1.5 m off
    assert judged.true_positive["-offset"].tolist() == [True, False]  # still 40° off
    assert judged.true_positive["-normal"].tolist() == [True, False]  # still 1.5 m off
    assert judged.true_positive["-offset-normal"].tolist() == [True, True]
    ap = average_precision([judged])
    assert ap["-offset-normal"] == pytest.approx(100.0)
    # Ranked [FP (score 4), TP]: recall 0.5 is reached at precision 0.5.
    assert ap["all"] == pytest.approx(25.0)


def test_each_truth_matched_once_and_failures_count_as_misses() -> None:
    gt_masks = _masks([1, 1, 1, 1])
    gt = np.array([[0, 0, 1, 2.0]])
    pred = np.array([[0, 0, 1, 2.0], [0, 0, 1, 2.0]])
    judged = judge_pair(_masks([1, 1, 1, 1], [1, 1, 1, 0]), pred, gt_masks, gt,
                        np.array([1.0, 2.0]))
    # Higher score first takes the truth; the duplicate is a false positive.
    assert judged.true_positive["all"].tolist() == [False, True]
    assert average_precision([judged])["all"] == pytest.approx(100.0)
    empty = judge_pair(np.zeros((1, 0, 4), bool), np.zeros((0, 4)), gt_masks, gt, np.zeros(0))
    assert average_precision([judged, empty])["all"] == pytest.approx(50.0)


def test_ground_truth_scene_scores_perfectly() -> None:
    synth = generate(5, level="clean", n_views=2)
    views = [Reconstruction(frame=v.frame, labels=v.gt_labels, planes=v.gt_params)
             for v in synth.views]
    cams = [Camera(v.frame.K, v.R, v.t, v.frame.width, v.frame.height) for v in synth.views]
    scene = Scene(cameras=cams, views=views, planes=synth.gt_planes_world,
                  links=[dict(t) for t in synth.view_to_global])
    judged, scale = judge_scene(scene, synth)
    assert scale == pytest.approx(1.0)
    assert judged.true_positive["all"].all() and judged.n_gt == len(synth.gt_planes_world)
    assert average_precision([judged])["all"] == pytest.approx(100.0)
