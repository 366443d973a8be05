"""Descriptor matching and the correspondence bookkeeping of the features stage kind."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from monoplane.contracts import FeatureMatcher, NoConfig
from monoplane.datamodel import Frame, intrinsics_matrix
from monoplane.errors import InvalidInput
from monoplane.features import Correspondences, Keypoints, PairMatches
from monoplane.features.matching import mutual_nearest, mutual_ratio


def _unit(a: np.ndarray) -> np.ndarray:
    return (a / np.linalg.norm(a, axis=1, keepdims=True)).astype(np.float32)


def test_mutual_nearest_keeps_mutual_pairs_above_the_floor() -> None:
    e = np.eye(4, dtype=np.float32)
    a = e[[0, 1, 2]]
    # b0 = a1 exactly, b1 close to a0, b2 halfway between a2 and a3 (similarity 0.707).
    b = _unit(np.array([[0, 1, 0, 0], [1, 0.1, 0, 0], [0, 0, 1, 1]], np.float32))
    index, sim = mutual_nearest(a, b, 0.8)
    assert index.tolist() == [[0, 1], [1, 0]]
    np.testing.assert_allclose(sim, [1 / np.sqrt(1.01), 1.0], rtol=1e-6)
    index, _ = mutual_nearest(a, b, 0.7)
    assert index.tolist() == [[0, 1], [1, 0], [2, 2]]


def test_mutual_nearest_drops_one_sided_pairs() -> None:
    # Both a0 and a1 prefer b0, which prefers a1: only (1, 0) is mutual.
    a = _unit(np.array([[1, 0.3], [1, 0.05]], np.float32))
    b = _unit(np.array([[1, 0.0], [0, 1.0]], np.float32))
    index, _ = mutual_nearest(a, b, 0.0)
    assert index.tolist() == [[1, 0]]


def test_mutual_ratio_applies_lowes_ratio() -> None:
    a = np.array([[0, 0], [10, 0]], np.float32)
    # a0: nearest b0 at 1, second b1 at sqrt(101); a1: b1 at 1 and b2 at 1.2 (ratio 0.83).
    b = np.array([[1, 0], [10, 1], [10, -1.2]], np.float32)
    index, score = mutual_ratio(a, b, 0.8)
    assert index.tolist() == [[0, 0]]
    np.testing.assert_allclose(score, [1 - 1 / np.sqrt(101)], rtol=1e-5)
    assert mutual_ratio(a, b, 0.9)[0].tolist() == [[0, 0], [1, 1]]


K = intrinsics_matrix(100.0, 100.0, 31.5, 23.5)


def _frames(n: int) -> list[Frame]:
    return [Frame(rgb=np.full((48, 64, 3), 10 * i, np.uint8), K=K, name=f"v{i}") for i in range(n)]


@dataclass
class _Grid(FeatureMatcher):
    """Local features: keypoints on a grid, descriptors that match keypoint k to keypoint k."""

    name = "grid"
    Config = NoConfig

    def __init__(self) -> None:
        super().__init__()
        self.detected: list[str] = []

    def detect(self, frame: Frame) -> Keypoints:
        self.detected.append(frame.name)
        pixels = np.array([[5.0, 5.0], [20.0, 10.0], [40.0, 30.0]])
        return Keypoints(pixels, np.eye(3, dtype=np.float32), np.ones(3, np.float32))

    def match(self, a: Keypoints, b: Keypoints) -> PairMatches:
        index, sim = mutual_nearest(a.descriptors, b.descriptors, 0.5)
        return PairMatches(index, None, None, sim)


class _Pairwise(FeatureMatcher):
    """A pairwise network: view i's pixel (u, v) matches view j's (u + j - i, v)."""

    name = "pairwise"
    pairwise = True
    Config = NoConfig

    def match_pair(self, frame_i: Frame, frame_j: Frame) -> PairMatches:
        i, j = int(frame_i.name[1:]), int(frame_j.name[1:])
        pi = np.array([[10.0, 10.0], [30.2, 20.0], [30.4, 20.1]])
        return PairMatches(None, pi, pi + [j - i, 0.0], np.ones(3, np.float32))


def test_local_features_are_detected_once_per_view() -> None:
    stage = _Grid()
    found = Correspondences(stage, _frames(3))
    assert found.matches(0, 1).tolist() == [[0, 0], [1, 1], [2, 2]]
    assert found.matches(2, 1).tolist() == [[0, 0], [1, 1], [2, 2]]
    assert sorted(found.all_matches()) == [(0, 1), (0, 2), (1, 2)]
    assert stage.detected == ["v0", "v1", "v2"]
    pi, pj = found.pixels(0, 2)
    np.testing.assert_array_equal(pi, pj)


def test_pairwise_pixels_become_shared_keypoints_and_tracks() -> None:
    found = Correspondences(_Pairwise(), _frames(3))
    m01, m02 = found.matches(0, 1), found.matches(0, 2)
    # (30.2, 20) and (30.4, 20.1) round to one pixel: one keypoint, matched once.
    assert len(m01) == 2 and len(m02) == 2
    # View 0's keypoints are shared by both pairs: the same indices, so tracks form.
    np.testing.assert_array_equal(m01[:, 0], m02[:, 0])
    kp0 = found.keypoints(0)
    assert kp0.descriptors is None and len(kp0) == 2
    pi, pj = found.pixels(0, 2)
    np.testing.assert_allclose(pj - pi, [[2.0, 0.0], [2.0, 0.0]])
    # View 1 gathered pixels from pairs (0, 1) and (1, 2): (11, 10), (31.2, 20) and (10, 10),
    # (30.2, 20); none within half a pixel of another.
    assert len(found.keypoints(1)) == 4


def test_bad_view_indices_are_one_line_errors() -> None:
    found = Correspondences(_Grid(), _frames(2))
    with pytest.raises(InvalidInput, match="out of range"):
        found.matches(0, 2)
    with pytest.raises(InvalidInput, match="itself"):
        found.matches(1, 1)
