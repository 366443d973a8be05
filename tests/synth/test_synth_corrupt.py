"""Cue corruption: clean is the ground truth, strong errs more than mild."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from monoplane.synth import generate
from monoplane.synth.corrupt import (
    LEVEL_PARAMS,
    CorruptionParams,
    blur_discontinuities,
    corrupt,
    corrupt_depth,
    corrupt_normals,
    occlusion_edges,
    smooth_warp,
)

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


# --------------------------------------------------------------------------------------------
# The reusable pieces, as real data (with holes) uses them


def _only(level: str, **keep: float) -> CorruptionParams:
    """``level``'s parameters with every depth step but ``keep`` switched off."""
    off = dict(scale_range=(1.0, 1.0), gamma=0.0, warp=0.0, warp_bumps=0, edge_sigma=0.0,
               edge_width=0.0, depth_noise=0.0)
    p = LEVEL_PARAMS[level]
    return replace(p, **{k: getattr(p, k) if k in keep else v for k, v in off.items()})


def _ramp_px(row: np.ndarray, low: float, high: float) -> int:
    """Pixels of a step's profile strictly between 10 % and 90 % of the way up (its rise)."""
    frac = (row - low) / (high - low)
    return int(np.sum((frac > 0.1) & (frac < 0.9)))


@pytest.mark.parametrize("width, level, ramp", [(256, "mild", (1, 3)), (256, "strong", (5, 7)),
                                                (640, "mild", (5, 7))])
def test_a_step_edge_becomes_a_ramp_that_scales_with_the_width(width: int, level: str,
                                                               ramp: tuple[int, int]) -> None:
    depth = np.full((32, width), 2.0)
    depth[:, width // 2:] = 3.0
    out, scale = corrupt_depth(depth, _only(level, edge_sigma=1, edge_width=1),
                               np.random.default_rng(0))
    assert scale == 1.0
    n = _ramp_px(out[16].astype(np.float64), 2.0, 3.0)
    assert ramp[0] <= n <= ramp[1]
    # Away from the edge the depth is untouched.
    np.testing.assert_allclose(out[:, : width // 2 - 3 * width // 64], 2.0, rtol=1e-6)


def test_depth_noise_is_the_levels_fraction_of_the_median() -> None:
    depth = np.full((96, 128), 2.5)
    for level in ("mild", "strong"):
        out, scale = corrupt_depth(depth, _only(level, depth_noise=1, scale_range=1),
                                   np.random.default_rng(1))
        noise = out / (scale * 2.5) - 1.0
        assert abs(noise.mean()) < 1e-3
        assert noise.std() == pytest.approx(LEVEL_PARAMS[level].depth_noise, rel=0.05)


def test_corrupted_depth_keeps_holes_and_ignores_them() -> None:
    # Two near surfaces (2 m | 3 m) before a far wall (10 m, the median); a hole beside the
    # 2 | 3 edge, one in the middle of a surface.
    depth = np.full((48, 256), 10.0)
    depth[:, :50], depth[:, 50:100] = 2.0, 3.0
    depth[20:24, 42:50] = 0.0
    depth[5:15, 10:20] = 0.0
    out, scale = corrupt_depth(depth, LEVEL_PARAMS["strong"], np.random.default_rng(2))
    valid = depth > 0
    assert np.array_equal(out > 0, valid)
    away = valid.copy()
    away[:, 40:110] = False                       # the edges' blur mixes surfaces
    ratio = out[away] / (scale * depth[away])
    assert 0.75 < ratio.min() and ratio.max() < 1.3
    # A hole's rim is no occlusion edge, and the blur never averages the hole in.
    assert not occlusion_edges(depth)[:, :40].any()
    blurred, _ = corrupt_depth(depth, _only("strong", edge_sigma=1, edge_width=1),
                               np.random.default_rng(2))
    near = blurred[10:34, 30:70][valid[10:34, 30:70]]
    assert near.min() >= 2.0 - 1e-5 and near.max() <= 3.0 + 1e-5
    assert np.ptp(near) > 0.5   # still blurred


def test_corrupted_normals_keep_holes_blur_creases_and_turn_a_few_degrees() -> None:
    # Two walls meeting in a vertical crease at u = 32; no normal in the top rows.
    n = np.zeros((48, 64, 3))
    a, b = np.array([0.6, 0.0, -0.8]), np.array([-0.6, 0.0, -0.8])
    n[:, :32], n[:, 32:] = a, b
    n[:4] = 0.0
    K = np.array([[60.0, 0, 31.5], [0, 60.0, 23.5], [0, 0, 1]])
    blur_only = replace(LEVEL_PARAMS["strong"], normal_rotation_deg=0.0, normal_noise=0.0)
    out = corrupt_normals(n, K, blur_only, np.random.default_rng(0))
    assert not out[:4].any()
    np.testing.assert_allclose(np.linalg.norm(out[4:], axis=-1), 1.0, atol=1e-5)
    # Beside the crease the normals are a mix of both walls, far from it they are exact.
    assert out[24, 31] @ a < 0.99 and out[24, 31] @ b > a @ b + 0.05
    np.testing.assert_allclose(out[24, :20], np.broadcast_to(a, (20, 3)), atol=1e-6)
    for level, (lo, hi) in (("mild", (0.5, 4.0)), ("strong", (2.0, 12.0))):
        turned = corrupt_normals(n, K, LEVEL_PARAMS[level], np.random.default_rng(5))
        err = _normal_error_deg(turned[4:, :20], n[4:, :20])
        assert lo < err < hi


def test_corrupt_is_the_depth_steps_then_the_normal_steps() -> None:
    v = generate(4, "clean", 64, 48).views[0]
    whole = corrupt(v.gt_depth, v.gt_normals, v.frame.K, "mild", np.random.default_rng(9))
    rng = np.random.default_rng(9)
    depth, scale = corrupt_depth(v.gt_depth, LEVEL_PARAMS["mild"], rng)
    normals = corrupt_normals(v.gt_normals, v.frame.K, LEVEL_PARAMS["mild"], rng)
    assert scale == whole.scale
    assert np.array_equal(depth, whole.depth) and np.array_equal(normals, whole.normals)
