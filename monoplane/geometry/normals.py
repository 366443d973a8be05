"""Surface normals from a depth map: edge-aware local plane fits in inverse depth.

Why inverse depth: a plane ``n · X + d = 0`` seen through a pinhole has inverse depth
``w = 1/z`` that is exactly *linear* in pixel coordinates, ``w(u, v) = g · [u, v, 1]`` with
``g = -K^-T n / d``. A least-squares line fit of ``w`` over a pixel window is therefore exact on
planes (no bias from perspective), and the normal is recovered in closed form as
``n ∝ -K^T g``.

Why edge-aware: RANSAC's normal-consistency sampler (ε_n = 10°) and the proximity graph cut
compare normals across a surface, so a normal smeared over an occluding edge creates false
hypotheses. Each pixel's fit only uses neighbours on its own side of every depth discontinuity:

1. a discontinuity is a 4-neighbour pair whose inverse-depth step differs from both adjacent
   steps on its row or column by more than ``max_jump`` (relative); on a plane the steps are
   equal however steep it is. The farther pixel of the pair is a *rim* pixel;
2. valid, non-rim pixels are split into 4-connected components, which the rims separate;
3. a non-rim pixel fits only neighbours of its own component whose relative inverse-depth
   difference stays within ``max_jump`` plus its own local step per pixel of offset (this also
   catches edges that do not close a component); a rim pixel fits only neighbours within
   ``max_jump`` of its own depth, which excludes the nearer (occluding) side.

Windows that provably see one surface (no rim, one component, small depth range) are fitted
for the whole image at once with separable filters of the masked moments; only the band near
depth edges goes through the per-neighbour gating above. At 640x480 with the defaults this
takes about 0.1 s of CPU time.

Holes (depth 0, NaN or inf) contribute nothing and get a zero normal. Pixels without enough
well-spread support (fewer than ``min_support`` accepted neighbours, or all on a line) get a
zero normal too, which downstream code treats as invalid.
"""

from __future__ import annotations

import cv2
import numpy as np

from monoplane.errors import InvalidInput
from monoplane.geometry.components import label_regions


def _rim_and_components(depth: np.ndarray, valid: np.ndarray,
                        max_jump: float) -> tuple[np.ndarray, np.ndarray]:
    """Rim mask (far side of each discontinuity) and component labels of the other pixels.

    Along a row or column, the inverse depth of a plane changes by the same step from pixel
    to pixel, however steep the plane (a floor near the horizon). So a discontinuity is a
    step that differs from *both* neighbouring steps by more than ``max_jump`` relative to the
    inverse depth; a step whose neighbours are missing (holes, image border) is compared with
    zero instead.

    Returns
    -------
    rim : numpy.ndarray
        (H, W) bool.
    labels : numpy.ndarray
        (H, W) int32, 0 on invalid and rim pixels.
    """
    inv = np.zeros(depth.shape, dtype=np.float32)
    inv[valid] = 1.0 / depth[valid]
    rim = np.zeros(depth.shape, dtype=bool)
    for axis in (1, 0):
        w = np.moveaxis(inv, axis, -1)
        ok = np.moveaxis(valid, axis, -1)
        step = w[..., 1:] - w[..., :-1]
        step_ok = ok[..., 1:] & ok[..., :-1]
        inf = np.float32(np.inf)
        before = np.full_like(step, inf)
        before[..., 1:] = np.where(step_ok[..., :-1], np.abs(step[..., 1:] - step[..., :-1]), inf)
        after = np.full_like(step, inf)
        after[..., :-1] = np.where(step_ok[..., 1:], np.abs(step[..., :-1] - step[..., 1:]), inf)
        deviation = np.minimum(before, after)
        deviation = np.where(np.isinf(deviation), np.abs(step), deviation)
        near = np.maximum(w[..., 1:], w[..., :-1])
        jump = step_ok & (deviation > max_jump * near)
        r = np.moveaxis(rim, axis, -1)
        r[..., :-1] |= jump & (step < 0)         # first pixel farther (smaller inverse depth)
        r[..., 1:] |= jump & (step > 0)
    labels, _ = label_regions(valid & ~rim, connectivity=4)
    return rim, labels


def _relative_slope(inv: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(H, W) float32 per-pixel step of inverse depth relative to its value, per pixel.

    Per axis, the smaller of the two one-sided steps to neighbours of the same component (so a
    step across an edge does not count); the larger of the two axes. 0 where unknown.
    """
    slope = np.zeros(inv.shape, dtype=np.float32)
    for axis in (1, 0):
        w = np.moveaxis(inv, axis, -1)
        lab = np.moveaxis(labels, axis, -1)
        same = (lab[..., 1:] == lab[..., :-1]) & (lab[..., 1:] > 0)
        step = np.where(same, np.abs(w[..., 1:] - w[..., :-1]), np.float32(np.inf))
        side = np.full(w.shape[:-1] + (w.shape[-1] + 1,), np.inf, dtype=np.float32)
        side[..., 1:-1] = step
        smaller = np.minimum(side[..., :-1], side[..., 1:])
        smaller = np.where(np.isinf(smaller), 0, smaller)
        out = np.moveaxis(slope, axis, -1)
        np.maximum(out, smaller, out=out)
    return np.where(inv > 0, slope / np.where(inv > 0, inv, 1), 0).astype(np.float32)


def auto_window(height: int, width: int) -> tuple[int, int]:
    """Default ``(radius, stride)`` for an image size: a window about 2 % of the longer side.

    Wider windows average out sensor noise; narrower ones keep creases (plane intersections,
    which have no depth jump) sharp. Scaling with the image keeps that balance across
    resolutions: (6, 2) at 640x480, (3, 1) at 256x192, (1, 1) at 64x48.
    """
    radius = max(1, round(max(height, width) / 100))
    return radius, _default_stride(radius)


def _default_stride(radius: int) -> int:
    """Sample every pixel in small windows, every other pixel from radius 4 on."""
    return 1 if radius < 4 else 2


def normals_from_depth(depth: np.ndarray, K: np.ndarray, *, radius: int | None = None,
                       stride: int | None = None, max_jump: float = 0.05,
                       min_support: int = 4) -> np.ndarray:
    """Estimate unit surface normals from a z-depth map, without smearing across edges.

    Parameters
    ----------
    depth : numpy.ndarray
        (H, W) z-depth in any unit (only ratios matter, so relative depth works too); 0, NaN
        and inf mark holes.
    K : numpy.ndarray
        (3, 3) pinhole intrinsics in pixels.
    radius : int, optional
        Half-size of the square fitting window in pixels (window side ``2 * radius + 1``),
        rounded down to a multiple of ``stride``. Default: :func:`auto_window`.
    stride : int, optional
        Spacing of the window samples in pixels; ``stride = 2`` covers a window twice as wide
        at the same cost. Default: 1 below radius 4, else 2.
    max_jump : float
        Relative depth jump between adjacent pixels above which they lie on different
        surfaces (0.05 = 5 %). Raise it for very noisy sensors or grazing views.
    min_support : int
        Minimum number of accepted window samples for a valid normal (3 is the minimum
        for a plane).

    Returns
    -------
    numpy.ndarray
        (H, W, 3) float32 unit normals in the camera frame (OpenCV axes: x right, y down,
        z forward), oriented towards the camera (``n · ray < 0``); all-zero where the depth is
        a hole or the local fit is degenerate.
    """
    depth = np.asarray(depth)
    if depth.ndim != 2:
        raise InvalidInput(f"depth must have shape (H, W), got {depth.shape}")
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise InvalidInput(f"K must be 3x3, got {K.shape}")
    radius = auto_window(*depth.shape)[0] if radius is None else radius
    stride = _default_stride(radius) if stride is None else stride
    if radius < 1 or stride < 1 or stride > radius:
        raise InvalidInput(f"need 1 <= stride <= radius, got radius={radius}, stride={stride}")
    if max_jump <= 0:
        raise InvalidInput(f"max_jump must be positive, got {max_jump}")
    z = np.where(np.isfinite(depth), depth, 0).astype(np.float32)
    valid = z > 0
    rim, labels = _rim_and_components(z, valid, max_jump)
    inv = np.zeros_like(z)
    inv[valid] = 1.0 / z[valid]
    r = radius - radius % stride
    steps = np.arange(-r, r + 1, stride)
    win = np.ones((2 * r + 1, 2 * r + 1), np.uint8)

    # A window without rims, with a single component and a small depth range cannot mix
    # surfaces, so its masked fit reduces to separable filters over the whole image. Only the
    # band near depth edges needs per-neighbour gating.
    big = np.float32(np.inf)
    lab_f = labels.astype(np.float32)
    one_surface = (
        (cv2.dilate(rim.astype(np.uint8), win) == 0)
        & (cv2.dilate(lab_f, win) == cv2.erode(np.where(labels > 0, lab_f, big), win))
        & (cv2.dilate(z, win) / (1.0 + max_jump * r) <= cv2.erode(np.where(valid, z, big), win))
    )
    interior = valid & one_surface
    band = valid & ~interior
    min_support = max(min_support, 3)

    normals = np.zeros(z.shape + (3,), dtype=np.float32)
    vv, uu = np.nonzero(interior)
    if vv.size:
        # Full-footprint kernels with zero taps between the strided samples; zero padding
        # outside the image acts like holes.
        one = np.zeros(2 * r + 1, dtype=np.float32)
        one[steps + r] = 1.0
        ramp = one * np.arange(-r, r + 1, dtype=np.float32)
        ramp2 = ramp * ramp
        m = valid.astype(np.float32)

        def corr(img: np.ndarray, kx: np.ndarray, ky: np.ndarray) -> np.ndarray:
            out = cv2.sepFilter2D(img, cv2.CV_32F, kx, ky, borderType=cv2.BORDER_CONSTANT)
            return out[interior].astype(np.float64)

        moments = [corr(m, one, one), corr(m, ramp, one), corr(m, one, ramp),
                   corr(m, ramp2, one), corr(m, ramp, ramp), corr(m, one, ramp2),
                   corr(inv, ramp, one), corr(inv, one, ramp), corr(inv, one, one)]
        a, b, c, good = _solve_line_fits(*moments, min_support=min_support, stride=stride)
        # Here the fitted line is absolute inverse depth, so its value at the centre is c.
        normals[interior] = _normals_from_inverse_depth_line(a, b, c, uu, vv, K, good)
    vv, uu = np.nonzero(band)
    if vv.size:
        slope = _relative_slope(inv, labels)[vv, uu]
        normals[band] = _gated_fit(inv, labels, rim, slope, vv, uu, steps, r, K, max_jump,
                                   min_support, stride)
    return normals


def _solve_line_fits(cnt: np.ndarray, su: np.ndarray, sv: np.ndarray, suu: np.ndarray,
                     suv: np.ndarray, svv: np.ndarray, ru: np.ndarray, rv: np.ndarray,
                     r1: np.ndarray, *, min_support: int,
                     stride: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Solve many least-squares fits ``y ≈ a du + b dv + c`` from their moments.

    Each argument is an (N,) float64 array of window sums: sample count, ``Σdu``, ``Σdv``,
    ``Σdu²``, ``Σdu dv``, ``Σdv²``, ``Σdu y``, ``Σdv y`` and ``Σy``. Returns ``a, b, c`` and a
    bool mask of the well-posed fits (enough samples, not all on one line); the others are 0.
    """
    # Cramer's rule on the symmetric 3x3 normal equations, written out because batched
    # LAPACK calls are slower for 3x3 systems.
    c00 = svv * cnt - sv * sv
    c01 = su * sv - suv * cnt
    c02 = suv * sv - svv * su
    c11 = suu * cnt - su * su
    c12 = suv * su - suu * sv
    c22 = suu * svv - suv * suv
    det = suu * c00 + suv * c01 + su * c02
    # Samples on (nearly) one line give a singular system: no plane is defined there.
    good = (cnt >= min_support) & (det > 1e-2 * stride**4 * np.maximum(cnt, 1) ** 3)
    inv_det = np.where(good, 1.0 / np.where(good, det, 1.0), 0.0)
    a = (c00 * ru + c01 * rv + c02 * r1) * inv_det
    b = (c01 * ru + c11 * rv + c12 * r1) * inv_det
    c = (c02 * ru + c12 * rv + c22 * r1) * inv_det
    return a, b, c, good


def _gated_fit(inv: np.ndarray, labels: np.ndarray, rim: np.ndarray, slope: np.ndarray,
               vv: np.ndarray, uu: np.ndarray, steps: np.ndarray, r: int, K: np.ndarray,
               max_jump: float, min_support: int, stride: int) -> np.ndarray:
    """Edge-aware least-squares fits for the pixels ``(vv, uu)``; returns (N, 3) normals."""
    dv, du = (a.ravel() for a in np.meshgrid(steps, steps, indexing="ij"))
    inv_p = np.pad(inv, r).ravel()
    lab_p = np.pad(labels, r).ravel()
    width_p = inv.shape[1] + 2 * r
    flat = ((vv + r) * width_p + (uu + r))[:, None] + (dv * width_p + du)[None, :]
    q_inv = inv_p.take(flat)
    c_inv = inv[vv, uu][:, None]
    # e is the neighbour's inverse depth relative to the centre's, so a and b below are
    # relative gradients and one tolerance fits every depth range.
    e = q_inv / c_inv - 1.0
    abs_e = np.abs(e)
    chebyshev = np.maximum(np.maximum(np.abs(du), np.abs(dv)), 1).astype(np.float32)
    on_rim = rim[vv, uu]
    ok = lab_p.take(flat) == labels[vv, uu][:, None]
    # Steep planes change inverse depth fast: scale the tolerance with the pixel's own step.
    ok &= abs_e <= (max_jump + slope[:, None]) * chebyshev[None, :]
    ok[on_rim] = (abs_e[on_rim] <= max_jump) & (q_inv[on_rim] > 0)
    # Moments of the accepted samples. einsum keeps this single-threaded: a BLAS product this
    # skinny is no faster and thrashes when other processes share the cores.
    fu, fv = du.astype(np.float32), dv.astype(np.float32)
    basis = np.stack([np.ones_like(fu), fu, fv, fu * fu, fu * fv, fv * fv], axis=1)
    m = ok.astype(np.float32)
    moments = np.einsum("nk,kj->jn", m, basis).astype(np.float64)
    rhs = np.einsum("nk,kj->jn", e * m, basis[:, [1, 2, 0]]).astype(np.float64)
    a, b, c, good = _solve_line_fits(*moments, *rhs, min_support=min_support, stride=stride)
    # Near the centre, w = w_p (1 + c + a du + b dv); the positive factor w_p drops out.
    return _normals_from_inverse_depth_line(a, b, 1.0 + c, uu, vv, K, good)


def _normals_from_inverse_depth_line(grad_u: np.ndarray, grad_v: np.ndarray,
                                     value: np.ndarray, uu: np.ndarray, vv: np.ndarray,
                                     K: np.ndarray, good: np.ndarray) -> np.ndarray:
    """Normals from local linear models of inverse depth at pixels ``(uu, vv)``.

    ``w(u', v') ≈ value + grad_u (u' - u) + grad_v (v' - v)`` (any positive scale) gives
    ``g = [grad_u, grad_v, value - grad_u u - grad_v v]`` and ``n ∝ -K^T g``; rows where
    ``good`` is False come back as zeros. Returns (N, 3) float32, facing the camera.
    """
    gu = np.asarray(grad_u, dtype=np.float64)
    gv = np.asarray(grad_v, dtype=np.float64)
    val = np.asarray(value, dtype=np.float64)
    g2 = val - gu * uu - gv * vv
    # n = -K^T g, written per component: (N, 3) x (3, 3) products are slow through BLAS.
    n = np.empty((gu.size, 3), dtype=np.float64)
    for i in range(3):
        n[:, i] = -(gu * K[0, i] + gv * K[1, i] + g2 * K[2, i])
    # n · K^-1 [u, v, 1] = -g · [u, v, 1] = -value: a positive inverse depth already means the
    # normal faces the camera, and a non-positive one means the fit is unusable.
    norm = np.sqrt(np.einsum("ij,ij->i", n, n))
    good = good & (val > 0) & (norm > 0)
    n *= (good / np.where(good, norm, 1.0))[:, None]
    return n.astype(np.float32)
