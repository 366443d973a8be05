"""Dense CRF: permutohedral filtering against the exact Gaussian sum, unaries, mean-field, and
label-map refinement on frames with known edges."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from scipy import ndimage

from monoplane.algorithm import lattice_kernels as lk
from monoplane.algorithm.densecrf import (
    CrfParams,
    _not_constant_3x3,
    crf_features,
    crf_grid,
    dense_crf,
)
from monoplane.algorithm.mean_field import (
    GaussianKernel,
    PermutohedralLattice,
    mean_field,
    unary_from_labels,
)
from monoplane.errors import InvalidInput
from monoplane.stages.refiners import DenseCrfRefiner
from monoplane.testing import room_cues


def params(**changes) -> CrfParams:
    """The paper's CRF: the refiner's defaults without its two deviations (uniform unary for
    non-planar pixels, working-resolution cap), run for 3 mean-field iterations (the paper
    gives no count; the refiner's speed default is 2, and these edge tests measure what the
    kernels can pull, which takes a third), with ``changes``."""
    paper = replace(DenseCrfRefiner().crf, uniform_nonplanar=False, max_pixels=0, iterations=3)
    return replace(paper, **changes)


def boundary_band(gt: np.ndarray, radius: int) -> np.ndarray:
    """Pixels within ``radius`` of a label change of ``gt``."""
    edge = ndimage.morphological_gradient(gt, size=3) > 0
    return ndimage.binary_dilation(edge, iterations=radius)


def ragged_split(height: int, width: int, jitter: int, seed: int):
    """True map: left half 1, right half 2; observed: boundary moved per row by ±jitter px."""
    rng = np.random.default_rng(seed)
    u = np.arange(width)[None, :].repeat(height, axis=0)
    gt = np.where(u < width // 2, 1, 2).astype(np.int32)
    offset = rng.integers(-jitter, jitter + 1, height)
    observed = np.where(u < width // 2 + offset[:, None], 1, 2).astype(np.int32)
    band = np.abs(u - (width // 2 - 0.5)) < jitter + 2
    return gt, observed, band


# --- permutohedral lattice -----------------------------------------------------------------

@pytest.mark.parametrize("dim, spread, min_corr, max_mean_err", [
    (1, 2.0, 0.995, 0.002),
    (2, 2.0, 0.99, 0.005),
    (3, 1.0, 0.97, 0.005),
    # Random points in 5-D are sparse for the lattice; a few isolated ones are off by ~0.2.
    (5, 1.0, 0.88, 0.01),
])
def test_lattice_matches_exact_normalised_gaussian(dim, spread, min_corr, max_mean_err):
    rng = np.random.default_rng(dim)
    f = rng.normal(size=(800, dim)) * spread
    values = rng.random((800, 1))
    lat = PermutohedralLattice(f)
    approx = lat.filter(values) / lat.filter(np.ones((800, 1)))
    sq = ((f[:, None] - f[None]) ** 2).sum(-1)

    def exact(sigma: float) -> np.ndarray:
        k = np.exp(-0.5 * sq / sigma**2)
        return k @ values / k.sum(axis=1, keepdims=True)

    err = np.abs(approx - exact(1.0)).mean()
    assert np.corrcoef(approx[:, 0], exact(1.0)[:, 0])[0, 1] > min_corr
    assert err < max_mean_err
    # The lattice's Gaussian has unit deviation: a narrower or wider exact one fits worse.
    for sigma in (0.6, 1.5):
        assert np.abs(approx - exact(sigma)).mean() > 1.5 * err


def _elevate(f: np.ndarray) -> np.ndarray:
    """Reference elevation of (N, d) features onto Σx = 0 in R^(d+1) (Adams et al., §3)."""
    n, d = f.shape
    i = np.arange(1, d + 1)
    cf = f * (np.sqrt(2.0 / 3.0) * (d + 1) / np.sqrt(i * (i + 1)))
    basis = np.zeros((d + 1, d))  # column k: (1, .., 1, -(k+1), 0, .., 0) with k+1 ones
    for k in range(d):
        basis[: k + 1, k] = 1.0
        basis[k + 1, k] = -(k + 1)
    return cf @ basis.T


def _enclose_by_division(f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Adams et al.'s enclosing simplex of one (d,) point as first written (floors of
    quotients, ranks by pairwise comparison): key0, rank, float32 weights."""
    d = f.size
    d1 = d + 1
    scale = np.sqrt(2.0 / 3.0) * d1 / np.sqrt(np.arange(1, d + 1) * np.arange(2, d + 2))
    elevated = np.empty(d1)
    tail = 0.0
    for j in range(d, 0, -1):
        cf = f[j - 1] * scale[j - 1]
        elevated[j] = tail - j * cf
        tail += cf
    elevated[0] = tail
    rem0 = np.empty(d1)
    for j in range(d1):
        down = np.floor(elevated[j] / d1) * d1
        rem0[j] = down + d1 if down + d1 - elevated[j] < elevated[j] - down else down
    total = 0.0
    for j in range(d1):
        total += rem0[j]
    s = np.int64(np.rint(total / d1))
    diff = elevated - rem0
    rank = np.array([s + sum(diff[j] > diff[k] or (j < k and diff[j] == diff[k])
                             for j in range(d1)) for k in range(d1)], np.int64)
    rem0[rank < 0] += d1
    rem0[rank > d] -= d1
    rank[rank < 0] += d1
    rank[rank > d] -= d1
    bary = np.zeros(d1 + 1)
    for k in range(d1):
        v = (elevated[k] - rem0[k]) / d1
        bary[d - rank[k]] += v
        bary[d - rank[k] + 1] -= v
    bary[0] += 1.0 + bary[d1]
    return rem0[:d].astype(np.int64), rank, bary[:d1].astype(np.float32)


@pytest.mark.parametrize("dim", [2, 3, 5])
def test_enclosing_simplices_equal_the_division_formulation_bit_for_bit(dim):
    # The kernel floors e * (1 / (d+1)) instead of e / (d+1) away from integers: the same
    # simplices and weights, also at points on lattice hyperplanes (integer and half-integer
    # features, zero) and ties between residuals.
    rng = np.random.default_rng(dim)
    f = np.concatenate([rng.normal(size=(300, dim)) * 30.0,
                        rng.integers(-20, 20, (100, dim)) * 1.0,
                        rng.integers(-20, 20, (100, dim)) * 0.5 / np.sqrt(2.0 / 3.0),
                        np.zeros((1, dim))])
    key0, rank, weights = lk.enclosing_simplices(f)
    for i in range(f.shape[0]):
        k, r, w = _enclose_by_division(f[i])
        np.testing.assert_array_equal(key0[i], k)
        np.testing.assert_array_equal(rank[i], r)
        np.testing.assert_array_equal(weights[i].view(np.int32), w.view(np.int32))


@pytest.mark.parametrize("dim", [1, 2, 3, 5, 8])
def test_lattice_kernels_against_slow_references(dim):
    """Each numba kernel against a plain numpy/Python reference on random features."""
    rng = np.random.default_rng(dim)
    f = rng.normal(size=(400, dim)) * 2.0
    d1 = dim + 1
    key0, rank, weights = lk.enclosing_simplices(f)
    # Simplex: ranks are a permutation, weights barycentric, and the weighted vertices
    # reproduce the elevated point exactly (up to float32 weights).
    np.testing.assert_array_equal(np.sort(rank, axis=1), np.tile(np.arange(d1), (400, 1)))
    assert weights.min() >= -1e-6
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-5)
    vertices = np.empty((400, d1, d1), np.int64)
    for r in range(d1):
        first = key0 + r - d1 * (rank[:, :dim] > dim - r)
        vertices[:, r] = np.column_stack([first, -first.sum(axis=1)])
        assert np.all(first % d1 == r % d1)  # vertex r has remainder r
    np.testing.assert_allclose(np.einsum("nr,nrk->nk", weights, vertices), _elevate(f),
                               atol=1e-4 * d1)
    # Hash table against a dictionary; neighbours against a brute-force lookup.
    lo = key0.min(axis=0) - 2 * d1
    radix = key0.max(axis=0) + 2 * d1 - lo + 1
    place = np.concatenate([[1], np.cumprod(radix[:-1])]).astype(np.int64)
    vertex_of, codes, table, index = lk.insert_vertices(key0 - lo, rank, place)
    ref_codes = ((vertices[:, :, :dim] - lo) @ place).astype(np.int64)
    np.testing.assert_array_equal(codes[vertex_of], ref_codes)
    assert len(set(codes.tolist())) == codes.size == np.unique(ref_codes).size
    neighbours = lk.lattice_neighbours(codes, place, table, index)
    where = {c: i for i, c in enumerate(codes.tolist())}
    for a in range(d1):
        step = -np.ones(dim, np.int64)
        if a < dim:
            step[a] += d1
        delta = int(step @ place)
        for side, shift in enumerate((delta, -delta)):
            ref = [where.get(c + shift, -1) for c in codes.tolist()]
            np.testing.assert_array_equal(neighbours[a, :, side], ref)
    # Splat, blur and slice against dense matrices.
    values = rng.random((400, 3)).astype(np.float32)
    m = codes.size
    splat = np.zeros((400, m))
    np.add.at(splat, (np.repeat(np.arange(400), d1), vertex_of.ravel()), weights.ravel())
    lattice = splat.T @ values
    for a in range(d1):
        blur = np.eye(m)
        for side in range(2):
            hit = neighbours[a, :, side] >= 0
            blur[np.flatnonzero(hit), neighbours[a, hit, side]] += 0.5
        lattice = blur @ lattice
    blurred = lk.splat_blur(vertex_of, weights, neighbours, values, m)
    np.testing.assert_allclose(blurred, lattice, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(lk.slice_values(vertex_of, weights, blurred), splat @ lattice,
                               rtol=1e-4, atol=1e-5)


def test_messages_at_other_points():
    rng = np.random.default_rng(4)
    f = rng.normal(size=(500, 3))
    kernel = GaussianKernel(f, 2.0)
    values = rng.random((500, 2)).astype(np.float32)
    blurred = kernel.blur(values)

    def message_at(points):
        out = np.zeros((len(points), 2), np.float32)
        kernel.add_message_at(blurred, points[:, :1], points[:, 1:], (1.0, 1.0),
                              (0, len(points)), out)
        return out

    # Far outside the data (outside the key range, or in cells without vertices) nothing.
    far = np.array([[100.0, 0.0, 0.0], [0.0, -1e5, 3.0]])
    np.testing.assert_array_equal(message_at(far), 0.0)
    # Between the points it follows the exact symmetric-normalised Gaussian message
    # w · D_g^-½ Σ_j k(g, f_j) D_j^-½ v_j (the lattice's overall scale cancels).
    g = rng.normal(size=(200, 3)) * 0.8
    k_gf = np.exp(-0.5 * ((g[:, None] - f[None]) ** 2).sum(-1))
    d_f = np.exp(-0.5 * ((f[:, None] - f[None]) ** 2).sum(-1)).sum(axis=1)
    exact = 2.0 * (k_gf / np.sqrt(d_f)[None]) @ values / np.sqrt(k_gf.sum(axis=1))[:, None]
    assert np.abs(message_at(g) - exact).mean() < 0.03 * np.abs(exact).mean()


def test_messages_at_own_points_are_the_message():
    rng = np.random.default_rng(5)
    f = rng.normal(size=(400, 3))
    kernel = GaussianKernel(f, 2.5)
    q = rng.random((400, 3)).astype(np.float32)
    blurred = kernel.blur(q)
    own = kernel.message_from(blurred)
    np.testing.assert_array_equal(own, kernel.message(q))
    # At its own points the kernel's message to them is the same normalised response.
    at = np.zeros((400, 3), np.float32)
    kernel.add_message_at(blurred, f[:, :2], f[:, 2:] * 4.0, (2.0, 2.0), (0, 400), at)
    np.testing.assert_allclose(at, own, rtol=1e-5, atol=1e-6)


def test_fused_messages_at_points_equal_slicing_there():
    # At the lattice's own points the fused kernel finds their simplices again, so it gives
    # the sliced, normalised message bit for bit; it adds to what is there, and does only
    # the rows asked for.
    rng = np.random.default_rng(6)
    f = rng.normal(size=(300, 4))
    kernel = GaussianKernel(f, 1.5)
    blurred = kernel.blur(rng.random((300, 5)).astype(np.float32))
    lat = kernel.lattice
    both = lk.slice_values(lat._vertex_of, lat._weights, np.hstack([blurred, kernel._ones]))
    expected = 1.5 * both[:, :-1] / np.sqrt(np.maximum(both[:, -1:], 1e-20))
    start = rng.random((300, 5)).astype(np.float32)
    out = start.copy()
    kernel.add_message_at(blurred, f[:, :1], f[:, 1:] * 8.0, (4.0, 2.0), (10, 290), out)
    np.testing.assert_array_equal(out[:10], start[:10])
    np.testing.assert_array_equal(out[10:290], start[10:290] + expected[10:290])
    np.testing.assert_array_equal(out[290:], start[290:])
    with pytest.raises(InvalidInput):
        kernel.add_message_at(blurred, f[:, :1], f[:, 1:3], (1.0, 1.0), (0, 1), out)


def test_lattice_is_nearly_symmetric_linear_and_local():
    rng = np.random.default_rng(0)
    f = rng.normal(size=(300, 3)) * 3
    lat = PermutohedralLattice(f)
    a, b = rng.random((300, 1)), rng.random((300, 1))
    # Nearly symmetric: <a, K b> ≈ <K a, b>; linear: K(2a + b) = 2 K a + K b.
    assert (a.T @ lat.filter(b)).item() == pytest.approx((lat.filter(a).T @ b).item(), rel=0.02)
    np.testing.assert_allclose(lat.filter(2 * a + b), 2 * lat.filter(a) + lat.filter(b),
                               rtol=1e-4, atol=1e-5)
    # Two clusters 100 deviations apart do not exchange anything.
    g = np.concatenate([np.zeros((50, 2)), np.full((50, 2), 100.0)])
    g += rng.normal(size=g.shape) * 0.3
    v = np.concatenate([np.ones((50, 1)), np.zeros((50, 1))])
    out = PermutohedralLattice(g).filter(v)
    assert np.all(out[50:] == 0) and np.all(out[:50] > 0)


def test_lattice_rejects_bad_features():
    with pytest.raises(InvalidInput):
        PermutohedralLattice(np.array([[0.0, np.nan]]))
    with pytest.raises(InvalidInput):
        PermutohedralLattice(np.zeros((4, 0)))
    with pytest.raises(InvalidInput):
        PermutohedralLattice(np.zeros((4, 9)))
    with pytest.raises(InvalidInput, match="too small"):
        PermutohedralLattice(np.array([[0.0] * 6, [1e12] * 6]))


# --- unary and mean field ------------------------------------------------------------------

def test_unary_from_labels_closed_form():
    u = unary_from_labels(np.array([0, 2, 1]), 4, 0.7)
    assert u.shape == (3, 4) and u.dtype == np.float32
    np.testing.assert_allclose(u[0], -np.log([0.7, 0.1, 0.1, 0.1]), rtol=1e-6)
    np.testing.assert_allclose(u[1], -np.log([0.1, 0.1, 0.7, 0.1]), rtol=1e-6)
    np.testing.assert_allclose(np.exp(-u).sum(axis=1), 1.0, rtol=1e-6)
    with pytest.raises(InvalidInput):
        unary_from_labels(np.array([0]), 4, 0.25)  # not above 1/L
    with pytest.raises(InvalidInput):
        unary_from_labels(np.array([0]), 1, 0.9)


def test_unary_uniform_label_carries_no_evidence():
    u = unary_from_labels(np.array([0, 2, 1]), 4, 0.7, uniform_label=0)
    np.testing.assert_allclose(u[0], np.log(4.0), rtol=1e-6)
    np.testing.assert_allclose(u[1], -np.log([0.1, 0.1, 0.7, 0.1]), rtol=1e-6)


def test_uniform_nonplanar_fills_a_hole_from_its_surroundings():
    # A 6x6 hole of label 0 inside plane 1, on one flat grey plane: with the paper's unary the
    # hole's own evidence keeps most of it 0; with a uniform unary plane 1 fills it.
    labels = np.ones((32, 32), dtype=np.int32)
    labels[:, 16:] = 2
    labels[8:14, 4:10] = 0
    depth = np.full((32, 32), 2.0, dtype=np.float32)
    paper = dense_crf(labels, 3, params(), depth=depth)
    filled = dense_crf(labels, 3, params(uniform_nonplanar=True), depth=depth)
    assert (paper[8:14, 4:10] == 0).mean() > 0.5
    np.testing.assert_array_equal(filled, np.where(labels == 0, 1, labels))


def test_mean_field_without_kernels_is_the_unary_softmax():
    labels = np.array([0, 1, 2, 1])
    q = mean_field(unary_from_labels(labels, 3, 0.6), [], iterations=5)
    np.testing.assert_allclose(q[np.arange(4), labels], 0.6, rtol=1e-6)
    np.testing.assert_array_equal(q.argmax(axis=1), labels)


def test_crf_params_validation():
    with pytest.raises(InvalidInput):
        params(theta_depth=0.0)
    with pytest.raises(InvalidInput):
        params(w_normal=-1.0)
    with pytest.raises(InvalidInput):
        params(iterations=-1)
    with pytest.raises(InvalidInput):
        GaussianKernel(np.zeros((3, 2)), 0.0)


# --- kernels -------------------------------------------------------------------------------

def test_kernels_follow_weights_and_available_cues():
    rgb, depth, normals, _, _ = room_cues(24, 32)
    p = params()
    dims = [k.lattice.dim for k in crf_features((24, 32), p, rgb, depth, normals)]
    assert dims == [2, 5, 3, 5]  # smoothness, appearance, depth, normal
    grey = np.repeat(rgb[..., :1], 3, axis=2)
    assert [k.lattice.dim for k in crf_features((24, 32), p, grey, depth, normals)] == [2, 3, 5]
    assert [k.lattice.dim for k in crf_features((24, 32), p, None, depth, None)] == [2, 3]
    off = params(w_smoothness=0.0, w_depth=0.0, w_normal=0.0)
    kernels = crf_features((24, 32), off, rgb, depth, normals)
    assert [k.lattice.dim for k in kernels] == [5] and kernels[0].weight == 1.0


def test_feature_scaling_matches_documented_units():
    # Position θ scales with image size: at 512x384 (4x the reference area) it is 20 px, so the
    # lattice of a 2x larger image has about as many vertices as the reference one.
    p = params()
    small = crf_features((192, 256), p)[0].lattice.num_vertices
    large = crf_features((384, 512), p)[0].lattice.num_vertices
    assert abs(large - small) <= 0.1 * small
    # Depth is normalised by its maximum: scaling the depth map changes nothing.
    rgb, depth, normals, gt, _ = room_cues(48, 64)
    rng = np.random.default_rng(0)
    noisy = np.where(rng.random(gt.shape) < 0.2, rng.integers(0, 6, gt.shape), gt)
    a = dense_crf(noisy, 6, p, rgb, depth, normals)
    b = dense_crf(noisy, 6, p, rgb, depth * 1000.0, normals)
    np.testing.assert_array_equal(a, b)


def test_working_resolution_cap():
    rgb, depth, normals, gt, _ = room_cues(96, 128)
    rng = np.random.default_rng(2)
    noisy = np.where(rng.random(gt.shape) < 0.2, rng.integers(0, 6, gt.shape), gt)
    full = dense_crf(noisy, 6, params(), rgb, depth, normals)
    # A cap at or above the pixel count changes nothing.
    same = dense_crf(noisy, 6, params(max_pixels=96 * 128), rgb, depth, normals)
    np.testing.assert_array_equal(same, full)
    # A cap of 3100 px: 2 x 2 blocks, a 48 x 64 = 3072 grid.
    coarse = dense_crf(noisy, 6, params(max_pixels=3100), rgb, depth, normals)
    assert (noisy == gt).mean() < 0.85
    assert (coarse == gt).mean() > 0.99       # measured 0.993; full resolution 0.998
    assert (coarse == full).mean() > 0.99
    with pytest.raises(InvalidInput):
        params(max_pixels=-1)


def test_band_margin_limits_exact_messages_to_close_calls():
    rgb, depth, normals, gt, _ = room_cues(96, 128)
    rng = np.random.default_rng(3)
    noisy = np.where(rng.random(gt.shape) < 0.2, rng.integers(0, 6, gt.shape), gt)
    whole = dense_crf(noisy, 6, params(max_pixels=3100), rgb, depth, normals)
    # A margin wider than any gap between two labels' energies sends the whole band.
    wide = dense_crf(noisy, 6, params(max_pixels=3100, band_margin=1e30), rgb, depth, normals)
    np.testing.assert_array_equal(wide, whole)
    # Without any exact message (a margin no gap is below) edges follow the 2 x 2 blocks;
    # a margin of 2 nats gives the whole band's labels back but for a handful of pixels.
    none = dense_crf(noisy, 6, params(max_pixels=3100, band_margin=1e-30), rgb, depth, normals)
    two = dense_crf(noisy, 6, params(max_pixels=3100, band_margin=2.0), rgb, depth, normals)
    assert (none != whole).sum() > 5 * max((two != whole).sum(), 1)
    assert (two == gt).mean() >= (whole == gt).mean() - 0.001
    with pytest.raises(InvalidInput, match="band_margin"):
        params(band_margin=0.0)


@pytest.mark.parametrize("max_pixels", [0, 3100])
def test_a_grid_built_beforehand_gives_the_same_labels(max_pixels):
    # The label-independent part (block grid, cues, lattices) may be built before the labels
    # exist, on this thread alone or on parallel ones: the result is the same to the bit.
    rgb, depth, normals, gt, _ = room_cues(96, 128)
    rng = np.random.default_rng(4)
    noisy = np.where(rng.random(gt.shape) < 0.2, rng.integers(0, 6, gt.shape), gt)
    p = params(max_pixels=max_pixels)
    direct = dense_crf(noisy, 6, p, rgb, depth, normals)
    for threaded in (True, False):
        grid = crf_grid(gt.shape, p, rgb, depth, normals, threaded=threaded)
        assert grid.step == (1 if max_pixels == 0 else 2)
        np.testing.assert_array_equal(
            dense_crf(noisy, 6, p, rgb, depth, normals, grid=grid), direct)
    with pytest.raises(InvalidInput, match="grid is for"):
        dense_crf(noisy[:-1], 6, p, rgb[:-1], depth[:-1], normals[:-1], grid=grid)


# --- refinement on label maps with known answers --------------------------------------------

def test_crf_removes_speckle_and_keeps_edges():
    rgb, depth, normals, gt, _ = room_cues()
    rng = np.random.default_rng(1)
    speckle = rng.random(gt.shape) < 0.2
    noisy = np.where(speckle, rng.integers(0, 6, gt.shape), gt).astype(np.int32)
    out = dense_crf(noisy, 6, params(), rgb, depth, normals)
    band = boundary_band(gt, 3)
    assert (noisy == gt).mean() < 0.85
    assert (out == gt).mean() > 0.995
    # Edges stay where the colour/depth/normal discontinuities are.
    assert (out == gt)[band].mean() > 0.98


def test_crf_moves_ragged_boundaries_onto_the_room_edges():
    rgb, depth, normals, gt, _ = room_cues()
    rng = np.random.default_rng(3)
    ragged = np.stack([np.roll(row, rng.integers(-3, 4)) for row in gt])
    band = boundary_band(gt, 4)
    before = (ragged == gt)[band].mean()
    out = dense_crf(ragged, 6, params(), rgb, depth, normals)
    assert (out == gt)[band].mean() > before + 0.025  # measured 0.917 -> 0.951


def test_appearance_kernel_snaps_to_a_colour_edge():
    h, w = 96, 128
    gt, observed, band = ragged_split(h, w, jitter=3, seed=0)
    rng = np.random.default_rng(0)
    colours = np.where((gt == 1)[..., None], [180, 60, 60], [60, 60, 180])
    rgb = np.clip(colours + rng.normal(0, 5, (h, w, 3)), 0, 255).astype(np.uint8)
    depth = np.full((h, w), 2.0, np.float32)
    normals = np.zeros((h, w, 3), np.float32)
    normals[..., 2] = -1.0
    before = (observed == gt)[band].mean()
    with_colour = dense_crf(observed, 3, params(), rgb, depth, normals)
    without = dense_crf(observed, 3, params(w_appearance=0.0), rgb, depth, normals)
    assert (with_colour == gt)[band].mean() > before + 0.05  # measured 0.84 -> 0.93
    assert (without == gt)[band].mean() < before + 0.02


def test_depth_kernel_snaps_to_a_depth_step_on_a_grey_frame():
    h, w = 96, 128
    gt, observed, band = ragged_split(h, w, jitter=3, seed=0)
    depth = np.where(gt == 1, 2.0, 3.0).astype(np.float32)
    normals = np.zeros((h, w, 3), np.float32)
    normals[..., 2] = -1.0
    grey = np.full((h, w, 3), 128, np.uint8)
    before = (observed == gt)[band].mean()
    # Five mean-field iterations (the refiner's default is 2): on a grey frame only the depth kernel
    # pulls the 3 px ragged edge, and it needs the extra iterations to pull all of it.
    with_depth = dense_crf(observed, 3, params(iterations=5), grey, depth, normals)
    without = dense_crf(observed, 3, params(iterations=5, w_depth=0.0), grey, depth, normals)
    assert (with_depth == gt)[band].mean() > before + 0.04  # measured 0.84 -> 0.90
    assert (without == gt)[band].mean() < before + 0.02


def test_dense_crf_trivial_cases():
    labels = np.zeros((8, 8), np.int32)
    np.testing.assert_array_equal(dense_crf(labels, 1, params()), labels)
    labels[2:5, 2:5] = 1
    np.testing.assert_array_equal(dense_crf(labels, 2, params(iterations=0)), labels)
    with pytest.raises(InvalidInput):
        dense_crf(labels, 1, params())


@pytest.mark.parametrize("uniform", [True, False])
@pytest.mark.parametrize("num_labels", [2, 11])
@pytest.mark.parametrize("step, shape", [(3, (192, 256)), (8, (480, 640)), (2, (37, 53))])
def test_block_means_from_counts_equal_the_per_pixel_sums(uniform, num_labels, step, shape):
    from monoplane.algorithm.densecrf import _block_mean_probabilities

    h, w = shape
    lab = np.random.default_rng(num_labels).integers(0, num_labels, size=shape)
    p = replace(DenseCrfRefiner().crf, uniform_nonplanar=uniform)
    unary = unary_from_labels(lab, num_labels, p.confidence, uniform_label=0 if uniform else None)
    hs, ws = -(-h // step), -(-w // step)
    block = (np.minimum(np.arange(h) // step, hs - 1)[:, None] * ws
             + np.minimum(np.arange(w) // step, ws - 1)[None, :]).ravel()
    prob = np.exp(-unary)  # the per-pixel formulation it replaces
    ref = np.stack([np.bincount(block, prob[:, k], hs * ws) for k in range(num_labels)], 1)
    ref /= np.bincount(block, minlength=hs * ws)[:, None]
    got = _block_mean_probabilities(lab.astype(np.int32), step, num_labels, p)
    np.testing.assert_array_equal(got, ref)


@pytest.mark.parametrize("step, shape", [(3, (192, 256)), (8, (480, 640)), (5, (37, 53))])
def test_band_pixels_are_the_pixels_of_the_flagged_blocks(step, shape):
    from monoplane.algorithm.densecrf import _band_pixels

    h, w = shape
    hs, ws = -(-h // step), -(-w // step)
    edge = np.random.default_rng(step).random((hs, ws)) < 0.3
    edge[-1, -1] = True  # a block cut by both image borders
    block = (np.arange(h) // step)[:, None] * ws + (np.arange(w) // step)[None, :]
    np.testing.assert_array_equal(_band_pixels(edge, step, h, w),
                                  np.flatnonzero(edge.ravel()[block.ravel()]))


def _no_taps() -> tuple[np.ndarray, ...]:
    """Interpolation taps for upsampled_labels when it reads an upsampled array instead."""
    return (np.zeros((1, 2), np.int64), np.zeros((1, 2), np.float32),
            np.zeros((1, 2), np.int64), np.zeros((1, 2), np.float32))


@pytest.mark.parametrize("uniform", [True, False])
def test_final_labels_kernels_equal_the_numpy_argmax(uniform):
    from monoplane.algorithm.crf_labels import exact_labels, upsampled_labels

    rng = np.random.default_rng(11)
    h, w, num = 23, 31, 6
    lab = rng.integers(0, num, size=(h, w))
    fine = rng.normal(size=(h + 2, w + 3, num)).astype(np.float32)  # resize may overhang
    fine[0, 0, 1:3] = fine[0, 0].max() + 1.0  # a tie: the first maximum wins, margin 0
    band = np.sort(rng.choice(h * w, 200, replace=False))
    band[0] = 0
    exact = rng.normal(size=(200, num)).astype(np.float32)
    unary = unary_from_labels(lab, num, 0.55, uniform_label=0 if uniform else None)
    upsampled = fine[:h, :w].reshape(-1, num) - unary
    top2 = np.sort(upsampled[band], axis=1)[:, -2:]
    values = unary_from_labels(np.array([1, 0]), num, 0.55, uniform_label=0)
    args = (values[0, 1], values[0, 0], values[1, 0], uniform)
    for margin in (0.5, np.inf):
        expected_close = top2[:, 1] - top2[:, 0] < margin
        energy = upsampled.copy()
        energy[band[expected_close]] = exact[expected_close] - unary[band[expected_close]]
        expected = energy.argmax(axis=1).reshape(h, w)
        # Whole, and in row pieces (threads) that each find their part of the band.
        for bounds in ([0, h], [0, 1, 9, 10, h]):
            got = np.full((h, w), -1, dtype=np.int32)
            close = np.zeros(200, bool)
            for y0, y1 in zip(bounds[:-1], bounds[1:], strict=True):
                # No certified cells: every pixel reads its messages (from fine; one coarse
                # cell, whose taps are not read).
                upsampled_labels(np.zeros((1, 1, num), np.float32), *_no_taps(), fine,
                                 lab.astype(np.int32), band, *args, margin, np.full(1, -1),
                                 np.zeros(1), h + w, 0.0, 0.0, y0, y1, got, close)
            np.testing.assert_array_equal(close, expected_close)
            assert close[0]
            exact_labels(exact[close], lab.astype(np.int32), band[close], *args, got)
            np.testing.assert_array_equal(got, expected)


def test_label_change_band_matches_max_and_min_filters():
    # Reference: a 3 x 3 window is not constant where its maximum and minimum differ.
    rng = np.random.default_rng(3)
    for _ in range(50):
        h, w = rng.integers(1, 30, 2)
        coarse = np.kron(rng.integers(0, 3, (h, w)), np.ones((3, 2), dtype=np.int64))
        expected = ndimage.maximum_filter(coarse, 3) != ndimage.minimum_filter(coarse, 3)
        np.testing.assert_array_equal(_not_constant_3x3(coarse), expected)


def test_sum_in_place_equals_the_sum_from_zeros_bit_for_bit() -> None:
    from monoplane.algorithm.densecrf import _sum_in_place

    rng = np.random.default_rng(3)
    for count in (1, 2, 3):
        arrays = [rng.normal(size=(50, 7)).astype(np.float32) for _ in range(count)]
        for a in arrays:
            a[rng.random(a.shape) < 0.2] = -0.0
        expected = sum((a.copy() for a in arrays), np.zeros((50, 7), np.float32))
        got = _sum_in_place([a.copy() for a in arrays])
        assert got.dtype == np.float32
        np.testing.assert_array_equal(got, expected)
        np.testing.assert_array_equal(np.signbit(got), np.signbit(expected))
        assert np.signbit(expected).sum() < np.signbit(arrays[0]).sum()  # -0 did occur


@pytest.mark.parametrize("uniform", [True, False])
@pytest.mark.parametrize("step, shape", [(8, (45, 70)), (3, (31, 40))])
def test_certified_cells_give_the_labels_the_upsampled_argmax_gives(uniform, step, shape):
    # Coarse messages with plateaus (one label ahead by 0.5-6 nats) and a few cells where two
    # labels are close; observed labels mostly the plateau's, some another or 0.
    from monoplane.algorithm.crf_labels import certified_cells, upsampled_labels

    rng = np.random.default_rng(step)
    h, w = shape
    hs, ws, num = -(-h // step), -(-w // step), 5
    ahead = np.kron(rng.integers(0, num, (hs // 4 + 1, ws // 4 + 1)), np.ones((4, 4), int))
    coarse = rng.normal(0.0, 0.2, (hs, ws, num)).astype(np.float32)
    lead = rng.uniform(0.5, 6.0, (hs, ws)).astype(np.float32)
    lead[rng.random((hs, ws)) < 0.1] = 0.01
    np.put_along_axis(coarse, ahead[:hs, :ws, None], lead[..., None] + 1.0, axis=2)
    fine = cv2.resize(coarse, (ws * step, hs * step), interpolation=cv2.INTER_LINEAR)
    block = ahead[:hs, :ws].repeat(step, 0).repeat(step, 1)[:h, :w]
    lab = np.where(rng.random((h, w)) < 0.2, rng.integers(0, num, (h, w)), block)
    band = np.sort(rng.choice(h * w, 40, replace=False))
    values = unary_from_labels(np.array([1, 0]), num, 0.55, uniform_label=0)
    args = (values[0, 1], values[0, 0], values[1, 0], uniform, 2.0)
    cell_label, cell_gap, slack = certified_cells(coarse)
    hard = float(values[0, 0]) - float(values[0, 1]) + slack
    assert (cell_label >= 0).mean() > 0.3
    got, expected = (np.full((h, w), -1, np.int32) for _ in range(2))
    close, expected_close = np.zeros(40, bool), np.zeros(40, bool)
    upsampled_labels(coarse, *_no_taps(), fine, lab.astype(np.int32), band, *args, cell_label,
                     cell_gap, step, slack, hard, 0, h, got, close)
    upsampled_labels(coarse, *_no_taps(), fine, lab.astype(np.int32), band, *args,
                     np.full(hs * ws, -1), cell_gap, step, slack, hard, 0, h, expected,
                     expected_close)
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(close, expected_close)


@pytest.mark.parametrize("num", [2, 3, 21])
def test_best_two_equal_argmax_partition_and_abs_max(num):
    # One compiled pass against the numpy formulation it replaced, with ties for the first
    # and the second place, -0 and a row of equal values.
    from monoplane.algorithm.crf_labels import _best_two

    rng = np.random.default_rng(num)
    values = rng.integers(-3, 4, (300, num)).astype(np.float32) * np.float32(0.7)
    values[:100] += rng.normal(size=(100, num)).astype(np.float32)
    values[5] = 1.5
    values[6, 0] = -0.0
    flat = values.astype(np.float64)
    top2 = np.partition(flat, num - 2, axis=1)[:, -2:]
    best, lead, largest = _best_two(values)
    np.testing.assert_array_equal(best, flat.argmax(axis=1))
    np.testing.assert_array_equal(lead, top2[:, 1] - top2[:, 0])
    assert largest == float(np.abs(flat).max())
    assert (lead == 0).sum() > 10


@pytest.mark.parametrize("num", [2, 5, 21])
@pytest.mark.parametrize("step, shape", [(8, (45, 70)), (3, (31, 40)), (5, (20, 24))])
def test_interpolated_messages_are_cv2_resize_bit_for_bit(num, step, shape):
    # The labelling interpolates the coarse messages where it needs them instead of reading
    # cv2.resize's upsampling (for these label counts): the same float32 values, hence the
    # same labels and close calls. Coarse messages of three magnitudes, a zero and a -0.
    from monoplane.algorithm.crf_labels import _interpolate, bilinear_taps, upsampled_labels

    rng = np.random.default_rng(num * step)
    h, w = shape
    hs, ws = -(-h // step), -(-w // step)
    coarse = (rng.normal(size=(hs, ws, num)) * rng.choice([1e-3, 1.0, 30.0], (hs, ws, num))
              ).astype(np.float32)
    coarse[0, 0, 0], coarse[-1, -1, -1] = 0.0, -0.0
    fine = cv2.resize(coarse, (ws * step, hs * step), interpolation=cv2.INTER_LINEAR
                      ).reshape(hs * step, ws * step, num)
    rows, row_w = bilinear_taps(h, hs, step, clamp_weights=False)
    cols, col_w = bilinear_taps(w, ws, step, clamp_weights=True)
    message = np.empty(num, np.float32)
    for y in range(h):
        for x in range(w):
            _interpolate(coarse, rows, row_w, cols, col_w, y, x, message)
            np.testing.assert_array_equal(message.view(np.int32), fine[y, x].view(np.int32))
    lab = rng.integers(0, num, (h, w)).astype(np.int32)
    band = np.sort(rng.choice(h * w, h * w // 3, replace=False))
    values = unary_from_labels(np.array([1, 0]), num, 0.55, uniform_label=0)
    args = (values[0, 1], values[0, 0], values[1, 0], True, 0.05, np.full(hs * ws, -1),
            np.zeros(hs * ws), step, 0.0, 0.0, 0, h)
    got, expected = (np.full((h, w), -1, np.int32) for _ in range(2))
    close, expected_close = np.zeros(band.size, bool), np.zeros(band.size, bool)
    upsampled_labels(coarse, rows, row_w, cols, col_w, np.zeros((0, 0, num), np.float32), lab,
                     band, *args, got, close)
    upsampled_labels(coarse, *_no_taps(), fine, lab, band, *args, expected, expected_close)
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(close, expected_close)


def test_softmax_equals_the_numpy_formula_bit_for_bit() -> None:
    from monoplane.algorithm.mean_field import _softmax

    rng = np.random.default_rng(5)
    for shape in ((1, 1), (7, 2), (300, 16), (50, 41)):
        x = (rng.normal(size=shape) * 5).astype(np.float32)
        x[0, -1] = x[0, 0]  # a tie for the maximum
        e = np.exp(x - x.max(axis=1, keepdims=True))
        expected = e / e.sum(axis=1, keepdims=True)
        got = _softmax(x.copy())
        assert got.dtype == np.float32
        np.testing.assert_array_equal(got, expected)
