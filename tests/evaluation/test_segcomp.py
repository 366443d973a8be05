"""The SegComp measure against hand-computed cases."""

import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.evaluation.segcomp import segcomp


def strip(*runs):
    """A 1-row label image from (label, length) runs."""
    return np.concatenate([np.full(n, v, dtype=np.int32) for v, n in runs])[None, :]


def counts(s):
    return (s.correct, s.over, s.under, s.missed, s.noise)


def test_identical_segmentations_are_all_correct():
    gt = strip((1, 10), (2, 10), (3, 5))
    s = segcomp(gt * 7, gt)  # label values do not matter
    assert counts(s) == (3, 0, 0, 0, 0) and s.n_gt == 3 and s.n_pred == 3


def test_correct_needs_both_overlap_fractions():
    # G1 = 10 px, P1 covers 8 of them plus 2 of G2: 8/10 of G1 and 8/10 of P1 -> correct at 0.8.
    gt = strip((1, 10), (2, 10))
    pred = strip((1, 8), (2, 2), (2, 2), (0, 8))
    # P (label 1) = 8 px all in G1; P (label 2) = 4 px: 2 in G1, 2 in G2.
    s = segcomp(pred, gt, 0.8)
    # G1: O=8 >= 0.8*10 and >= 0.8*8 -> correct. G2: P2 holds 2/10 of G2 -> missed; P2 has
    # 2/4 in G2 and 2/4 in G1 -> noise.
    assert counts(s) == (1, 0, 0, 1, 1)
    # At T = 0.9 the 8/10 is not enough: G1 missed, P1 noise (its 8/8 inside G1 alone is not an
    # over-segmentation, which needs two parts).
    assert counts(segcomp(pred, gt, 0.9)) == (0, 0, 0, 2, 2)


def test_over_segmentation():
    # G1 (20 px) cut into P1 (10) and P2 (9) plus one unlabelled pixel: 19/20 >= 0.8.
    gt = strip((1, 20), (2, 10))
    pred = strip((1, 10), (2, 9), (0, 1), (3, 10))
    assert counts(segcomp(pred, gt)) == (1, 1, 0, 0, 0)


def test_over_segmentation_needs_enough_coverage():
    # Parts cover 15/20 < 0.8 of G1: no over-segmentation, G1 missed, both parts noise.
    gt = strip((1, 20))
    pred = strip((1, 8), (2, 7), (0, 5))
    assert counts(segcomp(pred, gt)) == (0, 0, 0, 1, 2)


def test_under_segmentation():
    # P1 (25 px) covers G1 (10) and G2 (10) fully and 5 px of G3 (20): 20/25 = 0.8 of P1 in
    # regions it covers entirely -> one under-segmentation of G1, G2; G3 missed (15/20 < 0.8
    # in P2... P2 holds 15 px of G3 and nothing else: 15/20 = 0.75 < 0.8).
    gt = strip((1, 10), (2, 10), (3, 20))
    pred = strip((1, 25), (2, 15))
    assert counts(segcomp(pred, gt)) == (0, 0, 1, 1, 1)
    # At T = 0.75, G3 and P2 are a correct detection.
    assert counts(segcomp(pred, gt, 0.75)) == (1, 0, 1, 0, 0)


def test_unlabelled_ground_truth_is_ignored():
    # P1 spills over 30 unlabelled pixels: they do not count against it.
    gt = strip((0, 30), (1, 10))
    pred = strip((1, 40))
    assert counts(segcomp(pred, gt)) == (1, 0, 0, 0, 0)
    # A machine region entirely on unlabelled pixels is not noise.
    pred2 = strip((2, 30), (1, 10))
    s = segcomp(pred2, gt)
    assert counts(s) == (1, 0, 0, 0, 0) and s.n_pred == 1


def test_nothing_predicted_misses_everything():
    gt = strip((1, 10), (2, 5))
    assert counts(segcomp(np.zeros_like(gt), gt)) == (0, 0, 0, 2, 0)


def test_two_dimensional_images():
    gt = np.zeros((4, 4), dtype=np.uint16)
    gt[:2] = 1
    gt[2:] = 2
    pred = np.ones((4, 4), dtype=np.int32)
    pred[2:, :] = 5
    pred[3, 3] = 0
    assert counts(segcomp(pred, gt)) == (2, 0, 0, 0, 0)


def test_bad_input():
    gt = strip((1, 4))
    with pytest.raises(InvalidInput, match="tolerance"):
        segcomp(gt, gt, 0.5)
    with pytest.raises(InvalidInput, match="shape"):
        segcomp(gt[:, :2], gt)
    with pytest.raises(InvalidInput, match="integers"):
        segcomp(gt.astype(float), gt)
