"""VOI, RI and SC against hand-computed values and brute-force definitions."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.evaluation.segmentation import (
    contingency,
    segmentation_scores,
)

GT = np.array([[1, 1, 1], [2, 2, 2]])


def test_perfect_prediction_scores_best_whatever_the_label_ids() -> None:
    pred = np.array([[7, 7, 7], [3, 3, 3]])
    s = segmentation_scores(pred, GT)
    assert s.voi == pytest.approx(0.0, abs=1e-12)
    assert s.ri == pytest.approx(1.0)
    assert s.sc == pytest.approx(1.0)
    assert s.n_pixels == 6


def test_merge_of_two_planes() -> None:
    # Table [[3], [3]]: H(G) = ln 2, H(P) = 0, joint = ln 2 -> VOI = ln 2.
    # Disagreeing pairs: the 9 cross pairs out of C(6, 2) = 15 -> RI = 0.4.
    # Each GT plane has IoU 3/6 with the merged segment -> SC = 0.5.
    s = segmentation_scores(np.ones((2, 3), dtype=int), GT)
    assert s.voi == pytest.approx(math.log(2))
    assert s.ri == pytest.approx(0.4)
    assert s.sc == pytest.approx(0.5)


def test_split_of_one_plane() -> None:
    gt = np.ones((2, 3), dtype=int)
    s = segmentation_scores(GT, gt)
    assert s.voi == pytest.approx(math.log(2))
    assert s.ri == pytest.approx(0.4)
    assert s.sc == pytest.approx(0.5)  # covering of GT by the prediction: best IoU 3/6


def test_prediction_non_planar_pixels_are_one_pooled_segment() -> None:
    pred = np.array([[1, 0, 0], [0, 0, 2]])
    # Scored table (rows GT 1, 2; columns pred 0, 1, 2): [[2, 1, 0], [2, 0, 1]].
    np.testing.assert_array_equal(contingency(pred, GT), [[2, 1, 0], [2, 0, 1]])
    s = segmentation_scores(pred, GT)
    # H(G) = ln 2, H(P) = H(1/6, 4/6, 1/6), joint = H(1/6, 1/3, 1/3, 1/6); VOI works out to ln 3.
    assert s.voi == pytest.approx(math.log(3))
    # Same-GT pairs 6, same-pred pairs 6 (the pooled 4 px), both 2 -> 8 disagreements of 15.
    assert s.ri == pytest.approx(7 / 15)
    # Each GT plane: IoU 1/3 with its own plane, 2/5 with the pooled segment -> 0.4.
    assert s.sc == pytest.approx(0.4)


def test_empty_prediction_is_one_segment_not_a_free_pass() -> None:
    s = segmentation_scores(np.zeros((2, 3), dtype=int), GT)
    merged = segmentation_scores(np.ones((2, 3), dtype=int), GT)
    assert (s.voi, s.ri, s.sc) == pytest.approx((merged.voi, merged.ri, merged.sc))


def test_ground_truth_non_planar_pixels_are_ignored() -> None:
    gt = np.array([[1, 1, 0], [2, 2, 0]])
    pred = np.array([[1, 1, 5], [2, 2, 1]])  # anything on GT non-planar pixels
    s = segmentation_scores(pred, gt)
    assert (s.voi, s.ri, s.sc, s.n_pixels) == pytest.approx((0.0, 1.0, 1.0, 4))


def test_no_ground_truth_plane_gives_neutral_scores() -> None:
    s = segmentation_scores(np.ones((2, 3), dtype=int), np.zeros((2, 3), dtype=int))
    assert (s.voi, s.ri, s.sc, s.n_pixels) == (0.0, 1.0, 1.0, 0)


def _brute_force(pred: np.ndarray, gt: np.ndarray) -> tuple[float, float, float]:
    """Definitions evaluated literally: all pixel pairs, per-pixel entropies, mask IoUs."""
    keep = gt.ravel() > 0
    g, p = gt.ravel()[keep], pred.ravel()[keep]
    n = g.size
    agree = sum((g[i] == g[j]) == (p[i] == p[j]) for i, j in itertools.combinations(range(n), 2))
    ri = agree / (n * (n - 1) / 2)

    def entropy(x: np.ndarray) -> float:
        _, c = np.unique(x, return_counts=True, axis=0)
        q = c / n
        return float(-(q * np.log(q)).sum())

    mi = entropy(g) + entropy(p) - entropy(np.stack([g, p], axis=1))
    voi = entropy(g) + entropy(p) - 2 * mi
    sc = 0.0
    for lab in np.unique(g):
        gm = g == lab
        best = max(((gm & (p == q)).sum() / (gm | (p == q)).sum()) for q in np.unique(p))
        sc += gm.sum() * best
    return voi, ri, sc / n


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matches_brute_force_definitions_on_random_maps(seed: int) -> None:
    rng = np.random.default_rng(seed)
    gt = rng.integers(0, 4, size=(6, 7))
    pred = rng.integers(0, 5, size=(6, 7))
    s = segmentation_scores(pred, gt)
    assert (s.voi, s.ri, s.sc) == pytest.approx(_brute_force(pred, gt))


def test_is_fast_on_a_full_resolution_map() -> None:
    rng = np.random.default_rng(0)
    gt = rng.integers(0, 30, size=(480, 640))
    pred = rng.integers(0, 30, size=(480, 640))
    s = segmentation_scores(pred, gt)
    assert 0.0 < s.ri < 1.0


@pytest.mark.parametrize("pred, gt", [
    (np.zeros((2, 3), int), np.zeros((3, 2), int)),
    (np.zeros((2, 3)), np.zeros((2, 3), int)),
    (-np.ones((2, 3), int), np.zeros((2, 3), int)),
])
def test_rejects_bad_inputs(pred: np.ndarray, gt: np.ndarray) -> None:
    with pytest.raises(InvalidInput):
        segmentation_scores(pred, gt)
