"""Compiled kernels of :mod:`monoplane.geometry.normals`: the depth discontinuities, the gated
per-sample fits and the box fits (the window sums and the pixels near edges).

Kept apart from the module that orchestrates them so that each stays small; the inline helpers
live here beside every kernel that calls them (numba's disk cache of a kernel follows its own
source file).
"""

from __future__ import annotations

import numpy as np

from monoplane.jit import inline, kernel


@kernel
def _inverse_depth(z: np.ndarray, row0: int, row1: int, inv: np.ndarray) -> None:
    """Rows ``row0:row1`` of the (H, W) float32 inverse depth ``inv = 1 / z`` of the (H, W)
    float32 depth ``z``, 0 on holes (``z <= 0``, NaN; ``1 / inf`` is 0 as well)."""
    for v in range(row0, row1):
        for u in range(z.shape[1]):
            if z[v, u] > 0:
                inv[v, u] = np.float32(1.0) / z[v, u]
            else:
                inv[v, u] = 0


@kernel
def _rims(inv: np.ndarray, max_jump: float, row0: int, row1: int, rim: np.ndarray) -> None:
    """Rows ``row0:row1`` of the (H, W) bool rim mask (near side of each discontinuity) of the
    (H, W) float32 inverse depth ``inv`` (0 on holes).

    Along a row or column, the inverse depth of a plane changes by the same step from pixel
    to pixel, however steep the plane (a floor near the horizon). So a discontinuity is a
    step that differs from *both* neighbouring steps by more than ``max_jump`` relative to the
    inverse depth; a step whose neighbours are missing (holes, image border) is compared with
    zero instead. Arithmetic is float32, like the inputs.

    Each pair is tested on its own, so the order is free: row by row, both axes, each row's
    pairs in a branch-free loop (vectorised), the image border (a missing outer neighbour)
    passed as a hole. Only rows ``row0:row1`` are written (the vertical pairs that cross
    their first and last row are tested by both neighbouring pieces), so pieces of rows can
    run on parallel threads.
    """
    h, w = inv.shape
    jump = np.float32(max_jump)
    zero = np.float32(0.0)
    side = np.zeros(max(h, w), dtype=np.int8)
    for v in range(row0, row1):
        for u in range(w):
            rim[v, u] = False
    for v in range(row0, row1):
        row = inv[v]
        for i in range(w - 1):
            prev = row[i - 1] if i > 0 else zero
            nxt = row[i + 2] if i + 2 < w else zero
            side[i] = _pair_edge(prev, row[i], row[i + 1], nxt, jump)
        for i in range(w - 1):
            rim[v, i] |= side[i] < 0
            rim[v, i + 1] |= side[i] > 0
    # The vertical pairs (p, p + 1) that touch the rows.
    for p in range(max(row0 - 1, 0), min(row1, h - 1)):
        row, nxt_row = inv[p], inv[p + 1]
        above = inv[p - 1] if p > 0 else row * zero
        below = inv[p + 2] if p + 2 < h else row * zero
        for u in range(w):
            side[u] = _pair_edge(above[u], row[u], nxt_row[u], below[u], jump)
        if p >= row0:
            for u in range(w):
                rim[p, u] |= side[u] < 0
        if p + 1 < row1:
            for u in range(w):
                rim[p + 1, u] |= side[u] > 0


@inline
def _pair_edge(prev: float, a: float, b: float, nxt: float, jump: float) -> int:
    """Whether the step ``a -> b`` of float32 inverse depth between neighbours is a
    discontinuity (see :func:`_rims`; ``prev`` and ``nxt`` are the outer
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


@inline
def _relative_slope(inv: np.ndarray, labels: np.ndarray, v: int, u: int) -> np.float32:
    """Step of float32 inverse depth at pixel ``(v, u)`` relative to its value, per pixel.

    Per axis, the smaller of the two one-sided steps to neighbours of the same component (so a
    step across an edge does not count); the larger of the two axes. 0 where unknown. Float32
    arithmetic throughout. See also :func:`_own_slope`, the box method's float64 twin that
    tells sides by rims instead of components.
    """
    h, w = inv.shape
    if not inv[v, u] > 0:
        return np.float32(0.0)
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
    return np.float32(best / inv[v, u])


@inline
def _line_fit(cnt: float, su: float, sv: float, suu: float, suv: float, svv: float,
              ru: float, rv: float, r1: float, min_support: int,
              stride: int) -> tuple[float, float, float, bool]:
    """Least-squares fit ``y ≈ a du + b dv + c`` from its window sums: sample count, ``Σdu``,
    ``Σdv``, ``Σdu²``, ``Σdu dv``, ``Σdv²``, ``Σdu y``, ``Σdv y`` and ``Σy``. Returns ``a, b,
    c`` and whether the fit is well posed (enough samples, not all on one line)."""
    c00, c01, c02, c11, c12, c22, inv_det, good = _cofactors(cnt, su, sv, suu, suv, svv,
                                                             min_support, stride)
    if not good:
        return 0.0, 0.0, 0.0, False
    a, b, c = _solve(c00, c01, c02, c11, c12, c22, inv_det, ru, rv, r1)
    return a, b, c, True


@inline
def _cofactors(cnt: float, su: float, sv: float, suu: float, suv: float, svv: float,
               min_support: int, stride: int
               ) -> tuple[float, float, float, float, float, float, float, bool]:
    """The cofactors and ``1 / det`` of the symmetric 3x3 normal equations of
    :func:`_line_fit` (its sums of offsets), and whether the fit is well posed."""
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
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, False
    return c00, c01, c02, c11, c12, c22, 1.0 / det, True


@inline
def _solve(c00: float, c01: float, c02: float, c11: float, c12: float, c22: float,
           inv_det: float, ru: float, rv: float, r1: float) -> tuple[float, float, float]:
    """``a, b, c`` of :func:`_line_fit` from :func:`_cofactors` and the sums of ``y``."""
    return ((c00 * ru + c01 * rv + c02 * r1) * inv_det,
            (c01 * ru + c11 * rv + c12 * r1) * inv_det,
            (c02 * ru + c12 * rv + c22 * r1) * inv_det)


@inline
def _camera_normal(u: int, v: int, grad_u: float, grad_v: float, value: float,
                   params: np.ndarray) -> tuple[float, float, float, float]:
    """``-K^T g`` of the inverse-depth model ``g`` at pixel ``(v, u)`` (see
    :func:`_store_normal`) and its norm; ``params[1:10]`` is K row-major."""
    g2 = value - grad_u * u - grad_v * v
    nx = -(grad_u * params[1] + grad_v * params[4] + g2 * params[7])
    ny = -(grad_u * params[2] + grad_v * params[5] + g2 * params[8])
    nz = -(grad_u * params[3] + grad_v * params[6] + g2 * params[9])
    return nx, ny, nz, np.sqrt(nx * nx + ny * ny + nz * nz)


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
    nx, ny, nz, norm = _camera_normal(u, v, grad_u, grad_v, value, params)
    if norm > 0:
        out[v, u, 0] = nx / norm
        out[v, u, 1] = ny / norm
        out[v, u, 2] = nz / norm


@inline
def _window_sums(inv: np.ndarray, labels: np.ndarray, v: int, u: int, r: int, stride: int,
                 lab: int, on_rim: bool, tol: float, max_jump: float
                 ) -> tuple[float, float, float, float, float, float, float, float, float]:
    """Window sums of the accepted samples around pixel ``(v, u)``, in the order of
    :func:`_line_fit`, the fitted value being the sample's inverse depth relative to the
    centre's, ``e = w / w_p - 1`` (so the fit's gradients are relative and one tolerance fits
    every depth range).

    A rim pixel (``on_rim``) accepts valid samples within ``max_jump`` of its own inverse
    depth, any other pixel samples of its own component ``lab`` whose ``|e|`` stays within
    ``tol`` per pixel of offset (Chebyshev).
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
            if on_rim:
                if not (q > 0 and abs(e) <= max_jump):
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


@inline
def _valid_offsets(inv: np.ndarray, v: int, u: int, r: int, stride: int, count: float
                   ) -> tuple[float, float, float, float, float, float]:
    """Count, ``Σdu``, ``Σdv``, ``Σdu²``, ``Σdu dv`` and ``Σdv²`` of the valid samples
    (``inv > 0``) of the window of pixel ``(v, u)``, every ``stride`` pixels within ``r``
    (Chebyshev), cut by the image border; ``count`` is how many there are. Sums of small
    integers, so exact in any order."""
    h, w = inv.shape
    # The offsets that stay in the image, per axis: their number, sum and sum of squares.
    nu = su1 = su2 = nv = sv1 = sv2 = 0
    for d in range(-r, r + 1, stride):
        if 0 <= u + d < w:
            nu, su1, su2 = nu + 1, su1 + d, su2 + d * d
        if 0 <= v + d < h:
            nv, sv1, sv2 = nv + 1, sv1 + d, sv2 + d * d
    if count == nu * nv:  # no hole, only the image border: the sums of a grid
        return (float(nu * nv), float(nv * su1), float(nu * sv1), float(nv * su2),
                float(su1 * sv1), float(nu * sv2))
    cnt = su = sv = suu = suv = svv = 0
    # The window's first column in the image, on the grid of offsets.
    lo_u = u - r if u >= r else u - r + ((r - u + stride - 1) // stride) * stride
    for dv in range(-r, r + 1, stride):
        y = v + dv
        if y < 0 or y >= h:
            continue
        for x in range(lo_u, min(u + r, w - 1) + 1, stride):
            # Same moments as _box_band's gated ones, in exact integers (no residual terms).
            keep = 1 if inv[y, x] > 0 else 0
            du = x - u
            cnt += keep
            su += keep * du
            sv += keep * dv
            suu += keep * du * du
            suv += keep * du * dv
            svv += keep * dv * dv
    return float(cnt), float(su), float(sv), float(suu), float(suv), float(svv)


@kernel
def _fit_interior(inv: np.ndarray, interior: np.ndarray, sums: np.ndarray, params: np.ndarray,
                  r: int, stride: int, min_support: int, row0: int, row1: int,
                  out: np.ndarray) -> None:
    """Normals of the ``interior`` pixels of rows ``row0:row1`` into ``out`` ((H, W, 3)
    float32), each from the fit of absolute inverse depth over its whole window.

    ``sums`` is (4, H, W) float32: per window, the count of valid samples and ``Σdu w``,
    ``Σdv w``, ``Σw``. A window with every sample valid has the same sums of offsets
    everywhere; one with holes gets them from its valid samples (:func:`_valid_offsets`).
    ``params`` is ``[max_jump, K (row-major)]``.
    """
    w = inv.shape[1]
    side = (2 * r) // stride + 1
    full = float(side * side)
    spread = 0.0  # Σdu² over a full window (= Σdv²)
    for d in range(-r, r + 1, stride):
        spread += float(d * d) * side
    # The full windows' normal equations: the same for every pixel.
    c00, c01, c02, c11, c12, c22, inv_det, good = _cofactors(full, 0.0, 0.0, spread, 0.0,
                                                             spread, min_support, stride)
    # One row of normals (x, y, z, then the norm) and whether each is kept.
    row = np.empty((4, w), np.float64)
    keep = np.zeros(w, np.bool_)
    for v in range(row0, row1):
        # Full windows: the arithmetic of _line_fit and _store_normal without a branch on the
        # pixel, so that the loop runs on vector registers; a pixel that is not kept is
        # divided by 1 instead. The division is a ufunc: `/` checks each divisor for zero.
        # (An ill-posed full window, too few samples for min_support, keeps none.)
        if good:
            for u in range(w):
                a, b, c = _solve(c00, c01, c02, c11, c12, c22, inv_det, float(sums[1, v, u]),
                                 float(sums[2, v, u]), float(sums[3, v, u]))
                nx, ny, nz, norm = _camera_normal(u, v, a, b, c, params)
                ok = interior[v, u] & (sums[0, v, u] >= full) & (c > 0) & (norm > 0)
                row[0, u], row[1, u], row[2, u] = nx, ny, nz
                row[3, u] = norm if ok else 1.0
                keep[u] = ok
            for k in range(3):
                np.divide(row[k], row[3], row[k])
        for u in range(w):
            if keep[u]:
                out[v, u, 0], out[v, u, 1], out[v, u, 2] = row[0, u], row[1, u], row[2, u]
            elif interior[v, u] and sums[0, v, u] < full:
                # holes: the sums of offsets of the valid samples
                cnt, su, sv, suu, suv, svv = _valid_offsets(inv, v, u, r, stride,
                                                            float(sums[0, v, u]))
                a, b, c, good = _line_fit(cnt, su, sv, suu, suv, svv, float(sums[1, v, u]),
                                          float(sums[2, v, u]), float(sums[3, v, u]),
                                          min_support, stride)
                if good:  # the line is absolute inverse depth: its centre value is c
                    _store_normal(out, v, u, a, b, c, params)


@kernel
def _fit_band(inv: np.ndarray, labels: np.ndarray, rim: np.ndarray, band: np.ndarray,
              params: np.ndarray, r: int, stride: int, min_support: int, row0: int, row1: int,
              out: np.ndarray) -> None:
    """Edge-aware normals of the ``band`` pixels of rows ``row0:row1`` into ``out``.

    Each window sample is gated: a rim pixel accepts samples within ``max_jump`` of its own
    inverse depth, any other pixel samples of its own component within ``max_jump`` plus its
    own relative slope (:func:`_relative_slope`) per pixel of offset (Chebyshev). The fit is
    of inverse depth relative to the centre's (:func:`_window_sums`). ``params`` is
    ``[max_jump, K (row-major)]``.
    """
    w = inv.shape[1]
    max_jump = params[0]
    for v in range(row0, row1):
        for u in range(w):
            if not band[v, u]:
                continue
            cnt, su, sv, suu, suv, svv, ru, rv, r1 = _window_sums(
                inv, labels, v, u, r, stride, labels[v, u], rim[v, u],
                max_jump + _relative_slope(inv, labels, v, u), max_jump)
            a, b, c0, good = _line_fit(cnt, su, sv, suu, suv, svv, ru, rv, r1, min_support,
                                       stride)
            if good:  # near the centre w = w_p (1 + c0 + a du + b dv); w_p > 0 drops out
                _store_normal(out, v, u, a, b, 1.0 + c0, params)


@kernel
def _box_planes(fixed: np.ndarray, r: int, scale: float, tol: float,
                params: np.ndarray, row0: int, row1: int, reach: np.ndarray,
                out: np.ndarray) -> None:
    """Box fits of rows ``row0:row1`` of the (H, W) int32 fixed-point inverse depth ``fixed``
    (:func:`_fixed_point`; 0 on holes and rims).

    A pixel whose whole ``(2r+1)²`` window lies in the image, holds valid samples off the
    rim only, and is explained by one line of inverse depth to a relative RMS of ``tol``,
    gets the line's normal ``n`` in ``out`` and its inverse distance ``1 / d`` in ``reach``
    ((H, W) float32; the plane ``n · X + d = 0`` has inverse depth ``-(n · ray) / d`` on the
    ray ``K^-1 [u, v, 1]``); other pixels are left as they are (``reach = 0``: no fit).

    The samples are taken in fixed point, ``round(inv * scale)``, so that the window sums
    are exact integers: they run along the columns (from one row to the next) and then along
    the row (one column in, one out), each an O(1) update per pixel, and do not depend on
    where a thread's rows start or in which order they are added.
    """
    h, w = fixed.shape
    side = 2 * r + 1
    full = side * side
    spread = 0  # Σdu² over the window (= Σdv²)
    for d in range(-r, r + 1):
        spread += d * d * side
    # Multiplications by reciprocals: these fits run on most pixels of the frame.
    inv_full, inv_spread, unit, tol2 = 1.0 / full, 1.0 / spread, 1.0 / scale, tol * tol * full
    col = np.zeros(w, np.int64)      # Σ over the window's rows of the sample
    ramp = np.zeros(w, np.int64)     # Σ of dv × sample
    sq = np.zeros(w, np.int64)       # Σ of its square
    cnt = np.zeros(w, np.int64)      # how many samples are valid non-rim
    start = max(row0, r)
    for v in range(start, min(row1, h - r)):
        if v == start:
            for dv in range(-r, r + 1):
                for u in range(w):
                    q = np.int64(fixed[v + dv, u])
                    col[u] += q
                    ramp[u] += dv * q
                    sq[u] += q * q
                    cnt[u] += 1 if q > 0 else 0
        else:  # slide down one row: drop row v - r - 1, add row v + r
            for u in range(w):
                old, new = np.int64(fixed[v - r - 1, u]), np.int64(fixed[v + r, u])
                col[u] += new - old
                ramp[u] += r * old + r * new - col[u] + new
                sq[u] += new * new - old * old
                cnt[u] += (1 if new > 0 else 0) - (1 if old > 0 else 0)
        # The window's sums of the columns u - r .. u + r (Σ u' col for the du moment),
        # slid along the row.
        s0 = s1 = sv = s2 = sn = np.int64(0)
        for u in range(2 * r):
            s0 += col[u]
            s1 += u * col[u]
            sv += ramp[u]
            s2 += sq[u]
            sn += cnt[u]
        for u in range(r, w - r):
            j = u + r
            s0 += col[j]
            s1 += j * col[j]
            sv += ramp[j]
            s2 += sq[j]
            sn += cnt[j]
            if sn >= full:
                f0 = float(s0)
                fu = float(s1) - u * f0
                fv = float(sv)
                c = f0 * inv_full
                a, b = fu * inv_spread, fv * inv_spread
                if not float(s2) - f0 * c - (fu * a + fv * b) > tol2 * c * c:
                    nx, ny, nz, norm = _camera_normal(u, v, a * unit, b * unit, c * unit,
                                                      params)
                    if norm > 0:
                        k = 1.0 / norm
                        out[v, u, 0] = nx * k
                        out[v, u, 1] = ny * k
                        out[v, u, 2] = nz * k
                    reach[v, u] = norm
            i = u - r
            s0 -= col[i]
            s1 -= i * col[i]
            sv -= ramp[i]
            s2 -= sq[i]
            sn -= cnt[i]


@kernel
def _fixed_point(inv: np.ndarray, rim: np.ndarray, scale: float, row0: int, row1: int,
                 fixed: np.ndarray) -> None:
    """Rows ``row0:row1`` of the (H, W) int32 fixed-point inverse depth ``round(inv *
    scale)`` of the valid non-rim pixels, 0 elsewhere."""
    for v in range(row0, row1):
        for u in range(inv.shape[1]):
            ok = inv[v, u] > 0 and not rim[v, u]
            fixed[v, u] = np.int32(inv[v, u] * scale + 0.5) if ok else np.int32(0)


@inline
def _own_slope(inv: np.ndarray, rim: np.ndarray, v: int, u: int) -> float:
    """Step of inverse depth per pixel at ``(v, u)``: per axis the smaller one-sided step to
    a valid non-rim neighbour, the larger of the two axes (0 if unknown). See also
    :func:`_relative_slope`, the gated method's float32 twin on components; each keeps its
    own arithmetic for its method's bits."""
    h, w = inv.shape
    best = 0.0
    for dv, du in ((0, 1), (1, 0)):
        smaller = np.inf
        for sign in (-1, 1):
            y, x = v + sign * dv, u + sign * du
            if 0 <= y < h and 0 <= x < w and inv[y, x] > 0 and not rim[y, x]:
                smaller = min(smaller, abs(float(inv[y, x]) - float(inv[v, u])))
        if smaller != np.inf:
            best = max(best, smaller)
    return best


@kernel
def _box_band(inv: np.ndarray, rim: np.ndarray, reach: np.ndarray, params: np.ndarray,
              k_inv: np.ndarray, radius: int, r: int, stride: int, min_support: int,
              row0: int, row1: int, out: np.ndarray) -> None:
    """Normals of the valid pixels of rows ``row0:row1`` without a box fit of their own.

    Such a pixel lies in the window of every box-fitted pixel within ``radius`` (Chebyshev),
    so on that window's one surface. It takes the normal of one of them, on the offsets
    ``{0, ±radius/2}²`` or else ``{0, ±radius}²``: the one whose plane predicts its inverse
    depth ``-(n · ray) / d`` best, within ``max_jump`` (on a crease, its own face). A pixel
    without one (a rim pixel, a sliver narrower than a window) fits the samples of its
    ``(2r+1)²`` window every ``stride`` pixels by the gated rule without the components:
    within ``max_jump`` of its own inverse depth, plus (off the rim) its own relative slope
    per pixel of offset. ``k_inv`` is (3, 3) float64 ``K^-1``; ``reach`` (``1 / d``) and
    ``out`` hold the box fits. Every pixel of the rows without a box fit is written to
    ``out``, 0 where it gets no normal (holes included).
    """
    h, w = inv.shape
    max_jump = params[0]
    half = max(radius // 2, 1)
    for v in range(row0, row1):
        for u in range(w):
            if reach[v, u] > 0:  # a box fit of its own
                continue
            # Every other pixel is written here (zero unless it gets a normal), so ``out``
            # needs no zeroing pass before the box fits.
            out[v, u, 0] = out[v, u, 1] = out[v, u, 2] = 0
            p = inv[v, u]
            if not p > 0:
                continue
            # The ray of this pixel
            hx = k_inv[0, 0] * u + k_inv[0, 1] * v + k_inv[0, 2]
            hy = k_inv[1, 0] * u + k_inv[1, 1] * v + k_inv[1, 2]
            hz = k_inv[2, 0] * u + k_inv[2, 1] * v + k_inv[2, 2]
            # The inner ring first, then the outer one, in raster order (a tie goes to the
            # later offset); the border tests only for pixels near the image border.
            best, py, px = max_jump * p, -1, -1
            inside = radius <= v < h - radius and radius <= u < w - radius
            for ring in (half, radius):
                if py >= 0:  # the inner ring had one
                    break
                for dv in (-ring, 0, ring):
                    y = v + dv
                    if not inside and (y < 0 or y >= h):
                        continue
                    for du in (-ring, 0, ring):
                        x = u + du
                        if (dv == 0 and du == 0) or not inside and (x < 0 or x >= w):
                            continue
                        q = reach[y, x]
                        if not q > 0:
                            continue
                        dot = out[y, x, 0] * hx + out[y, x, 1] * hy + out[y, x, 2] * hz
                        miss = abs(dot * q + p)  # |predicted - p|, predicted = -dot / d
                        if miss <= best:
                            best, py, px = miss, y, x
            if py >= 0:
                for c in range(3):
                    out[v, u, c] = out[py, px, c]
                continue
            # Samples within max_jump of the pixel's inverse depth, plus (off the rim) its
            # own relative slope per pixel of offset, e = w / w_p - 1 (the gated fit's rule
            # without the components), accumulated with 0/1 weights.
            to_e = 1.0 / p
            slope = 0.0 if rim[v, u] else _own_slope(inv, rim, v, u) * to_e
            cnt = su = sv = suu = suv = svv = ru = rv = r1 = 0.0
            lo_u = u - r if u >= r else u - r + ((r - u + stride - 1) // stride) * stride
            for dv in range(-r, r + 1, stride):
                y = v + dv
                if y < 0 or y >= h:
                    continue
                fv = float(dv)
                for x in range(lo_u, min(u + r, w - 1) + 1, stride):
                    e = inv[y, x] * to_e - 1.0
                    tol = max_jump + slope * max(abs(x - u), abs(dv), 1)
                    keep = 1.0 if inv[y, x] > 0 and abs(e) <= tol else 0.0
                    # _valid_offsets' moments in float, in this order for the bits, plus the
                    # residual sums.
                    fu = float(x - u)
                    cnt += keep
                    su += keep * fu
                    sv += keep * fv
                    suu += keep * fu * fu
                    suv += keep * fu * fv
                    svv += keep * fv * fv
                    ru += keep * e * fu
                    rv += keep * e * fv
                    r1 += keep * e
            a, b, c0, good = _line_fit(cnt, su, sv, suu, suv, svv, ru, rv, r1, min_support,
                                       stride)
            if good:
                _store_normal(out, v, u, a, b, 1.0 + c0, params)
