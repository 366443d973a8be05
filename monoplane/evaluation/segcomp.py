"""The SegComp region classification of Hoover et al. (1996) for range-image segmentations.

Hoover, Jean-Baptiste, Jiang, Flynn, Bunke, Goldgof, Bowyer, Eggert, Fitzgibbon and Fisher,
"An Experimental Comparison of Range Image Segmentation Algorithms", IEEE TPAMI 18(7), 1996.

Given a ground-truth segmentation with regions ``G_m`` and a machine segmentation with regions
``P_n``, let ``O_mn`` be the number of pixels in both and ``T`` a tolerance in (0.5, 1]:

* **correct detection** of ``G_m`` by ``P_n``: ``O_mn >= T |P_n|`` and ``O_mn >= T |G_m|``;
* **over-segmentation** of ``G_m`` into ``P_n1 .. P_nx`` (x >= 2): every ``O_mni >= T |P_ni|``
  and ``Σ_i O_mni >= T |G_m|``;
* **under-segmentation** of ``G_m1 .. G_mx`` (x >= 2) into ``P_n``: every ``O_min >= T |G_mi|``
  and ``Σ_i O_min >= T |P_n|``;
* **missed**: a ground-truth region in none of the above;
* **noise**: a machine region in none of the above.

Conventions (the ones of the SegComp comparison tool):

* Only pixels with a ground-truth label (``gt > 0``) take part; ground-truth 0 (shadow, no
  measurement, unlabelled edges) is ignored, and so are the parts of machine regions that fall
  on it. Region sizes ``|G_m|`` and ``|P_n|`` are counted on those pixels.
* Machine label 0 means "no region" and is never classified.
* Classifications are assigned in the order correct, over-, under-segmentation; a region used
  by one is not considered for the next. With ``T > 0.5`` a region can take part in at most one
  instance of each kind anyway.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.evaluation.segmentation import check_label_pair

#: The tolerance of the published ABW tables.
DEFAULT_TOLERANCE = 0.8


@dataclass(frozen=True)
class SegCompScores:
    """Hoover et al.'s region counts for one image.

    Attributes
    ----------
    correct : int
        Correctly detected ground-truth regions.
    over : int
        Over-segmented ground-truth regions (instances).
    under : int
        Under-segmentation instances (machine regions covering several ground-truth regions).
    missed : int
        Ground-truth regions in no other class.
    noise : int
        Machine regions in no other class.
    n_gt : int
        Ground-truth regions.
    n_pred : int
        Machine regions with at least one pixel on labelled ground truth.
    tolerance : float
        The T used.
    """

    correct: int
    over: int
    under: int
    missed: int
    noise: int
    n_gt: int
    n_pred: int
    tolerance: float


def _compact(labels: np.ndarray) -> tuple[np.ndarray, int]:
    """Renumber positive labels to 0..K-1 (label 0 becomes -1); returns (ids, K)."""
    values, inverse = np.unique(labels, return_inverse=True)
    positive = values > 0
    remap = np.full(values.size, -1, dtype=np.int64)
    remap[positive] = np.arange(int(positive.sum()))
    return remap[inverse.ravel()], int(positive.sum())


def segcomp(pred: np.ndarray, gt: np.ndarray, tolerance: float = DEFAULT_TOLERANCE
            ) -> SegCompScores:
    """Classify the regions of a machine segmentation against the ground truth.

    Parameters
    ----------
    pred : numpy.ndarray
        Integer machine labels (any shape, e.g. (H, W) or (N,)), 0 = no region.
    gt : numpy.ndarray
        Integer ground-truth labels of the same shape, 0 = not scored.
    tolerance : float
        T in (0.5, 1]; the published tables use 0.8.

    Returns
    -------
    SegCompScores
    """
    pred, gt = check_label_pair(pred, gt)
    if not 0.5 < tolerance <= 1.0:
        raise InvalidInput(f"SegComp tolerance must lie in (0.5, 1], got {tolerance}")
    scored = gt.ravel() > 0
    g, n_gt = _compact(gt.ravel()[scored])
    p, n_pred = _compact(pred.ravel()[scored])
    inside = p >= 0
    overlap = np.zeros((n_gt, n_pred), dtype=np.int64)
    np.add.at(overlap, (g[inside], p[inside]), 1)
    size_g = np.bincount(g, minlength=n_gt)
    size_p = overlap.sum(axis=0)
    # Machine regions that only touch unscored pixels do not exist for this measure.
    present = size_p > 0
    n_present = int(present.sum())
    t = float(tolerance)
    # Both fractions, compared with a tiny slack so that exact hand-computed ratios such as
    # 4/5 at T = 0.8 count as reaching the tolerance despite rounding.
    of_g = overlap >= t * size_g[:, None] - 1e-9
    of_p = overlap >= t * size_p[None, :] - 1e-9

    used_g = np.zeros(n_gt, dtype=bool)
    used_p = ~present
    correct = 0
    for m, n in zip(*np.nonzero(of_g & of_p), strict=True):
        if not used_g[m] and not used_p[n]:
            used_g[m] = used_p[n] = True
            correct += 1

    over = 0
    for m in np.flatnonzero(~used_g):
        parts = np.flatnonzero(of_p[m] & ~used_p)
        if parts.size >= 2 and overlap[m, parts].sum() >= t * size_g[m] - 1e-9:
            used_g[m] = True
            used_p[parts] = True
            over += 1

    under = 0
    for n in np.flatnonzero(~used_p):
        parts = np.flatnonzero(of_g[:, n] & ~used_g)
        if parts.size >= 2 and overlap[parts, n].sum() >= t * size_p[n] - 1e-9:
            used_p[n] = True
            used_g[parts] = True
            under += 1

    return SegCompScores(correct=correct, over=over, under=under,
                         missed=int((~used_g).sum()), noise=int((~used_p).sum()),
                         n_gt=n_gt, n_pred=n_present, tolerance=t)
