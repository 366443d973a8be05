"""The curvature test: spread of the normal cue over a plane's pixels, and its noise floor."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.geometry.flatness import (
    interior_labels,
    interior_samples,
    noise_floor_deg,
    normal_spread_deg,
)


def _unit(x: np.ndarray) -> np.ndarray:
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


def test_interior_labels_drop_a_band_along_every_border() -> None:
    labels = np.zeros((10, 12), np.int32)
    labels[:, :6], labels[:, 6:] = 1, 2
    inner = interior_labels(labels, 2)
    # Columns 4..7 are within 2 px of the other label; the image border does not count.
    assert (inner[:, :4] == 1).all() and (inner[:, 4:8] == 0).all() and (inner[:, 8:] == 2).all()
    np.testing.assert_array_equal(interior_labels(labels, 0), labels)


@pytest.mark.parametrize("seed", range(6))
def test_interior_samples_are_the_sampled_interior_labels(seed: int) -> None:
    # Reference: the full-resolution erosion, masked by the depth, then sampled. Blocky label
    # maps with holes, odd sizes, radii 0-6 and steps 1-5; labels up to 70 000 compare
    # modulo 65536 as the erosion's uint16 image does.
    rng = np.random.default_rng(seed)
    h, w = rng.integers(5, 90, size=2)
    coarse = rng.integers(0, 4, size=(h // 4 + 1, w // 4 + 1))
    labels = np.kron(coarse, np.ones((4, 4), int))[:h, :w].astype(np.int32)
    labels[rng.random((h, w)) < 0.02] = rng.integers(0, 70_000)
    depth = rng.uniform(0.5, 3.0, (h, w)).astype(np.float32)
    depth[rng.random((h, w)) < 0.1] = 0.0
    for radius in range(7):
        step = int(rng.integers(1, 6))
        want = (interior_labels(labels, radius) * (depth > 0))[::step, ::step].ravel()
        np.testing.assert_array_equal(interior_samples(labels, depth, radius, step), want)


def test_flat_noisy_patch_spreads_by_its_noise_and_a_sphere_by_its_curvature() -> None:
    rng = np.random.default_rng(0)
    h, w = 60, 120
    labels = np.zeros((h, w), np.int32)
    labels[:, :60], labels[:, 60:] = 1, 2
    normals = np.zeros((h, w, 3))
    noise = 0.02
    normals[:, :60] = _unit(np.array([0.1, -0.2, -1.0]) + rng.normal(0, noise, (h, 60, 3)))
    # Plane 2 lies on a sphere: normals turn with position, 40 degrees across the patch.
    u, v = np.meshgrid(np.linspace(-0.35, 0.35, 60), np.linspace(-0.35, 0.35, h))
    normals[:, 60:] = _unit(np.stack([u, v, -np.ones_like(u)], -1))
    spread, count = normal_spread_deg(normals, labels, 2, radius=1)
    # Noise of 0.02 per component: the angle is Rayleigh with sigma 0.02 rad, median 1.35 deg.
    assert spread[0] == pytest.approx(np.degrees(noise * np.sqrt(2 * np.log(2))), rel=0.1)
    assert spread[1] > 8.0
    assert count[0] == h * 59 and count[1] == h * 59          # one border column each


def test_the_spread_ignores_a_strip_of_a_neighbouring_surface() -> None:
    labels = np.ones((40, 40), np.int32)
    normals = np.zeros((40, 40, 3))
    normals[:] = [0.0, 0.0, -1.0]
    normals[:, :8] = _unit(np.array([1.0, 0.0, -1.0]))          # a fifth on another surface
    spread, _ = normal_spread_deg(normals, labels, 1, radius=0)
    assert spread[0] < 1e-6


def test_too_few_samples_give_nan_and_the_floor_is_the_weighted_median() -> None:
    labels = np.zeros((20, 20), np.int32)
    labels[:5, :5] = 1
    normals = np.tile([0.0, 0.0, -1.0], (20, 20, 1))
    spread, count = normal_spread_deg(normals, labels, 2, radius=0)
    assert np.isnan(spread).all() and count.tolist() == [25, 0]
    assert noise_floor_deg(np.array([1.0, 20.0, 2.0, np.nan]),
                           np.array([100, 10, 50, 1000])) == 1.0
    assert noise_floor_deg(np.array([1.0, 2.0]), np.array([10, 30])) == 2.0
    assert np.isnan(noise_floor_deg(np.array([np.nan]), np.array([5])))


def test_spread_of_groups_ignores_the_sign_of_a_normal() -> None:
    # A face whose normals flip sign from point to point (a viewpoint on its plane) is still one
    # direction: the spread is its noise, not 90 degrees.
    from monoplane.geometry.flatness import spread_of_groups

    rng = np.random.default_rng(1)
    n = _unit(np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.01, (400, 3)))
    n *= np.where(rng.random(400) < 0.5, -1.0, 1.0)[:, None]
    spread, count = spread_of_groups(n, np.ones(400, np.int64), 1)
    assert count[0] == 400 and spread[0] < 1.5


def test_quadric_ratio_is_one_on_a_noisy_plane_and_large_on_a_cap_and_a_strip() -> None:
    from monoplane.geometry.flatness import quadric_ratio

    rng = np.random.default_rng(2)
    u, v = rng.uniform(-1, 1, (2, 2000))
    plane = np.stack([u, v, 0.3 * u - 0.2 * v + rng.normal(0, 0.01, u.size)], 1)
    # A spherical cap of radius 5 over the same square: sagitta 0.2, far above the noise.
    cap = np.stack([u, v, np.sqrt(25 - u**2 - v**2) + rng.normal(0, 0.01, u.size)], 1)
    # A 20-degree strip of a cylinder of radius 1 around the y axis, exact points.
    a = np.radians(rng.uniform(-10, 10, u.size))
    strip = np.stack([np.sin(a), v, np.cos(a)], 1)
    points = np.concatenate([plane, cap, strip])
    labels = np.repeat([1, 2, 3], u.size)
    ratio = quadric_ratio(points, labels, 3)
    assert ratio[0] == pytest.approx(1.0, abs=0.01)
    assert ratio[1] > 3.0 and ratio[2] > 100.0
    # Fewer than MIN_SAMPLES points: no evidence, NaN.
    assert np.isnan(quadric_ratio(points[:10], np.ones(10, np.int64), 1)[0])
