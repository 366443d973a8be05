"""Connected components, small-region removal and refit, on hand-made maps with exact answers."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from monoplane.algorithm.region_moments import RegionMoments, refit_planes, scene_radius
from monoplane.algorithm.region_scan import scan_pieces
from monoplane.algorithm.regions import (
    _renumbered_pairs,
    absorb_small_regions,
    clean_regions,
    gate_filled_pixels,
    merge_coplanar,
    region_adjacency,
    remove_small_regions,
    scaled_min_area,
    split_components,
)
from monoplane.datamodel import Frame, Reconstruction, intrinsics_matrix, pixel_rays
from monoplane.errors import InvalidInput

# Label 1 has two regions touching only at a corner (joined by 8- but not by 4-connectivity)
# plus a separate region on the right; label 2 has two regions; 0 is non-planar. New labels go
# by original label, then by the raster index of each region's first pixel.
MAP = np.array([
    [1, 1, 0, 0, 0, 1],
    [1, 1, 0, 2, 0, 1],
    [0, 0, 1, 2, 0, 0],
    [2, 0, 1, 0, 0, 0],
], dtype=np.int32)


@pytest.mark.parametrize("connectivity, expected, origin", [
    (8, [[1, 1, 0, 0, 0, 2],
         [1, 1, 0, 3, 0, 2],
         [0, 0, 1, 3, 0, 0],
         [4, 0, 1, 0, 0, 0]], [1, 1, 2, 2]),
    (4, [[1, 1, 0, 0, 0, 2],
         [1, 1, 0, 4, 0, 2],
         [0, 0, 3, 4, 0, 0],
         [5, 0, 3, 0, 0, 0]], [1, 1, 1, 2, 2]),
])
def test_split_components_exact(connectivity, expected, origin):
    labels, origin_labels = split_components(MAP, connectivity=connectivity)
    np.testing.assert_array_equal(labels, expected)
    np.testing.assert_array_equal(origin_labels, origin)
    assert labels.dtype == np.int32


def test_split_components_anti_diagonal_and_edges():
    # An anti-diagonal chain is one region with 8-connectivity, three with 4-connectivity.
    m = np.array([[0, 0, 3], [0, 3, 0], [3, 0, 0]], dtype=np.int32)
    eight, origin8 = split_components(m, 8)
    np.testing.assert_array_equal(eight, (m > 0).astype(np.int32))
    np.testing.assert_array_equal(origin8, [3])
    four, origin4 = split_components(m, 4)
    np.testing.assert_array_equal(four, [[0, 0, 1], [0, 2, 0], [3, 0, 0]])
    np.testing.assert_array_equal(origin4, [3, 3, 3])
    empty, origin = split_components(np.zeros((3, 4), np.int32))
    assert not empty.any() and origin.size == 0
    with pytest.raises(InvalidInput):
        split_components(m, connectivity=6)


def test_remove_small_regions_exact():
    m = np.array([[1, 1, 2], [1, 3, 3], [0, 3, 3]], dtype=np.int32)
    labels, kept = remove_small_regions(m, min_area=3)
    np.testing.assert_array_equal(labels, [[1, 1, 0], [1, 2, 2], [0, 2, 2]])
    np.testing.assert_array_equal(kept, [1, 3])
    same, kept_all = remove_small_regions(m, min_area=0)
    np.testing.assert_array_equal(same, m)
    np.testing.assert_array_equal(kept_all, [1, 2, 3])
    none, kept_none = remove_small_regions(m, min_area=100)
    assert not none.any() and kept_none.size == 0


def test_scaled_min_area():
    assert scaled_min_area((192, 256)) == 300
    assert scaled_min_area((480, 640)) == 1875
    assert scaled_min_area((96, 128)) == 75
    assert scaled_min_area((192, 256), 0) == 0
    with pytest.raises(InvalidInput):
        scaled_min_area((192, 256), -1)


def two_plane_frame(height: int = 40, width: int = 60):
    """Exact depth of two planes (left: tilted wall, right: floor-like slope) and its labels."""
    K = intrinsics_matrix(50.0, 50.0, (width - 1) / 2, (height - 1) / 2)
    rays = pixel_rays(K, height, width)
    planes = np.array([[0.3, -0.2, -0.9327379, 3.0], [0.0, -0.8, -0.6, 2.0]])
    planes[:, :3] /= np.linalg.norm(planes[:, :3], axis=1, keepdims=True)
    labels = np.where(np.arange(width)[None, :] < width // 2, 1, 2).repeat(height, axis=0)
    p = planes[labels - 1]
    depth = -p[..., 3] / np.einsum("hwc,hwc->hw", rays, p[..., :3])
    assert np.all(depth > 0)
    return Frame(rgb=None, K=K, depth=depth), labels.astype(np.int32), planes


def test_refit_recovers_exact_planes():
    frame, labels, planes = two_plane_frame()
    # float32 depth limits accuracy; refit on float64 points computed from the exact planes.
    rays = pixel_rays(frame.K, *frame.shape)
    p = planes[labels - 1]
    z = -p[..., 3] / np.einsum("hwc,hwc->hw", rays, p[..., :3])
    points = rays * z[..., None]
    wrong = np.array([[0.0, 0.0, -1.0, 1.0], [0.0, 0.0, -1.0, 1.0]])
    params, rmse, support = refit_planes(points, np.ones(frame.shape, bool), labels, wrong)
    np.testing.assert_allclose(params, planes, atol=1e-9)
    # The RMSE is the root of the scatter's smallest eigenvalue: exact zero comes out as
    # sqrt(round-off), about 1e-7 of the scene's extent.
    np.testing.assert_allclose(rmse, 0.0, atol=1e-6)
    np.testing.assert_array_equal(support, [1200, 1200])


def test_refit_falls_back_without_enough_valid_points():
    frame, labels, planes = two_plane_frame()
    points = frame.points()
    valid = np.ones(frame.shape, bool)
    valid[labels == 2] = False
    valid[0, -2:] = True  # two valid points left on plane 2
    fallback = np.array([[0.0, 0.0, -1.0, 1.0], planes[1]])
    params, rmse, support = refit_planes(points, valid, labels, fallback)
    np.testing.assert_allclose(params[0], planes[0], atol=1e-5)
    np.testing.assert_array_equal(params[1], planes[1])
    np.testing.assert_array_equal(support, [1200, 2])
    assert rmse[1] < 1e-5


def test_clean_regions_splits_filters_and_refits():
    frame, labels, planes = two_plane_frame()
    # One plane label covering both true planes, split by a non-planar column in the middle;
    # plus a 4-pixel fragment that must disappear.
    observed = np.ones_like(labels)
    observed[:, 29:31] = 0
    observed[0:2, 0:2] = 2
    rec = Reconstruction(frame=frame, labels=observed,
                         planes=np.array([[0.0, 0.0, -1.0, 2.5], [0.0, 0.0, -1.0, 9.0]]),
                         config={"refiner": {"plugin": "x"}}, timings={"ransac": 1.0})
    out = clean_regions(rec, observed, min_area=10, connectivity=8)
    assert out.num_planes == 2
    expected = np.zeros_like(labels)
    expected[:, :29] = 1
    expected[:, 31:] = 2
    expected[0:2, 0:2] = 0
    np.testing.assert_array_equal(out.labels, expected)
    np.testing.assert_allclose(out.planes, planes, atol=1e-5)  # float32 depth
    assert np.all(out.rmse < 1e-5)
    np.testing.assert_array_equal(out.support, [40 * 29 - 4, 40 * 29])
    assert out.config == rec.config and out.timings == rec.timings
    assert out.frame is frame


def test_clean_regions_with_nothing_left():
    frame, labels, _ = two_plane_frame()
    rec = Reconstruction(frame=frame, labels=labels,
                         planes=np.array([[0.0, 0.0, -1.0, 2.5], [0.0, 0.0, -1.0, 9.0]]))
    out = clean_regions(rec, labels, min_area=10_000)
    assert out.num_planes == 0 and not out.labels.any()
    assert out.planes.shape == (0, 4) and out.rmse.shape == (0,)


def test_clean_regions_without_split_keeps_one_plane_per_label():
    frame, labels, planes = two_plane_frame()
    # Plane 1 appears as two large regions (left and right of a non-planar column) and one
    # 4-pixel fragment; plane 2 is a 5x5 block. With split=False the two large regions stay
    # plane 1, the fragment goes, and plane 2 keeps its own label.
    observed = np.ones_like(labels)
    observed[:, 29:31] = 0
    observed[:3, :3] = 0
    observed[:2, :2] = 1  # the fragment, cut off by a one-pixel non-planar L
    observed[35:40, 50:55] = 2
    params = np.array([[0.0, 0.0, -1.0, 2.5], [0.0, 0.0, -1.0, 9.0]])
    rec = Reconstruction(frame=frame, labels=observed, planes=params)
    out = clean_regions(rec, observed, min_area=10, split=False)
    expected = observed.copy()
    expected[:2, :2] = 0
    np.testing.assert_array_equal(out.labels, expected)
    assert out.num_planes == 2
    split = clean_regions(rec, observed, min_area=10, split=True)
    assert split.num_planes == 3
    np.testing.assert_array_equal(np.unique(split.labels), [0, 1, 2, 3])


# --- deviations from the paper: re-merging, absorbing, gating, scene radius -----------------

def flat_points(z: np.ndarray) -> np.ndarray:
    """(H, W, 3) points with x = column, y = row and the given z: planes z = const are exact."""
    h, w = z.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    return np.stack([u, v, z], axis=-1)


def test_scene_radius_exact():
    pts = np.zeros((1, 4, 3))
    pts[0, :, 0] = [0.0, 2.0, 4.0, 100.0]
    valid = np.array([[True, True, True, False]])
    assert scene_radius(pts, valid) == 2.0
    assert scene_radius(pts, np.zeros_like(valid)) == 0.0


def test_region_adjacency_exact():
    # 1 touches 2 side by side; 3 touches 2 only at a corner; 0 never counts.
    labels = np.array([
        [1, 2, 0, 0],
        [1, 2, 0, 0],
        [0, 0, 3, 0],
    ])
    np.testing.assert_array_equal(region_adjacency(labels, 8), [[1, 2], [2, 3]])
    np.testing.assert_array_equal(region_adjacency(labels, 4), [[1, 2]])


def test_merge_coplanar_joins_only_agreeing_regions_of_one_label():
    # Regions 1, 2, 3 came from label 1; 4 from label 2. 1 and 3 lie on z = 5 (cut apart by a
    # column of 0), 2 lies on z = 5.5, 4 on z = 5 but from another label.
    z = np.full((2, 7), 5.0)
    z[:, 2] = 5.5
    labels = np.array([
        [1, 0, 2, 0, 3, 0, 4],
        [1, 0, 2, 0, 3, 0, 4],
    ], dtype=np.int32)
    origin = np.array([1, 1, 1, 2])
    params = np.array([[0, 0, -1, 5.0], [0, 0, -1, 5.5], [0, 0, -1, 5.0], [0, 0, -1, 5.0]])
    pts, valid = flat_points(z), np.ones(z.shape, bool)
    new, new_origin = merge_coplanar(pts, valid, labels, origin, params, 10.0, 0.1)
    np.testing.assert_array_equal(new, [[1, 0, 2, 0, 1, 0, 3]] * 2)
    np.testing.assert_array_equal(new_origin, [1, 1, 2])
    # With a 1.0 tolerance region 2 is on the same plane too, and all of label 1 merges.
    new, new_origin = merge_coplanar(pts, valid, labels, origin, params, 10.0, 1.0)
    np.testing.assert_array_equal(new, [[1, 0, 1, 0, 1, 0, 2]] * 2)
    np.testing.assert_array_equal(new_origin, [1, 2])
    # Extra pairs are tested whatever their origin: 3 and 4 lie on z = 5 and join; the group
    # takes its representative's origin (the lower label of two equal areas: 3, from label 1).
    new, new_origin = merge_coplanar(pts, valid, labels, origin, params, 10.0, 0.1,
                                     extra_pairs=np.array([[3, 4], [2, 3]]))
    np.testing.assert_array_equal(new, [[1, 0, 2, 0, 1, 0, 1]] * 2)
    np.testing.assert_array_equal(new_origin, [1, 1])
    # A normal beyond the angle tolerance blocks the merge whatever the residuals.
    tilted = params.copy()
    tilted[2, :3] = [np.sin(0.3), 0.0, -np.cos(0.3)]  # 17 degrees
    new, _ = merge_coplanar(pts, valid, labels, origin, tilted, 10.0, 1.0)
    np.testing.assert_array_equal(new, [[1, 0, 1, 0, 2, 0, 3]] * 2)


@pytest.mark.parametrize("seed", range(6))
def test_absorb_choices_equal_the_numpy_loop(seed):
    # The compiled choice of each small region's plane against the loop it replaces: first
    # the pairs with the region first, then second, the first smallest RMS (argmin: a NaN
    # wins), kept when within the tolerance; ties, inf (no points) and NaN included.
    from monoplane.algorithm.regions import _absorb_into

    rng = np.random.default_rng(seed)
    num = 30
    small = rng.random(num) < 0.4
    rms = rng.choice([0.1, 0.2, 0.3, 0.5, np.inf], size=(num, num))
    rms[rng.random((num, num)) < 0.02] = np.nan
    pairs = np.argwhere(np.triu(rng.random((num, num)) < 0.15, 1)) + 1
    expected = np.arange(num + 1, dtype=np.int32)
    for s in np.flatnonzero(small) + 1:
        other = np.concatenate([pairs[pairs[:, 0] == s, 1], pairs[pairs[:, 1] == s, 0]])
        cand = other[~small[other - 1]]
        if cand.size:
            fit = rms[s - 1, cand - 1]
            best = int(np.argmin(fit))
            if fit[best] <= 0.25:
                expected[s] = cand[best]
    got = np.arange(num + 1, dtype=np.int32)
    _absorb_into(small, rms, pairs.astype(np.int64), 0.25, got)
    np.testing.assert_array_equal(got, expected)
    assert (got != np.arange(num + 1)).any()


def test_absorb_small_regions_exact():
    # Large regions 1 (z = 5) and 2 (z = 8); small region 3 lies on z = 5 and touches both: it
    # joins 1. Small region 4 lies on z = 20 and touches 2 only: it becomes 0. Small region 5
    # touches no large region: 0.
    z = np.array([
        [5.0, 5.0, 5.0, 8.0, 8.0, 8.0, 1.0],
        [5.0, 5.0, 5.0, 8.0, 8.0, 20.0, 1.0],
        [5.0, 5.0, 5.0, 8.0, 8.0, 8.0, 1.0],
    ])
    labels = np.array([
        [1, 1, 1, 2, 2, 2, 0],
        [1, 1, 3, 2, 2, 4, 0],
        [1, 1, 1, 2, 2, 2, 5],
    ], dtype=np.int32)
    z[1, 2] = 5.0
    params = np.array([[0, 0, -1, 5.0], [0, 0, -1, 8.0], [0, 0, -1, 9.0], [0, 0, -1, 20.0],
                       [0, 0, -1, 1.0]])
    out = absorb_small_regions(flat_points(z), np.ones(z.shape, bool), labels, params,
                               min_area=3, max_distance=0.5)
    expected = labels.copy()
    expected[1, 2] = 1
    expected[1, 5] = 0
    expected[2, 6] = 0
    np.testing.assert_array_equal(out, expected)


def test_gate_filled_pixels_exact():
    # Pixels (0, 1) and (0, 2) were 0 and the refinement gave them plane 1 (z = 5): the first
    # lies on it and keeps it, the second is 1 away and goes back to 0. (0, 0) was already
    # plane 1 and is never tested; (0, 3) was 0, stays 0.
    z = np.array([[9.0, 5.0, 6.0, 5.0]])
    before = np.array([[1, 0, 0, 0]])
    after = np.array([[1, 1, 1, 0]])
    out = gate_filled_pixels(flat_points(z), np.ones(z.shape, bool), before, after,
                             np.array([[0.0, 0.0, -1.0, 5.0]]), 0.5)
    np.testing.assert_array_equal(out, [[1, 1, 0, 0]])
    invalid = np.array([[True, False, True, True]])
    out = gate_filled_pixels(flat_points(z), invalid, before, after,
                             np.array([[0.0, 0.0, -1.0, 5.0]]), 0.5)
    np.testing.assert_array_equal(out, [[1, 0, 0, 0]])


def test_clean_regions_merge_and_absorb_on_one_plane_cut_by_an_occluder():
    frame, labels, planes = two_plane_frame()
    # Plane 1 (left) is cut in two by a non-planar band; a 4-px fragment of plane 1 sits inside
    # the left plane's region but is labelled 2. Paper mode: 3 planes, fragment dropped.
    observed = labels.copy()
    observed[18:22, :30] = 0
    observed[0:2, 0:2] = 2
    params = planes.copy()
    rec = Reconstruction(frame=frame, labels=observed, planes=params)
    paper = clean_regions(rec, observed, min_area=10)
    assert paper.num_planes == 3 and not paper.labels[0:2, 0:2].any()
    out = clean_regions(rec, observed, min_area=10, merge=True, absorb=True)
    expected = labels.copy()
    expected[18:22, :30] = 0
    np.testing.assert_array_equal(out.labels, expected)
    np.testing.assert_allclose(out.planes, planes, atol=1e-5)


def _reference_moments(points, valid, labels, num):
    """The numpy formulation the compiled pass replaces (bincounts over the masked pixels)."""
    mask = valid & (labels > 0)
    lab, pts = labels[mask], points[mask]
    centre = pts.mean(axis=0)
    pts = pts - centre
    count = np.bincount(lab, minlength=num + 1)[1:num + 1]
    total = np.stack([np.bincount(lab, pts[:, k], num + 1)[1:num + 1] for k in range(3)], 1)
    outer = np.empty((num, 3, 3))
    for i in range(3):
        for j in range(3):
            outer[:, i, j] = np.bincount(lab, pts[:, i] * pts[:, j], num + 1)[1:num + 1]
    return count, total, outer, centre


@pytest.mark.parametrize("seed", range(4))
def test_region_moments_match_the_bincount_reference(seed):
    rng = np.random.default_rng(seed)
    labels = rng.integers(0, 7, size=(30, 40))
    valid = rng.random((30, 40)) > 0.2
    points = rng.normal(size=(30, 40, 3)) * 3.0 + [0.0, 0.0, 5.0]
    got = RegionMoments.of(points, valid, labels, 5)  # labels 6 are beyond num: ignored
    for a, b in zip((got.count, got.total, got.outer, got.centre),
                    _reference_moments(points, valid, labels, 5), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("size", [(1, 1), (3, 5), (480, 640)])
def test_masked_mean_equals_numpy_mean_of_the_gathered_rows(size):
    # Bit for bit: the centre of the moments must not move from numpy's.
    from monoplane.algorithm.region_moments import _masked_mean

    rng = np.random.default_rng(size[0])
    points = (rng.normal(size=(*size, 3)) * [1.0, 0.7, 2.0] + [0.0, 0.0, 3.0]).reshape(-1, 3)
    for fraction in (0.0, 0.3, 1.0):
        mask = rng.random(points.shape[0]) < fraction
        expected = points[mask].mean(axis=0) if mask.any() else np.zeros(3)
        np.testing.assert_array_equal(_masked_mean(points, mask), expected)


def _reference_gate(points, valid, before, after, params, max_distance, normals,
                    max_angle_deg, patch_px):
    """The numpy formulation of gate_filled_pixels that its compiled pass replaces."""
    import cv2

    out = after.astype(np.int32).copy()
    moved = (out > 0) & (out != before)
    plane = params[out[moved] - 1]
    dist = np.abs(np.einsum("nc,nc->n", points[moved], plane[:, :3]) + plane[:, 3])
    fits = valid[moved] & (dist <= max_distance)
    if normals is not None and max_angle_deg < 180.0:
        n = normals[moved]
        cos = np.abs(np.einsum("nc,nc->n", n, plane[:, :3]))
        known = np.einsum("nc,nc->n", n, n) > 0.5
        fits &= ~known | (cos >= np.cos(np.radians(max_angle_deg)))
    if patch_px > 0 and not fits.all():
        fail = np.zeros(out.shape, np.uint8)
        fail[moved] = ~fits
        kernel = np.ones((2 * patch_px + 1, 2 * patch_px + 1), np.uint8)
        fits = ~cv2.morphologyEx(fail, cv2.MORPH_OPEN, kernel).astype(bool)[moved]
    out[moved] = np.where(fits, out[moved], before[moved])
    return out


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize(("angle", "patch_px", "with_normals"),
                         [(180.0, 0, True), (20.0, 0, True), (20.0, 1, True), (20.0, 0, False)])
def test_gate_filled_pixels_equals_the_numpy_formulation(seed, angle, patch_px, with_normals):
    rng = np.random.default_rng(seed)
    h, w = 40, 50
    before = ndimage.zoom(rng.integers(0, 4, size=(8, 10)), 5, order=0)
    # Changes in 5x5 blocks, so that the opening keeps some failures.
    after = np.where(ndimage.zoom(rng.random((8, 10)) < 0.5, 5, order=0),
                     ndimage.zoom(rng.integers(0, 4, size=(8, 10)), 5, order=0), before)
    normal = rng.normal(size=(3, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    params = np.column_stack([normal, rng.uniform(-3.0, -1.0, 3)])
    points = pixel_rays(intrinsics_matrix(40.0, 40.0, 25.0, 20.0), h, w) * ndimage.zoom(
        rng.uniform(1.0, 3.0, (8, 10)), 5, order=0)[..., None]
    valid = rng.random((h, w)) > 0.1
    normals = rng.normal(size=(h, w, 3)).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    normals[rng.random((h, w)) < 0.1] = 0.0
    normals = normals if with_normals else None
    expected = _reference_gate(points, valid, before, after, params, 0.8, normals, angle,
                               patch_px)
    got = gate_filled_pixels(points, valid, before, after, params, 0.8, normals, angle,
                             patch_px=patch_px)
    assert got.dtype == np.int32
    np.testing.assert_array_equal(got, expected)
    assert 0 < (expected != after).sum() < (after != before).sum()


def _reference_adjacency(lab, connectivity):
    h, w = lab.shape
    offsets = [(0, 1), (1, 0)] + ([(1, 1), (1, -1)] if connectivity == 8 else [])
    pairs = set()
    for y in range(h):
        for x in range(w):
            for dy, dx in offsets:
                yy, xx = y + dy, x + dx
                if 0 <= yy < h and 0 <= xx < w:
                    a, b = lab[y, x], lab[yy, xx]
                    if a > 0 and b > 0 and a != b:
                        pairs.add((min(a, b), max(a, b)))
    return np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)


@pytest.mark.parametrize("connectivity", [4, 8])
@pytest.mark.parametrize("seed", range(3))
def test_region_adjacency_matches_a_pixel_walk(seed, connectivity):
    rng = np.random.default_rng(seed)
    lab = ndimage.zoom(rng.integers(0, 9, size=(6, 8)), 4, order=0)[:21, :29]
    np.testing.assert_array_equal(region_adjacency(lab, connectivity),
                                  _reference_adjacency(lab, connectivity))


def test_scene_radius_kernel_matches_the_numpy_formula():
    # Reference: gather the valid points, centre them, largest norm (only rounding differs).
    rng = np.random.default_rng(2)
    for _ in range(20):
        pts = rng.normal(size=(30, 40, 3)) * [1.0, 2.0, 0.5] + [0.0, 0.0, 3.0]
        valid = rng.random((30, 40)) < 0.7
        sel = pts[valid] - pts[valid].mean(axis=0)
        expected = np.sqrt((sel**2).sum(axis=1).max())
        assert scene_radius(pts, valid) == pytest.approx(expected, rel=1e-12)


def test_gate_sends_back_a_patch_whose_normals_leave_the_plane_but_not_a_thin_band() -> None:
    # Plane 1 is z = 5 (normal (0, 0, -1)); the refinement gave it every pixel of a 7 x 12
    # map. Columns 0-3 carry the plane's normal; column 4, a 1-px band, and the 3-px-wide
    # patch of columns 8-10 carry a normal 60 degrees off. The band stays (a crease's blurred
    # normals); the patch goes back to its RANSAC label 0.
    z = np.full((7, 12), 5.0)
    before = np.zeros((7, 12), np.int64)
    after = np.ones((7, 12), np.int64)
    normals = np.zeros((7, 12, 3))
    normals[..., 2] = -1.0
    off = np.array([np.sin(np.radians(60)), 0.0, -np.cos(np.radians(60))])
    normals[:, 4] = off
    normals[:, 8:11] = off
    plane = np.array([[0.0, 0.0, -1.0, 5.0]])
    out = gate_filled_pixels(flat_points(z), np.ones(z.shape, bool), before, after, plane,
                             np.inf, normals, 45.0, patch_px=1)
    expected = np.ones((7, 12), np.int32)
    expected[:, 8:11] = 0
    np.testing.assert_array_equal(out, expected)
    # Without the patch rule every failing pixel goes back; within 60 + 1 degrees none does.
    out = gate_filled_pixels(flat_points(z), np.ones(z.shape, bool), before, after, plane,
                             np.inf, normals, 45.0)
    assert (out[:, 4] == 0).all() and (out[:, 8:11] == 0).all() and out[:, :4].all()
    out = gate_filled_pixels(flat_points(z), np.ones(z.shape, bool), before, after, plane,
                             np.inf, normals, 61.0)
    assert out.all()


def test_gate_tests_a_move_between_planes_too() -> None:
    # A pixel RANSAC gave plane 1 (z = 5) that the refinement moved to plane 2 (z = 9) while its
    # point lies on plane 1 gets plane 1 back.
    z = np.array([[5.0, 9.0]])
    before = np.array([[1, 2]])
    after = np.array([[2, 2]])
    planes = np.array([[0.0, 0.0, -1.0, 5.0], [0.0, 0.0, -1.0, 9.0]])
    out = gate_filled_pixels(flat_points(z), np.ones(z.shape, bool), before, after, planes, 0.5)
    np.testing.assert_array_equal(out, [[1, 2]])


@pytest.mark.parametrize("connectivity", [4, 8])
def test_renumbered_pairs_are_the_adjacency_of_the_renumbered_labels(connectivity):
    # The clean-up renumbers the adjacency of the pieces after a merge instead of scanning
    # the renumbered image again: the same pairs, in the same order.
    rng = np.random.default_rng(connectivity)
    for _ in range(30):
        labels = np.kron(rng.integers(0, 9, (6, 7)), np.ones((3, 3), dtype=np.int64))
        remap = np.concatenate([[0], rng.integers(0, 5, 8)]).astype(np.int32)
        pairs = _renumbered_pairs(region_adjacency(labels, connectivity), remap)
        np.testing.assert_array_equal(pairs, region_adjacency(remap[labels], connectivity))
        assert pairs.dtype == np.int64


@pytest.mark.parametrize("connectivity", [4, 8, None])
@pytest.mark.parametrize("seed", range(4))
def test_scan_of_pieces_equals_the_separate_passes_bit_for_bit(seed, connectivity):
    # Blocky pieces (runs of several pixels, some at the borders) and speckle, a third of the
    # points invalid: moments, areas, radius and adjacency as the separate passes give them.
    rng = np.random.default_rng(seed)
    lab = ndimage.zoom(rng.integers(0, 9, size=(6, 8)), 4, order=0)[:21, :29]
    lab = np.where(rng.random(lab.shape) < 0.1, rng.integers(0, 9, lab.shape), lab)
    pieces = split_components(lab, connectivity or 8)[0]
    num = int(pieces.max())
    valid = rng.random(lab.shape) > 0.3
    points = rng.normal(size=(*lab.shape, 3)) * [1.0, 2.0, 0.5] + [0.0, 0.0, 4.0]
    scan = scan_pieces(points, valid, pieces, num, connectivity)
    moments = RegionMoments.of(points, valid, pieces, num)
    for a, b in zip((scan.moments.count, scan.moments.total, scan.moments.outer,
                     scan.moments.centre),
                    (moments.count, moments.total, moments.outer, moments.centre), strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(scan.area, np.bincount(pieces.ravel(), minlength=num + 1)[1:])
    assert scan.radius == scene_radius(points, valid)
    if connectivity is None:
        assert scan.touching is None
    else:
        np.testing.assert_array_equal(scan.touching, _reference_adjacency(pieces, connectivity))


def test_scan_of_pieces_rejects_labels_beyond_the_count():
    with pytest.raises(InvalidInput, match="0..2"):
        scan_pieces(np.zeros((2, 2, 3)), np.ones((2, 2), bool), np.array([[0, 1], [2, 3]]), 2)
