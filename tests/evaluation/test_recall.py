"""Plane recall at depth thresholds with known depth offsets, IoU rules and scale alignment."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.evaluation.recall import match_planes, median_scale, plane_recall

# Two GT planes: left half (label 1) at 2 m, right half (label 2) at 3 m.
GT_LABELS = np.repeat(np.array([[1] * 4 + [2] * 4]), 4, axis=0)
GT_DEPTH = np.where(GT_LABELS == 1, 2.0, 3.0)


def test_offsets_decide_the_threshold_at_which_a_plane_counts() -> None:
    pred_depth = np.where(GT_LABELS == 1, 2.07, 3.3)  # errors 0.07 m and 0.3 m
    r = plane_recall(GT_LABELS, pred_depth, GT_LABELS, GT_DEPTH, align_scale=False)
    assert r.thresholds == (0.05, 0.1, 0.6)
    assert r.recalled == (0, 1, 2)
    assert r.n_gt == 2
    assert r.recall == pytest.approx((0.0, 0.5, 1.0))


def test_error_is_the_mean_absolute_difference_over_the_overlap() -> None:
    pred_depth = GT_DEPTH.copy()
    pred_depth[:, 0] += 0.16  # one column of four off by 0.16 m: mean 0.04 on plane 1
    pred_depth[:, 1] -= 0.16  # signs must not cancel: mean |.| = 0.08
    r = plane_recall(GT_LABELS, pred_depth, GT_LABELS, GT_DEPTH, thresholds=(0.07, 0.09),
                     align_scale=False)
    assert r.recalled == (1, 2)


def test_unknown_scale_is_removed_by_median_alignment() -> None:
    pred_depth = GT_DEPTH / 3.7
    assert median_scale(pred_depth, GT_DEPTH) == pytest.approx(3.7)
    r = plane_recall(GT_LABELS, pred_depth, GT_LABELS, GT_DEPTH)
    assert r.recalled == (2, 2, 2)
    assert r.scale == pytest.approx(3.7)
    assert plane_recall(GT_LABELS, pred_depth, GT_LABELS, GT_DEPTH,
                        align_scale=False).recalled == (0, 0, 0)


def test_median_scale_ignores_far_and_invalid_pixels() -> None:
    gt = np.array([[1.0, 2.0, 3.0, 50.0, 0.0]])
    pred = np.array([[0.5, 1.0, 1.5, 1.0, 9.0]])
    assert median_scale(pred, gt) == pytest.approx(2.0)
    assert median_scale(np.zeros_like(gt), gt) == 1.0


def test_iou_must_exceed_one_half() -> None:
    pred = GT_LABELS.copy()
    pred[:2, :4] = 0  # plane 1 predicted on exactly half its pixels: IoU = 0.5, not > 0.5
    r = plane_recall(pred, GT_DEPTH, GT_LABELS, GT_DEPTH, align_scale=False)
    assert r.recalled == (1, 1, 1)
    pred[0, :3] = 1  # 11 of 16 px: IoU 11/16 > 0.5
    assert plane_recall(pred, GT_DEPTH, GT_LABELS, GT_DEPTH, align_scale=False).recalled == (
        2, 2, 2)


def test_a_merged_prediction_recalls_neither_plane() -> None:
    pred = np.ones_like(GT_LABELS)  # IoU 0.5 with each plane
    r = plane_recall(pred, GT_DEPTH, GT_LABELS, GT_DEPTH, align_scale=False)
    assert r.recalled == (0, 0, 0)


def test_each_prediction_matches_at_most_once() -> None:
    gt = np.array([[1, 1, 1, 1, 2]])
    pred = np.array([[3, 3, 3, 3, 3]])  # IoU 4/5 with plane 1, 1/5 with plane 2
    assert match_planes(pred, gt) == [(1, 3, pytest.approx(0.8))]
    r = plane_recall(pred, np.ones((1, 5)), gt, np.ones((1, 5)), align_scale=False)
    assert r.recalled == (1, 1, 1) and r.n_gt == 2


def test_no_prediction_recalls_nothing() -> None:
    r = plane_recall(np.zeros_like(GT_LABELS), np.zeros(GT_LABELS.shape), GT_LABELS, GT_DEPTH)
    assert r.recalled == (0, 0, 0) and r.n_gt == 2
