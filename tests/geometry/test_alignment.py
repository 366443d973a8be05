"""Scale alignment of monocular depth onto sparse SfM depths."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.geometry.alignment import align_scale, sample_depth


def _setup(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    mono = rng.uniform(1.0, 5.0, (60, 80)).astype(np.float32)
    pixels = np.stack([rng.integers(0, 80, n), rng.integers(0, 60, n)], axis=1).astype(float)
    return mono, pixels, sample_depth(mono, pixels)


def test_exact_scale_recovered() -> None:
    mono, pixels, d = _setup(50)
    a = align_scale(mono, pixels, 2.5 * d)
    assert a.scale == pytest.approx(2.5, rel=1e-6)
    assert a.num_points == a.num_inliers == 50
    assert a.residual == pytest.approx(0.0, abs=1e-5)


def test_least_squares_closed_form_on_noisy_inliers() -> None:
    mono, pixels, d = _setup(200, seed=1)
    rng = np.random.default_rng(2)
    sfm = 0.7 * d * (1 + 0.02 * rng.standard_normal(len(d)))
    a = align_scale(mono, pixels, sfm)
    # All points are inliers, so the result is the paper's closed form s = Σ Ds Dm / Σ Dm².
    assert a.num_inliers == 200
    assert a.scale == pytest.approx(float(sfm @ d / (d @ d)), rel=1e-9)
    assert 0.0 < a.relative_residual < 0.05


def test_gross_outliers_are_rejected() -> None:
    mono, pixels, d = _setup(100, seed=3)
    sfm = 3.0 * d
    sfm[:30] *= np.linspace(2.0, 6.0, 30)  # mismatched points far off the true scale
    a = align_scale(mono, pixels, sfm)
    assert a.scale == pytest.approx(3.0, rel=1e-6)
    assert a.num_inliers == 70
    plain = float(sfm @ d / (d @ d))
    assert abs(plain - 3.0) > 0.5  # the non-robust solve would be badly off


def test_invalid_depth_and_outside_pixels_ignored() -> None:
    mono, pixels, d = _setup(40, seed=4)
    mono = mono.copy()
    mono[:, :40] = 0
    pixels = np.vstack([pixels, [[-5.0, 3.0], [500.0, 2.0]]])
    a = align_scale(mono, pixels, np.concatenate([2.0 * d, [1.0, 1.0]]))
    assert a.scale == pytest.approx(2.0)
    assert a.num_points == int(np.sum(pixels[:40, 0] >= 39.5))


def test_too_few_points_is_an_error() -> None:
    mono, pixels, d = _setup(3)
    with pytest.raises(InvalidInput, match="at least 5 SfM points"):
        align_scale(mono, pixels, d)
