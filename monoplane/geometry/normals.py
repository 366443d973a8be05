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
from window sums of the masked moments, taken for the whole image at once with separable
filters; only the band near depth edges goes through the per-neighbour gating above. The
discontinuities, the slopes and the fits are compiled kernels (:mod:`monoplane.jit`), the fits
split by rows over the frame's threads: at 640x480 with the defaults they take about a quarter
of the CPU time of the NumPy version they replaced (same decisions, normals equal to float
rounding; docs/evaluation.md).

Holes (depth 0, NaN or inf) contribute nothing and get a zero normal. Pixels without enough
well-spread support (fewer than ``min_support`` accepted neighbours, or all on a line) get a
zero normal too, which downstream code treats as invalid.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from monoplane.errors import InvalidInput
from monoplane.jit import chunks, inline, kernel, run_threaded

#: Rows of the image per threaded piece of the fit below which one thread does it all.
_THREADED_ROWS = 64


@kernel
def _discontinuities(z: np.ndarray, max_jump: float) -> tuple[np.ndarray, np.ndarray]:
    """Inverse depth and rim mask (far side of each discontinuity) of a (H, W) float32 depth.

    Along a row or column, the inverse depth of a plane changes by the same step from pixel
    to pixel, however steep the plane (a floor near the horizon). So a discontinuity is a
    step that differs from *both* neighbouring steps by more than ``max_jump`` relative to the
    inverse depth; a step whose neighbours are missing (holes, image border) is compared with
    zero instead. Arithmetic is float32, like the inputs.

    Returns
    -------
    inv : numpy.ndarray
        (H, W) float32 ``1 / z``, 0 on holes (``z <= 0``).
    rim : numpy.ndarray
        (H, W) bool.
    """
    h, w = z.shape
    inv = np.zeros((h, w), dtype=np.float32)
    for v in range(h):
        for u in range(w):
            if z[v, u] > 0:
                inv[v, u] = np.float32(1.0) / z[v, u]
    rim = np.zeros((h, w), dtype=np.bool_)
    jump = np.float32(max_jump)
    zero = np.float32(0.0)
    # Each pair is tested on its own, so the order is free: row by row, both axes, each
    # row's pairs in a branch-free loop (vectorised), the image border (a missing outer
    # neighbour) passed as a hole.
    side = np.zeros(max(h, w), dtype=np.int8)
    for v in range(h):
        row = inv[v]
        for i in range(w - 1):
            prev = row[i - 1] if i > 0 else zero
            nxt = row[i + 2] if i + 2 < w else zero
            side[i] = _pair_edge(prev, row[i], row[i + 1], nxt, jump)
        for i in range(w - 1):
            rim[v, i] |= side[i] < 0
            rim[v, i + 1] |= side[i] > 0
        if v + 1 < h:
            above = inv[v - 1] if v > 0 else inv[v] * zero
            below = inv[v + 2] if v + 2 < h else inv[v] * zero
            nxt_row = inv[v + 1]
            for u in range(w):
                side[u] = _pair_edge(above[u], row[u], nxt_row[u], below[u], jump)
            for u in range(w):
                rim[v, u] |= side[u] < 0
                rim[v + 1, u] |= side[u] > 0
    return inv, rim


@inline
def _pair_edge(prev: float, a: float, b: float, nxt: float, jump: float) -> int:
    """Whether the step ``a -> b`` of float32 inverse depth between neighbours is a
    discontinuity (see :func:`_discontinuities`; ``prev`` and ``nxt`` are the outer
    neighbours, 0 when missing): -1 marks ``a``'s pixel as the rim, +1 ``b``'s, 0 none."""
    step = b - a
    inf = np.float32(np.inf)
    before = abs(step - (a - prev)) if prev > 0 else inf
    after = abs(step - (nxt - b)) if nxt > 0 else inf
    deviation = min(before, after)
    if deviation == inf:
        deviation = abs(step)
    if not (a > 0 and b > 0 and step != 0 and deviation > jump * max(a, b)):
        return 0
    return -1 if step < 0 else 1


@kernel
def _relative_slope(inv: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(H, W) float32 per-pixel step of inverse depth relative to its value, per pixel.

    Per axis, the smaller of the two one-sided steps to neighbours of the same component (so a
    step across an edge does not count); the larger of the two axes. 0 where unknown.
    """
    h, w = inv.shape
    slope = np.zeros((h, w), dtype=np.float32)
    for v in range(h):
        for u in range(w):
            if not inv[v, u] > 0:
                continue
            lab = labels[v, u]
            best = np.float32(0.0)
            for dv, du in ((0, 1), (1, 0)):
                smaller = np.float32(np.inf)
                for sign in (-1, 1):
                    y, x = v + sign * dv, u + sign * du
                    if 0 <= y < h and 0 <= x < w and lab > 0 and labels[y, x] == lab:
                        smaller = min(smaller, abs(inv[y, x] - inv[v, u]))
                if smaller != np.inf:
                    best = max(best, smaller)
            slope[v, u] = best / inv[v, u]
    return slope


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
    inv, rim = _discontinuities(z, float(max_jump))
    valid = z > 0
    # 4-connected components of the valid non-rim pixels; only equality of labels matters.
    labels = cv2.connectedComponents((valid & ~rim).view(np.uint8), connectivity=4,
                                     ltype=cv2.CV_32S)[1]
    r = radius - radius % stride
    win = np.ones((2 * r + 1, 2 * r + 1), np.uint8)

    # A window without rims, with a single component and a small depth range cannot mix
    # surfaces, so its masked fit reduces to separable filters over the whole image. Only the
    # band near depth edges needs per-neighbour gating.
    big = np.float32(np.inf)
    lab_f = labels.astype(np.float32)
    one_surface = (
        (cv2.dilate(rim.view(np.uint8), win) == 0)
        & (cv2.dilate(lab_f, win) == cv2.erode(np.where(labels > 0, lab_f, big), win))
        & (cv2.dilate(z, win) / (1.0 + max_jump * r) <= cv2.erode(np.where(valid, z, big), win))
    )
    interior = valid & one_surface
    # Window sums: full-footprint kernels with zero taps between the strided samples; zero
    # padding outside the image acts like holes.
    steps = np.arange(-r, r + 1, stride)
    one = np.zeros(2 * r + 1, dtype=np.float32)
    one[steps + r] = 1.0
    ramp = one * np.arange(-r, r + 1, dtype=np.float32)
    sums = np.empty((4,) + z.shape, dtype=np.float32)
    filters: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = [
        (valid.astype(np.float32), one, one), (inv, ramp, one), (inv, one, ramp), (inv, one, one)]
    for k, (img, kx, ky) in enumerate(filters):
        cv2.sepFilter2D(img, cv2.CV_32F, kx, ky, dst=sums[k], borderType=cv2.BORDER_CONSTANT)
    slope = _relative_slope(inv, labels)
    normals = np.zeros(z.shape + (3,), dtype=np.float32)
    params = np.array([max_jump, K[0, 0], K[0, 1], K[0, 2], K[1, 0], K[1, 1], K[1, 2],
                       K[2, 0], K[2, 1], K[2, 2]], dtype=np.float64)
    band = valid & ~interior
    support = max(min_support, 3)

    def fit(a: int, b: int) -> None:
        _fit_interior(inv, labels, interior, sums, params, r, stride, support, a, b, normals)
        _fit_band(inv, labels, rim, slope, band, params, r, stride, support, a, b, normals)

    run_threaded([functools.partial(fit, a, b) for a, b in chunks(z.shape[0], _THREADED_ROWS)])
    return normals


@inline
def _line_fit(cnt: float, su: float, sv: float, suu: float, suv: float, svv: float,
              ru: float, rv: float, r1: float, min_support: int,
              stride: int) -> tuple[float, float, float, bool]:
    """Least-squares fit ``y ≈ a du + b dv + c`` from its window sums: sample count, ``Σdu``,
    ``Σdv``, ``Σdu²``, ``Σdu dv``, ``Σdv²``, ``Σdu y``, ``Σdv y`` and ``Σy``. Returns ``a, b,
    c`` and whether the fit is well posed (enough samples, not all on one line)."""
    # Cramer's rule on the symmetric 3x3 normal equations.
    c00 = svv * cnt - sv * sv
    c01 = su * sv - suv * cnt
    c02 = suv * sv - svv * su
    c11 = suu * cnt - su * su
    c12 = suv * su - suu * sv
    c22 = suu * svv - suv * suv
    det = suu * c00 + suv * c01 + su * c02
    # Samples on (nearly) one line give a singular system: no plane is defined there.
    n = max(cnt, 1.0)
    if not (cnt >= min_support and det > 1e-2 * (stride * stride) ** 2 * (n * n * n)):
        return 0.0, 0.0, 0.0, False
    inv_det = 1.0 / det
    return ((c00 * ru + c01 * rv + c02 * r1) * inv_det,
            (c01 * ru + c11 * rv + c12 * r1) * inv_det,
            (c02 * ru + c12 * rv + c22 * r1) * inv_det, True)


@inline
def _store_normal(out: np.ndarray, v: int, u: int, grad_u: float, grad_v: float, value: float,
                  params: np.ndarray) -> None:
    """Write the normal of the local linear model of inverse depth at pixel ``(v, u)``.

    ``w(u', v') ≈ value + grad_u (u' - u) + grad_v (v' - v)`` (any positive scale) gives
    ``g = [grad_u, grad_v, value - grad_u u - grad_v v]`` and ``n ∝ -K^T g``. Since
    ``n · K^-1 [u, v, 1] = -g · [u, v, 1] = -value``, a positive value already means the normal
    faces the camera, and a non-positive one that the fit is unusable (left zero).
    """
    if not value > 0:
        return
    g2 = value - grad_u * u - grad_v * v
    nx = -(grad_u * params[1] + grad_v * params[4] + g2 * params[7])
    ny = -(grad_u * params[2] + grad_v * params[5] + g2 * params[8])
    nz = -(grad_u * params[3] + grad_v * params[6] + g2 * params[9])
    norm = np.sqrt(nx * nx + ny * ny + nz * nz)
    if norm > 0:
        out[v, u, 0] = nx / norm
        out[v, u, 1] = ny / norm
        out[v, u, 2] = nz / norm


@inline
def _window_sums(inv: np.ndarray, labels: np.ndarray, v: int, u: int, r: int, stride: int,
                 lab: int, on_rim: bool, ungated: bool, tol: float, max_jump: float
                 ) -> tuple[float, float, float, float, float, float, float, float, float]:
    """Window sums of the accepted samples around pixel ``(v, u)``, in the order of
    :func:`_line_fit`, the fitted value being the sample's inverse depth relative to the
    centre's, ``e = w / w_p - 1`` (so the fit's gradients are relative and one tolerance fits
    every depth range).

    ``ungated``: every valid sample is accepted. Otherwise a rim pixel (``on_rim``) accepts
    samples within ``max_jump`` of its own inverse depth, any other pixel samples of its own
    component ``lab`` whose ``|e|`` stays within ``tol`` per pixel of offset (Chebyshev).
    """
    h, w = inv.shape
    c = inv[v, u]
    cnt = su = sv = suu = suv = svv = ru = rv = r1 = 0.0
    for dv in range(-r, r + 1, stride):
        y = v + dv
        if y < 0 or y >= h:
            continue
        for du in range(-r, r + 1, stride):
            x = u + du
            if x < 0 or x >= w:
                continue
            q = inv[y, x]
            e = q / c - 1.0
            if ungated or on_rim:
                if not (q > 0 and (ungated or abs(e) <= max_jump)):
                    continue
            elif labels[y, x] != lab or not abs(e) <= tol * max(abs(du), abs(dv), 1):
                continue
            fu, fv = float(du), float(dv)
            cnt += 1.0
            su += fu
            sv += fv
            suu += fu * fu
            suv += fu * fv
            svv += fv * fv
            ru += e * fu
            rv += e * fv
            r1 += e
    return cnt, su, sv, suu, suv, svv, ru, rv, r1


@kernel
def _fit_interior(inv: np.ndarray, labels: np.ndarray, interior: np.ndarray, sums: np.ndarray,
                  params: np.ndarray, r: int, stride: int, min_support: int, row0: int,
                  row1: int, out: np.ndarray) -> None:
    """Normals of the ``interior`` pixels of rows ``row0:row1`` into ``out`` ((H, W, 3)
    float32), each from the fit of absolute inverse depth over its whole window.

    ``sums`` is (4, H, W) float32: per window, the count of valid samples and ``Σdu w``,
    ``Σdv w``, ``Σw``. A window with every sample valid has the same sums of offsets
    everywhere; one with holes gets them from its samples (:func:`_window_sums` ungated, so
    ``labels`` is not read). ``params`` is ``[max_jump, K (row-major)]``.
    """
    w = inv.shape[1]
    side = (2 * r) // stride + 1
    full = float(side * side)
    spread = 0.0  # Σdu² over a full window (= Σdv²)
    for d in range(-r, r + 1, stride):
        spread += float(d * d) * side
    for v in range(row0, row1):
        for u in range(w):
            if not interior[v, u]:
                continue
            cnt = float(sums[0, v, u])
            su = sv = suv = 0.0
            suu = svv = spread
            if cnt < full:  # holes: the offsets of the valid samples, ungated
                cnt, su, sv, suu, suv, svv, _, _, _ = _window_sums(
                    inv, labels, v, u, r, stride, 0, False, True, 0.0, 0.0)
            a, b, c, good = _line_fit(cnt, su, sv, suu, suv, svv, float(sums[1, v, u]),
                                      float(sums[2, v, u]), float(sums[3, v, u]),
                                      min_support, stride)
            if good:  # the line is absolute inverse depth: its centre value is c
                _store_normal(out, v, u, a, b, c, params)


@kernel
def _fit_band(inv: np.ndarray, labels: np.ndarray, rim: np.ndarray, slope: np.ndarray,
              band: np.ndarray, params: np.ndarray, r: int, stride: int, min_support: int,
              row0: int, row1: int, out: np.ndarray) -> None:
    """Edge-aware normals of the ``band`` pixels of rows ``row0:row1`` into ``out``.

    Each window sample is gated: a rim pixel accepts samples within ``max_jump`` of its own
    inverse depth, any other pixel samples of its own component within ``max_jump`` plus its
    own relative ``slope`` per pixel of offset (Chebyshev). The fit is of inverse depth
    relative to the centre's (:func:`_window_sums`). ``params`` is ``[max_jump, K
    (row-major)]``.
    """
    w = inv.shape[1]
    max_jump = params[0]
    for v in range(row0, row1):
        for u in range(w):
            if not band[v, u]:
                continue
            cnt, su, sv, suu, suv, svv, ru, rv, r1 = _window_sums(
                inv, labels, v, u, r, stride, labels[v, u], rim[v, u], False,
                max_jump + slope[v, u], max_jump)
            a, b, c0, good = _line_fit(cnt, su, sv, suu, suv, svv, ru, rv, r1, min_support,
                                       stride)
            if good:  # near the centre w = w_p (1 + c0 + a du + b dv); w_p > 0 drops out
                _store_normal(out, v, u, a, b, 1.0 + c0, params)
