"""Plane primitives against closed-form answers."""

import numpy as np
import pytest

from monoplane.geometry.planes import (
    fit_plane,
    fit_planes_per_label,
    planes_from_triplets,
    point_plane_distances,
)


def on_plane(n, d, count, seed=0):
    rng = np.random.default_rng(seed)
    n = np.asarray(n, float) / np.linalg.norm(n)
    x = rng.normal(size=(count, 3))
    return x - (x @ n + d)[:, None] * n, n


def test_fit_plane_exact_points_and_orientation():
    pts, n = on_plane([0.2, -1.0, 0.1], 1.5, 50)
    plane, rmse = fit_plane(pts)
    assert np.allclose(plane, [*n, 1.5]) and rmse < 1e-12


def test_fit_plane_rmse_of_symmetric_offsets():
    # Points at z = 2 +- 0.1: the plane z = 2, i.e. (0, 0, -1, 2) facing the camera, RMSE 0.1.
    xy = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], float)
    pts = np.vstack([np.c_[xy, np.full(4, 2.1)], np.c_[xy, np.full(4, 1.9)]])
    plane, rmse = fit_plane(pts)
    assert np.allclose(plane, [0, 0, -1, 2]) and np.isclose(rmse, 0.1)


def test_triplets_and_distances():
    tri = np.array([[[0, 0, 1], [1, 0, 1], [0, 1, 1]], [[0, 0, 0], [1, 1, 1], [2, 2, 2]]], float)
    planes, valid = planes_from_triplets(tri)
    assert valid.tolist() == [True, False]
    assert np.allclose(planes[0], [0, 0, -1, 1])
    assert np.allclose(point_plane_distances(np.array([[5, 5, 3.0]]), planes[:1]), [[2.0]])


def test_fit_planes_per_label():
    a, na = on_plane([0, -1, 0], 1.0, 20, seed=1)
    b, nb = on_plane([1, 0, -1], 2.0, 30, seed=2)
    pts = np.vstack([a, b, [[9.0, 9, 9]] * 2])
    labels = np.r_[np.full(20, 1), np.full(30, 3), [2, 2]]
    params, rmse, count = fit_planes_per_label(pts, labels, 3)
    assert count.tolist() == [20, 2, 30]
    assert np.allclose(params[0], [*na, 1.0]) and np.allclose(params[2], [*nb, 2.0])
    assert np.isnan(params[1]).all() and np.isnan(rmse[1])


def test_per_label_fits_match_one_fit_per_label():
    # Reference: fit_plane on each label's points. Labels 0, out of range or with < 3 points
    # are left out; offsets far from the origin check the centring.
    rng = np.random.default_rng(7)
    groups, labels = [], []
    for k in range(1, 9):
        count = [0, 1, 2, 3, 50, 400, 1000, 7][k - 1]
        n = rng.normal(size=3)
        x, _ = on_plane(n, rng.uniform(0, 50), count, seed=k)
        groups.append(x + rng.normal(0, 0.01, x.shape))
        labels.append(np.full(count, k))
    noise = rng.normal(size=(100, 3))
    pts = np.vstack([*groups, noise, noise])
    labels = np.concatenate([*labels, np.zeros(100, int), np.full(100, 12)])
    order = rng.permutation(len(pts))
    params, rmse, count = fit_planes_per_label(pts[order], labels[order], 8)
    assert count.tolist() == [0, 1, 2, 3, 50, 400, 1000, 7]
    for k, group in enumerate(groups):
        if len(group) < 3:
            assert np.isnan(params[k]).all() and np.isnan(rmse[k])
            continue
        ref, ref_rmse = fit_plane(group)
        np.testing.assert_allclose(params[k], ref, rtol=1e-9, atol=1e-9)
        assert rmse[k] == pytest.approx(ref_rmse, rel=1e-9, abs=1e-12)


def reference_planes_from_triplets(t):
    """The vectorised construction: cross products, scale-aware degeneracy, d >= 0."""
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    normal = np.cross(b - a, c - a)
    norm = np.linalg.norm(normal, axis=1)
    edge2 = np.maximum(((b - a) ** 2).sum(1), ((c - a) ** 2).sum(1))
    valid = norm > 1e-9 * np.maximum(edge2, 1e-300)
    planes = np.zeros((len(t), 4))
    n = normal[valid] / norm[valid, None]
    d = -np.einsum("ij,ij->i", n, a[valid])
    n[d < 0] *= -1
    planes[valid, :3] = n
    planes[valid, 3] = np.abs(d)
    return planes, valid


def test_triplet_planes_match_the_vectorised_reference():
    rng = np.random.default_rng(3)
    t = rng.normal(size=(500, 3, 3))
    t[:50, 2] = t[:50, 0] + 0.5 * (t[:50, 1] - t[:50, 0])  # collinear
    t[50:60] = t[50:60, :1]  # one point three times
    t[60:70, 2] = t[60:70, 0] + 2.0 * (t[60:70, 1] - t[60:70, 0]) + 1e-12  # nearly collinear
    planes, valid = planes_from_triplets(t)
    ref, ref_valid = reference_planes_from_triplets(t)
    np.testing.assert_array_equal(valid, ref_valid)
    assert not valid[:60].any() and valid[70:].all()
    np.testing.assert_allclose(planes, ref, rtol=1e-12, atol=1e-15)


def test_per_label_sums_add_each_labels_points_in_order_to_the_bit():
    # Reference: per label, in point order, centroid sums, then centred products, then the
    # squared distances through the centroid, in plain Python floats. Runs of one label (as
    # along image rows, summed in registers) and scattered labels, int32 and int64, some out
    # of range, all give these bits.
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(3000, 3)) * [3.0, 2.0, 0.01] + [5.0, -2.0, 40.0]
    runs = np.repeat(rng.integers(-1, 9, 300), 10)
    for labels in (runs, rng.integers(0, 8, 3000), runs.astype(np.int32)):
        params, rmse, count = fit_planes_per_label(pts, labels, 7)
        for k in range(1, 8):
            members = [tuple(map(float, p)) for p, lab in zip(pts, labels, strict=True)
                       if lab == k]
            assert count[k - 1] == len(members)
            if len(members) < 3:
                continue
            c = [0.0, 0.0, 0.0]
            for p in members:
                c = [c[j] + p[j] for j in range(3)]
            c = [x / len(members) for x in c]
            m = [0.0] * 6
            for p in members:
                x = [p[j] - c[j] for j in range(3)]
                m = [m[0] + x[0] * x[0], m[1] + x[0] * x[1], m[2] + x[0] * x[2],
                     m[3] + x[1] * x[1], m[4] + x[1] * x[2], m[5] + x[2] * x[2]]
            scatter = np.array([[m[0], m[1], m[2]], [m[1], m[3], m[4]], [m[2], m[4], m[5]]])
            normal = np.linalg.eigh(scatter[None])[1][0, :, 0]
            d = -float(np.einsum("pc,pc->p", normal[None], np.array([c]))[0])
            if d < 0:
                normal, d = -normal, -d
            np.testing.assert_array_equal(params[k - 1], [*normal, d])
            total = 0.0
            for p in members:
                r = 0.0
                for j in range(3):
                    r += normal[j] * (p[j] - c[j])
                total += r * r
            assert rmse[k - 1] == np.sqrt(total / len(members))
