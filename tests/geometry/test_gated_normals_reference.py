"""The gated normals from depth are the same bits as a plain reference of the method.

The reference below is the method as it was written before its kernels were reorganised for
speed (OpenCV morphology for the one-surface test, per-pixel loops for the fits), in plain
Python with the kernels' float types spelled out: float32 inverse depth, ratios and slopes,
float64 sums. The compiled code may change how it runs, but not one bit of what it returns.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from monoplane.datamodel import default_intrinsics
from monoplane.geometry.normals import _discontinuities, normals_from_depth
from monoplane.geometry.one_surface_windows import _one_surface

MAX_JUMP = 0.05


def random_depth(seed: int, h: int = 40, w: int = 56) -> np.ndarray:
    """Tilted planes in random boxes (depth jumps, creases), sensor noise, holes as 0, NaN
    and inf, and a larger hole: interior, band and rim pixels and windows with holes."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    z = np.full((h, w), 2.0)
    for _ in range(5):
        y0, x0 = rng.integers(0, h - 6), rng.integers(0, w - 6)
        y1, x1 = y0 + rng.integers(6, h), x0 + rng.integers(6, w)
        gu, gv = rng.normal(0, 5e-3, 2)
        inv = rng.uniform(0.2, 1.0) + gu * (u - x0) + gv * (v - y0)
        box = (v >= y0) & (v < y1) & (u >= x0) & (u < x1) & (inv > 0.05)
        z[box] = 1.0 / inv[box]
    z *= 1 + rng.normal(0, 0.003, z.shape)
    for value, share in ((0.0, 0.04), (np.nan, 0.01), (np.inf, 0.01)):
        z[rng.random(z.shape) < share] = value
    z[5:9, 10:20] = 0
    return z.astype(np.float32)


def reference_masks(z: np.ndarray, labels: np.ndarray, rim: np.ndarray,
                    r: int) -> np.ndarray:
    """(H, W) bool: valid pixels whose (2r+1)² window holds no rim, one component and a
    depth range within 1 + MAX_JUMP r (OpenCV morphology, the image border ignored)."""
    win = np.ones((2 * r + 1, 2 * r + 1), np.uint8)
    big = np.float32(np.inf)
    lab_f = labels.astype(np.float32)
    valid = z > 0
    return (valid & (cv2.dilate(rim.view(np.uint8), win) == 0)
            & (cv2.dilate(lab_f, win) == cv2.erode(np.where(labels > 0, lab_f, big), win))
            & (cv2.dilate(z, win) / (1.0 + MAX_JUMP * r)
               <= cv2.erode(np.where(valid, z, big), win)))


def line_fit(sums: tuple, support: int, stride: int) -> tuple | None:
    """Cramer's rule on the normal equations of y ≈ a du + b dv + c, or None if ill posed."""
    cnt, su, sv, suu, suv, svv, ru, rv, r1 = sums
    c00, c01, c02 = svv * cnt - sv * sv, su * sv - suv * cnt, suv * sv - svv * su
    c11, c12, c22 = suu * cnt - su * su, suv * su - suu * sv, suu * svv - suv * suv
    det = suu * c00 + suv * c01 + su * c02
    n = max(cnt, 1.0)
    if not (cnt >= support and det > 1e-2 * (stride * stride) ** 2 * (n * n * n)):
        return None
    inv_det = 1.0 / det
    return ((c00 * ru + c01 * rv + c02 * r1) * inv_det, (c01 * ru + c11 * rv + c12 * r1) * inv_det,
            (c02 * ru + c12 * rv + c22 * r1) * inv_det)


def store(out: np.ndarray, v: int, u: int, fit: tuple, value: float, K: np.ndarray) -> None:
    """The normal -K^T g of the inverse-depth line g at (v, u), if it faces the camera."""
    a, b = fit[0], fit[1]
    if not value > 0:
        return
    g2 = value - a * u - b * v
    n = [-(a * K[0, i] + b * K[1, i] + g2 * K[2, i]) for i in range(3)]
    norm = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
    if norm > 0:
        out[v, u] = [x / norm for x in n]


def slope(inv: np.ndarray, labels: np.ndarray, v: int, u: int) -> np.float32:
    """Relative float32 step to the same component's neighbours (the larger axis of the
    smaller side)."""
    h, w = inv.shape
    best = np.float32(0)
    for dv, du in ((0, 1), (1, 0)):
        steps = [abs(inv[y, x] - inv[v, u]) for y, x in ((v - dv, u - du), (v + dv, u + du))
                 if 0 <= y < h and 0 <= x < w and labels[v, u] > 0
                 and labels[y, x] == labels[v, u]]
        if steps:
            best = max(best, min(steps))
    return np.float32(best / inv[v, u])


def window_sums(inv, labels, rim, v, u, r, stride, gated, tol):
    """Sums of the accepted samples in row-major order; ungated: every valid sample."""
    h, w = inv.shape
    c = inv[v, u]
    s = [0.0] * 9
    for dv in range(-r, r + 1, stride):
        for du in range(-r, r + 1, stride):
            y, x = v + dv, u + du
            if not (0 <= y < h and 0 <= x < w):
                continue
            q = inv[y, x]
            e = float(np.float32(q / c)) - 1.0
            if not gated or rim[v, u]:
                if not (q > 0 and (not gated or abs(e) <= MAX_JUMP)):
                    continue
            elif labels[y, x] != labels[v, u] or not abs(e) <= tol * max(abs(du), abs(dv), 1):
                continue
            fu, fv = float(du), float(dv)
            for k, x_ in enumerate((1.0, fu, fv, fu * fu, fu * fv, fv * fv, e * fu, e * fv, e)):
                s[k] += x_
    return s


def reference_gated(depth: np.ndarray, K: np.ndarray, radius: int, stride: int,
                    support: int = 4) -> np.ndarray:
    z = np.where(np.isfinite(depth), depth, 0).astype(np.float32)
    inv, rim = _discontinuities(z, MAX_JUMP)
    valid = z > 0
    labels = cv2.connectedComponents((valid & ~rim).view(np.uint8), connectivity=4,
                                     ltype=cv2.CV_32S)[1]
    r = radius - radius % stride
    interior = reference_masks(z, labels, rim, r)
    one = np.zeros(2 * r + 1, np.float32)
    one[np.arange(-r, r + 1, stride) + r] = 1
    ramp = one * np.arange(-r, r + 1, dtype=np.float32)
    sums = [cv2.sepFilter2D(img, cv2.CV_32F, kx, ky, borderType=cv2.BORDER_CONSTANT)
            for img, kx, ky in ((valid.astype(np.float32), one, one), (inv, ramp, one),
                                (inv, one, ramp), (inv, one, one))]
    out = np.zeros(z.shape + (3,), np.float32)
    for v, u in zip(*np.nonzero(valid), strict=True):
        if interior[v, u]:
            # absolute inverse depth: the window's own sums of offsets, the filters' moments
            offsets = window_sums(inv, labels, rim, v, u, r, stride, False, 0.0)[:6]
            fit = line_fit((*offsets, *(float(s[v, u]) for s in sums[1:])), support, stride)
            if fit is not None:
                store(out, v, u, fit, fit[2], K)
        else:  # relative inverse depth, gated
            tol = MAX_JUMP + float(slope(inv, labels, v, u))
            fit = line_fit(window_sums(inv, labels, rim, v, u, r, stride, True, tol),
                           support, stride)
            if fit is not None:
                store(out, v, u, fit, 1.0 + fit[2], K)
    return out


@pytest.mark.parametrize("seed,radius,stride", [(0, 6, 2), (1, 3, 1), (2, 4, 2), (3, 2, 2)])
def test_gated_normals_are_the_reference_bits(seed: int, radius: int, stride: int) -> None:
    depth = random_depth(seed)
    K = default_intrinsics(depth.shape[1], depth.shape[0])
    ref = reference_gated(depth, K, radius, stride)
    got = normals_from_depth(depth, K, radius=radius, stride=stride, max_jump=MAX_JUMP)
    np.testing.assert_array_equal(got, ref)
    # every kind of pixel was there: fitted ones, and zero normals (holes, ill-posed fits)
    assert 0.5 < (np.abs(ref).sum(-1) > 0).mean() < 0.99


@pytest.mark.parametrize("r", [1, 3, 6])
@pytest.mark.parametrize("pieces", [[(0, 40)], [(0, 7), (7, 33), (33, 40)]])
def test_one_surface_masks_match_morphology(r: int, pieces: list) -> None:
    z = random_depth(7)
    z = np.where(np.isfinite(z), z, 0).astype(np.float32)
    z[30:, 40:] *= -1  # negative depth is invalid too
    _, rim = _discontinuities(z, MAX_JUMP)
    labels = cv2.connectedComponents(((z > 0) & ~rim).view(np.uint8), connectivity=4,
                                     ltype=cv2.CV_32S)[1]
    interior = np.zeros(z.shape, bool)
    band = np.zeros(z.shape, bool)
    for a, b in pieces:
        _one_surface(z, labels, rim, r, MAX_JUMP, a, b, interior, band)
    expected = reference_masks(z, labels, rim, r)
    np.testing.assert_array_equal(interior, expected)
    np.testing.assert_array_equal(band, (z > 0) & ~expected)
    assert expected.any() and band.any()
