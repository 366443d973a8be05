"""Cue corruption: clean is the ground truth, strong errs more than mild."""

from __future__ import annotations

import numpy as np

from monoplane.synth import generate
from monoplane.synth.corrupt import LEVEL_PARAMS, blur_discontinuities, occlusion_edges, smooth_warp

W, H = 128, 96


def _depth_error(depth: np.ndarray, gt: np.ndarray) -> float:
    """Mean absolute relative error after median-scale alignment."""
    s = np.median(gt / depth)
    return float(np.mean(np.abs(s * depth - gt) / gt))


def _normal_error_deg(n: np.ndarray, gt: np.ndarray) -> float:
    cos = np.clip(np.sum(n.astype(np.float64) * gt, axis=-1), -1, 1)
    return float(np.degrees(np.mean(np.arccos(cos))))


def test_clean_equals_ground_truth() -> None:
    v = generate(3, "clean", W, H).views[0]
    assert np.array_equal(v.frame.depth, v.gt_depth)
    assert np.array_equal(v.frame.normals, v.gt_normals)
    assert v.scale == 1.0 and v.frame.depth_kind == "metric"


def test_strong_worse_than_mild() -> None:
    for seed in range(4):
        mild = generate(seed, "mild", W, H).views[0]
        strong = generate(seed, "strong", W, H).views[0]
        dm = _depth_error(mild.frame.depth, mild.gt_depth)
        ds = _depth_error(strong.frame.depth, strong.gt_depth)
        nm = _normal_error_deg(mild.frame.normals, mild.gt_normals)
        ns = _normal_error_deg(strong.frame.normals, strong.gt_normals)
        assert 0.002 < dm < ds < 0.2
        assert 0.5 < nm < ns < 20.0


def test_unknown_scale_applied() -> None:
    lo, hi = LEVEL_PARAMS["mild"].scale_range
    scales = []
    for seed in range(6):
        v = generate(seed, "mild", 64, 48).views[0]
        ratio = np.median(v.frame.depth / v.gt_depth)
        assert lo * 0.9 < ratio < hi * 1.1
        assert abs(ratio / v.scale - 1) < 0.05
        scales.append(v.scale)
    assert max(scales) / min(scales) > 1.5, "scale should vary from scene to scene"


def test_smooth_warp_amplitude_and_smoothness() -> None:
    w = smooth_warp(96, 128, 3, 0.05, np.random.default_rng(0))
    assert np.isclose(np.abs(w).max(), 0.05)
    assert abs(w.mean()) < 1e-12
    # Low frequency: neighbouring pixels differ by a tiny fraction of the amplitude.
    assert np.abs(np.diff(w, axis=1)).max() < 0.05 * 0.1


def test_blur_only_near_discontinuities() -> None:
    depth = np.full((40, 40), 2.0)
    depth[:, 20:] = 4.0
    depth[5, 5] = 2.0  # no edge there
    edges = occlusion_edges(depth)
    assert edges[:, 19:21].all() and edges.sum() == 80
    out = blur_discontinuities(depth, edges, sigma=2.0, width=3.0)
    assert np.array_equal(out[:, :15], depth[:, :15]) and np.array_equal(out[:, 25:], depth[:, 25:])
    assert 2.0 < out[10, 19] < 4.0 and 2.0 < out[10, 20] < 4.0
