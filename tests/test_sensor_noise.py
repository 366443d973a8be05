"""Depth noise measured on a frame's planes (monoplane.geometry.sensor_noise)."""

import numpy as np
import pytest

from monoplane.geometry.sensor_noise import noise_limited_epsilon, plane_residual_sigma


def test_sigma_grows_with_depth_squared_and_is_given_at_the_far_quantile():
    # A plane y = 1 with Kinect-like noise 0.002 z² along its normal, z in 1..5: σ at the 90th
    # percentile depth (4.6) is 0.002 × 4.6².
    rng = np.random.default_rng(0)
    z = rng.uniform(1, 5, 200_000)
    points = np.stack([rng.uniform(-1, 1, z.size), 1 + rng.normal(0, 0.002 * z ** 2), z], 1)
    labels = np.ones(z.size, dtype=np.int64)
    sigma = plane_residual_sigma(points, z, labels, np.array([[0.0, 1.0, 0.0, -1.0]]))
    assert sigma == pytest.approx(0.002 * np.quantile(z, 0.9) ** 2, rel=0.02)


def test_sigma_ignores_unlabelled_points_and_needs_three():
    points = np.array([[0, 0, 1.0], [0, 0, 1.0], [0, 5, 1.0]])
    plane = np.array([[0.0, 1.0, 0.0, 0.0]])
    assert np.isnan(plane_residual_sigma(points, points[:, 2], np.array([1, 1, 0]), plane))
    assert plane_residual_sigma(points[:2].repeat(2, 0), np.ones(4), np.ones(4, int),
                                plane) == 0.0


def test_noise_limited_epsilon_is_clipped_between_the_floor_and_epsilon():
    assert noise_limited_epsilon(0.02, 0.001, 3.0) == pytest.approx(0.003)
    assert noise_limited_epsilon(0.02, 0.1, 3.0) == 0.02
    assert noise_limited_epsilon(0.02, 0.0, 3.0) == pytest.approx(0.002)
    assert noise_limited_epsilon(0.02, float("nan"), 3.0) == 0.02
    assert noise_limited_epsilon(0.02, 0.001, 0.0) == 0.02
