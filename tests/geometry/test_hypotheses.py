"""Plane hypotheses (monoplane.geometry.hypotheses) against numpy references."""

import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.geometry.hypotheses import (
    SearchRule,
    refit_hypothesis,
    sample_hypotheses,
    search_batches,
)
from monoplane.geometry.normal_bins import bin_points
from monoplane.geometry.planes import fit_plane, planes_from_triplets


def unit_mean(normals, fallback):
    """numpy reference: normalised mean over the second-last axis, fallback where it
    vanishes."""
    m = normals.mean(axis=-2)
    norm = np.linalg.norm(m, axis=-1, keepdims=True)
    return np.where(norm > 1e-9, m / np.maximum(norm, 1e-300), fallback)


def test_sample_hypotheses_equal_the_triplet_planes_and_the_numpy_mean():
    rng = np.random.default_rng(3)
    points = rng.normal(size=(50, 3))
    points[12] = points[10] + 2.0 * (points[11] - points[10])  # 10, 11, 12 collinear
    normals = rng.normal(size=(50, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[7] = -normals[8]  # with 8 and a zero vector the mean vanishes
    normals[9] = 0.0
    samples = rng.integers(0, 50, size=(200, 3))
    samples[0] = [7, 8, 9]
    samples[1] = [10, 11, 12]
    planes, model = sample_hypotheses(points, normals, samples)
    want, valid = planes_from_triplets(points[samples])
    assert not valid[1] and valid[0]
    np.testing.assert_array_equal(planes, want[valid])
    np.testing.assert_array_equal(model, unit_mean(normals[samples[valid]], want[valid, :3]))
    np.testing.assert_array_equal(model[0], planes[0, :3])  # the fallback where it vanishes


def test_refit_hypothesis_is_the_plane_fit_and_the_mean_normal_of_the_members():
    rng = np.random.default_rng(1)
    n = np.array([0.2, -1.0, 0.1]) / np.linalg.norm([0.2, -1.0, 0.1])
    x = rng.normal(size=(3000, 3))
    exact = x - (x @ n + 1.5)[:, None] * n  # on the plane n . X + 1.5 = 0
    normals = n + 0.1 * rng.normal(size=(3000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    members = np.sort(rng.choice(3000, 2000, replace=False))
    plane, model = refit_hypothesis(exact, normals, members, np.zeros(3))
    np.testing.assert_allclose(plane, [*n, 1.5], atol=1e-12)
    np.testing.assert_array_equal(model, unit_mean(normals[members][None], np.zeros((1, 3)))[0])
    noisy = exact + 0.01 * rng.normal(size=exact.shape)
    plane, _ = refit_hypothesis(noisy, normals, members, np.zeros(3))
    np.testing.assert_allclose(plane, fit_plane(noisy[members])[0], rtol=0, atol=1e-12)
    # Normals that cancel out: the fallback.
    flip = normals.copy()
    flip[members[1::2]] = -flip[members[::2]][: len(members[1::2])]
    _, model = refit_hypothesis(exact, flip, members, np.array([0.0, 0.0, 1.0]))
    np.testing.assert_array_equal(model, [0.0, 0.0, 1.0])
    with pytest.raises(InvalidInput, match="at least 3"):
        refit_hypothesis(exact, normals, members[:2], np.zeros(3))


def _plane_and_clutter(rng):
    """400 points on z = 0.2 (normal +z) and 200 scattered points with random normals."""
    on = np.column_stack([rng.uniform(-0.5, 0.5, (400, 2)), np.full(400, 0.2)])
    off = rng.uniform(-0.5, 0.5, (200, 3))
    normals = np.vstack([np.tile([0.0, 0.0, 1.0], (400, 1)), rng.normal(size=(200, 3))])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    return np.vstack([on, off]), normals


def _rule(**changes):
    rule = SearchRule(batch=50, first=100, budget=1000, check=True, cos_min=float(np.cos(0.2)),
                      epsilon=0.01, epsilon_n=0.2, min_iterations=100, max_iterations=1000,
                      confidence=0.99)
    return rule._replace(**changes)


def test_search_batches_takes_its_scalars_in_one_rule_and_finds_the_plane():
    rng = np.random.default_rng(0)
    points, normals = _plane_and_clutter(rng)
    pool = np.arange(len(points), dtype=np.int64)
    binned = bin_points(points, normals, pool, 0.2)
    found, plane, model = search_batches(np.random.default_rng(1), points, normals, pool, pool,
                                         binned, _rule())
    assert found
    # Any all-inlier sample spans the plane exactly: n = ±z, d = ∓0.2 with d >= 0.
    np.testing.assert_allclose(plane, [0.0, 0.0, -1.0, 0.2], atol=1e-12)
    np.testing.assert_allclose(model, [0.0, 0.0, 1.0], atol=1e-12)
    # A normal test nothing passes finds nothing; the rule's other fields are its own.
    found, _, _ = search_batches(np.random.default_rng(1), points, normals, pool, pool, binned,
                                 _rule(cos_min=1.5))
    assert not found
    # Without the normal test the draw is uniform and still finds the plane.
    found, plane, _ = search_batches(np.random.default_rng(1), points, normals, pool, pool,
                                     binned, _rule(check=False, cos_min=-2.0, first=50,
                                                   budget=50))
    assert found and abs(plane[2]) > 1 - 1e-12
