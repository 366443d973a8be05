"""Per-plane recall at depth thresholds (PlaneNet / PlaneRCNN protocol, MonoPlane Tab. I).

A ground-truth plane counts as recalled at threshold ``τ`` when a predicted plane

1. overlaps it with mask IoU > 0.5, and
2. the mean absolute difference between the (scale-aligned) predicted planar depth and the
   ground-truth depth, over the pixels the two masks share, is at most ``τ``.

Each predicted plane is matched at most once, greedily by decreasing IoU. (With the strict
IoU > 0.5 test and non-overlapping segments the match is unique anyway: a plane cannot cover
more than half of two disjoint masks' unions.)

Scale: monocular depth is known only up to scale, so before scoring the predicted planar depth
is multiplied by ``median(gt) / median(pred)`` over the pixels where both are valid and the
ground truth is closer than ``max_depth`` (10 m in the paper's protocol), as every method in
the paper's tables is.

Recall over a data set is ``Σ recalled / Σ ground-truth planes`` (pooled over frames), which is
what :class:`PlaneRecall` counts make easy to sum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.errors import InvalidInput

#: Depth thresholds of the paper's indoor tables, in metres.
DEPTH_THRESHOLDS: tuple[float, ...] = (0.05, 0.1, 0.6)
#: A match needs mask IoU strictly above this.
IOU_THRESHOLD = 0.5
#: Ground-truth depths at or beyond this (metres) are left out of the median scale.
MAX_SCALE_DEPTH = 10.0


def median_scale(pred_depth: np.ndarray, gt_depth: np.ndarray,
                 max_depth: float = MAX_SCALE_DEPTH) -> float:
    """Median scale factor that aligns a predicted depth map with the ground truth.

    Parameters
    ----------
    pred_depth : numpy.ndarray
        (H, W) predicted z-depth (any scale), 0 = invalid.
    gt_depth : numpy.ndarray
        (H, W) ground-truth z-depth in metres, 0 = invalid.
    max_depth : float
        Pixels whose ground truth is at or beyond this are ignored.

    Returns
    -------
    float
        ``median(gt) / median(pred)`` over pixels valid in both; 1.0 when there are none.
    """
    pred = np.asarray(pred_depth, dtype=np.float64)
    gt = np.asarray(gt_depth, dtype=np.float64)
    if pred.shape != gt.shape:
        raise InvalidInput(f"depth shapes differ: {pred.shape} vs {gt.shape}")
    both = (pred > 0) & (gt > 0) & (gt < max_depth) & np.isfinite(pred)
    if not np.any(both):
        return 1.0
    return float(np.median(gt[both]) / np.median(pred[both]))


@dataclass(frozen=True)
class PlaneRecall:
    """Recall counts of one frame.

    Attributes
    ----------
    thresholds : tuple of float
        Depth thresholds ``τ`` in metres.
    recalled : tuple of int
        Number of ground-truth planes recalled at each threshold.
    n_gt : int
        Number of ground-truth planes in the frame.
    scale : float
        Median scale applied to the predicted depth.
    """

    thresholds: tuple[float, ...]
    recalled: tuple[int, ...]
    n_gt: int
    scale: float

    @property
    def recall(self) -> tuple[float, ...]:
        """Per-threshold recall of this frame alone (1.0 when it has no ground-truth plane)."""
        if self.n_gt == 0:
            return tuple(1.0 for _ in self.thresholds)
        return tuple(r / self.n_gt for r in self.recalled)


def match_planes(pred: np.ndarray, gt: np.ndarray,
                 iou_threshold: float = IOU_THRESHOLD) -> list[tuple[int, int, float]]:
    """One-to-one matches between predicted and ground-truth planes with IoU above a threshold.

    Parameters
    ----------
    pred, gt : numpy.ndarray
        (H, W) integer label maps, 0 = non-planar (never matched).
    iou_threshold : float
        Minimum IoU, exclusive.

    Returns
    -------
    list of (int, int, float)
        ``(gt_label, pred_label, iou)`` triples, greedily chosen by decreasing IoU.
    """
    pred = np.asarray(pred).astype(np.int64)
    gt = np.asarray(gt).astype(np.int64)
    if pred.shape != gt.shape:
        raise InvalidInput(f"label shapes differ: {pred.shape} vs {gt.shape}")
    g_ids = np.unique(gt[gt > 0])
    p_ids = np.unique(pred[pred > 0])
    if g_ids.size == 0 or p_ids.size == 0:
        return []
    g_area = np.bincount(np.searchsorted(g_ids, gt[gt > 0]), minlength=g_ids.size)
    p_area = np.bincount(np.searchsorted(p_ids, pred[pred > 0]), minlength=p_ids.size)
    both = (gt > 0) & (pred > 0)
    gi = np.searchsorted(g_ids, gt[both])
    pi = np.searchsorted(p_ids, pred[both])
    inter = np.bincount(gi * p_ids.size + pi, minlength=g_ids.size * p_ids.size)
    inter = inter.reshape(g_ids.size, p_ids.size).astype(np.float64)
    iou = inter / (g_area[:, None] + p_area[None, :] - inter)
    rows, cols = np.nonzero(iou > iou_threshold)
    order = np.argsort(-iou[rows, cols], kind="stable")
    used_g: set[int] = set()
    used_p: set[int] = set()
    matches = []
    for k in order:
        r, c = int(rows[k]), int(cols[k])
        if r in used_g or c in used_p:
            continue
        used_g.add(r)
        used_p.add(c)
        matches.append((int(g_ids[r]), int(p_ids[c]), float(iou[r, c])))
    return matches


def plane_recall(pred_labels: np.ndarray, pred_depth: np.ndarray, gt_labels: np.ndarray,
                 gt_depth: np.ndarray, thresholds: tuple[float, ...] = DEPTH_THRESHOLDS,
                 iou_threshold: float = IOU_THRESHOLD, align_scale: bool = True,
                 max_depth: float = MAX_SCALE_DEPTH) -> PlaneRecall:
    """Per-plane recall of one frame at several depth thresholds.

    Parameters
    ----------
    pred_labels : numpy.ndarray
        (H, W) integer predicted plane labels, 0 = non-planar.
    pred_depth : numpy.ndarray
        (H, W) predicted planar z-depth (e.g. ``Reconstruction.planar_depth()``), any scale,
        0 = invalid.
    gt_labels : numpy.ndarray
        (H, W) integer ground-truth plane labels, 0 = non-planar.
    gt_depth : numpy.ndarray
        (H, W) ground-truth z-depth in metres, 0 = invalid.
    thresholds : tuple of float
        Depth thresholds ``τ`` in metres.
    iou_threshold : float
        Mask IoU a match must exceed.
    align_scale : bool
        Multiply ``pred_depth`` by :func:`median_scale` first (the paper's protocol).
    max_depth : float
        Depth cut-off of the median scale, metres.

    Returns
    -------
    PlaneRecall
    """
    pred_depth = np.asarray(pred_depth, dtype=np.float64)
    gt_depth = np.asarray(gt_depth, dtype=np.float64)
    if pred_depth.shape != np.shape(pred_labels) or gt_depth.shape != np.shape(gt_labels):
        raise InvalidInput("each depth map must have the shape of its label map")
    scale = median_scale(pred_depth, gt_depth, max_depth) if align_scale else 1.0
    depth = pred_depth * scale
    n_gt = int(np.unique(np.asarray(gt_labels)[np.asarray(gt_labels) > 0]).size)
    errors = []
    for g, p, _ in match_planes(pred_labels, gt_labels, iou_threshold):
        overlap = (gt_labels == g) & (pred_labels == p) & (depth > 0) & (gt_depth > 0)
        if np.any(overlap):
            errors.append(float(np.abs(depth[overlap] - gt_depth[overlap]).mean()))
    err = np.asarray(errors)
    recalled = tuple(int(np.count_nonzero(err <= t)) for t in thresholds)
    return PlaneRecall(thresholds=tuple(float(t) for t in thresholds), recalled=recalled,
                       n_gt=n_gt, scale=scale)
