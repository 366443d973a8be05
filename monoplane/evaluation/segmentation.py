"""Plane segmentation metrics: variation of information, Rand index, segmentation covering.

Protocol (as used by PlaneRCNN, PlaneTR and PlaneRecTR, and by the MonoPlane paper, Tab. I)
-------------------------------------------------------------------------------------------
* Only **ground-truth planar pixels** are scored (``gt > 0``); ground-truth non-planar pixels
  are ignored entirely.
* Every predicted plane is one segment; all of the prediction's **non-planar pixels** (label 0)
  inside the scored region are pooled into **one extra segment**. A method that labels nothing
  therefore gets a single segment covering the whole scored region, not a free pass.

All three metrics are functions of the contingency table ``n[i, j]`` (pixels in GT segment ``i``
and predicted segment ``j``), so they cost ``O(H·W + #gt · #pred)``, never ``O((H·W)²)``.

* VOI (lower is better) ``= H(G) + H(P) − 2 I(G; P)``, in **nats** (natural logarithm).
* RI (higher is better): fraction of unordered pixel pairs on which the two segmentations
  agree (both "same segment" or both "different segments"), by pair counting on the table.
* SC (higher is better): covering of the ground truth by the prediction,
  ``(1/N) Σ_g |g| · max_p IoU(g, p)``, with sizes and IoUs taken over scored pixels only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.errors import InvalidInput


@dataclass(frozen=True)
class SegmentationScores:
    """VOI, RI and SC of one prediction against one ground truth.

    Attributes
    ----------
    voi : float
        Variation of information in nats (↓, 0 for identical segmentations).
    ri : float
        Rand index in [0, 1] (↑).
    sc : float
        Segmentation covering of the ground truth in [0, 1] (↑).
    n_pixels : int
        Number of scored (ground-truth planar) pixels.
    """

    voi: float
    ri: float
    sc: float
    n_pixels: int


def check_label_pair(pred: np.ndarray, gt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both label maps as arrays; InvalidInput unless same shape, integer and >= 0."""
    pred = np.asarray(pred)
    gt = np.asarray(gt)
    if pred.shape != gt.shape:
        raise InvalidInput(f"prediction shape {pred.shape} differs from ground truth {gt.shape}")
    for what, arr in (("prediction", pred), ("ground truth", gt)):
        if not np.issubdtype(arr.dtype, np.integer):
            raise InvalidInput(f"{what} labels must be integers, got {arr.dtype}")
        if arr.size and arr.min() < 0:
            raise InvalidInput(f"{what} labels must be >= 0 (0 = non-planar)")
    return pred, gt


def contingency(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """Contingency table of the prediction against the ground truth on GT planar pixels.

    Parameters
    ----------
    pred : numpy.ndarray
        (H, W) integer predicted labels, 0 = non-planar (pooled into one segment).
    gt : numpy.ndarray
        (H, W) integer ground-truth labels, 0 = non-planar (not scored).

    Returns
    -------
    numpy.ndarray
        (G, P) int64 table; ``table[i, j]`` counts scored pixels in the ``i``-th ground-truth
        plane and the ``j``-th predicted segment (the pooled non-planar segment is one of the
        columns when it is non-empty). Empty rows and columns are dropped; shape ``(0, 0)``
        when the ground truth has no planar pixel.
    """
    pred, gt = check_label_pair(pred, gt)
    scored = gt > 0
    g = gt[scored].astype(np.int64)
    p = pred[scored].astype(np.int64)
    if g.size == 0:
        return np.zeros((0, 0), dtype=np.int64)
    g_ids, g_idx = np.unique(g, return_inverse=True)
    p_ids, p_idx = np.unique(p, return_inverse=True)
    flat = np.bincount(g_idx * len(p_ids) + p_idx, minlength=len(g_ids) * len(p_ids))
    return flat.reshape(len(g_ids), len(p_ids)).astype(np.int64)


def _entropy(counts: np.ndarray, total: float) -> float:
    prob = counts[counts > 0] / total
    return float(-(prob * np.log(prob)).sum())


def variation_of_information(table: np.ndarray) -> float:
    """VOI ``H(G) + H(P) − 2 I(G; P) = 2 H(G, P) − H(G) − H(P)`` in nats.

    Parameters
    ----------
    table : numpy.ndarray
        (G, P) contingency table from :func:`contingency`.

    Returns
    -------
    float
        Non-negative VOI; 0 for an empty table.
    """
    total = float(table.sum())
    if total == 0:
        return 0.0
    joint = _entropy(table.ravel(), total)
    h_gt = _entropy(table.sum(axis=1), total)
    h_pred = _entropy(table.sum(axis=0), total)
    return max(0.0, 2.0 * joint - h_gt - h_pred)


def rand_index(table: np.ndarray) -> float:
    """Rand index by pair counting on the contingency table.

    With row sums ``a_i``, column sums ``b_j`` and ``N`` pixels, the number of pixel pairs on
    which the segmentations disagree is ``(Σ a_i² + Σ b_j²) / 2 − Σ n_ij²`` and
    ``RI = 1 − disagreements / C(N, 2)``.

    Parameters
    ----------
    table : numpy.ndarray
        (G, P) contingency table.

    Returns
    -------
    float
        RI in [0, 1]; 1 when there are fewer than two pixels.
    """
    t = table.astype(np.float64)
    n = t.sum()
    if n < 2:
        return 1.0
    disagree = 0.5 * ((t.sum(axis=1) ** 2).sum() + (t.sum(axis=0) ** 2).sum()) - (t**2).sum()
    return float(1.0 - disagree / (0.5 * n * (n - 1.0)))


def segmentation_covering(table: np.ndarray) -> float:
    """Covering of the ground truth by the prediction, ``(1/N) Σ_g |g| max_p IoU(g, p)``.

    Parameters
    ----------
    table : numpy.ndarray
        (G, P) contingency table (rows: ground truth, columns: prediction).

    Returns
    -------
    float
        SC in [0, 1]; 1 for an empty table.
    """
    t = table.astype(np.float64)
    n = t.sum()
    if n == 0:
        return 1.0
    gt_size = t.sum(axis=1)
    union = gt_size[:, None] + t.sum(axis=0)[None, :] - t
    best_iou = (t / np.maximum(union, 1.0)).max(axis=1)
    return float((gt_size * best_iou).sum() / n)


def segmentation_scores(pred: np.ndarray, gt: np.ndarray) -> SegmentationScores:
    """VOI, RI and SC of a predicted label map under the protocol of the module docstring.

    Parameters
    ----------
    pred : numpy.ndarray
        (H, W) integer predicted labels, 0 = non-planar.
    gt : numpy.ndarray
        (H, W) integer ground-truth labels, 0 = non-planar.

    Returns
    -------
    SegmentationScores
    """
    table = contingency(pred, gt)
    return SegmentationScores(voi=variation_of_information(table), ri=rand_index(table),
                              sc=segmentation_covering(table), n_pixels=int(table.sum()))
