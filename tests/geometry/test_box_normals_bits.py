"""The box method of normals from depth gives the same bits as the kernels it was before the
ninth round of issue 35, kept below as the reference: on random depth with holes, NaN, inf and
jumps, on windows cut by the image border, on the living-room frames and the three real sensor
frames, at 1, 2 and 3 threads."""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
import pytest

from monoplane.datamodel import default_intrinsics, intrinsics_matrix
from monoplane.geometry import normal_kernels
from monoplane.geometry.normals import _ONE_SURFACE_RMS, _discontinuities, normals_from_depth
from monoplane.jit import _with_helpers

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"

# The shared helpers as the library compiles them (with the helpers they call in turn).
_line_fit = numba.njit(inline="always")(_with_helpers(normal_kernels._line_fit))
_camera_normal = numba.njit(inline="always")(_with_helpers(normal_kernels._camera_normal))


@numba.njit(inline="always")
def _store_normal(out: np.ndarray, v: int, u: int, grad_u: float, grad_v: float, value: float,
                  params: np.ndarray) -> None:
    if not value > 0:
        return
    nx, ny, nz, norm = _camera_normal(u, v, grad_u, grad_v, value, params)
    if norm > 0:
        out[v, u, 0] = nx / norm
        out[v, u, 1] = ny / norm
        out[v, u, 2] = nz / norm


# --- The reference: monoplane/geometry/normal_kernels.py's box kernels at a627dc0 ---

@numba.njit(cache=True, nogil=True)
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


@numba.njit(cache=True, nogil=True)
def _fixed_point(inv: np.ndarray, rim: np.ndarray, scale: float, row0: int, row1: int,
                 fixed: np.ndarray) -> None:
    """Rows ``row0:row1`` of the (H, W) int32 fixed-point inverse depth ``round(inv *
    scale)`` of the valid non-rim pixels, 0 elsewhere."""
    for v in range(row0, row1):
        for u in range(inv.shape[1]):
            ok = inv[v, u] > 0 and not rim[v, u]
            fixed[v, u] = np.int32(inv[v, u] * scale + 0.5) if ok else np.int32(0)


@numba.njit(inline="always")
def _own_slope(inv: np.ndarray, rim: np.ndarray, v: int, u: int) -> float:
    """Step of inverse depth per pixel at ``(v, u)``: per axis the smaller one-sided step to
    a valid non-rim neighbour, the larger of the two axes (0 if unknown)."""
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


@numba.njit(cache=True, nogil=True)
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
    ``out`` hold the box fits.
    """
    h, w = inv.shape
    max_jump = params[0]
    # The inner ring first, then the outer one.
    half = max(radius // 2, 1)
    offsets = np.empty((16, 2), np.int64)
    k = 0
    for ring in (half, radius):
        for dv in (-ring, 0, ring):
            for du in (-ring, 0, ring):
                if dv != 0 or du != 0:
                    offsets[k, 0], offsets[k, 1] = dv, du
                    k += 1
    for v in range(row0, row1):
        for u in range(w):
            p = inv[v, u]
            if not p > 0 or reach[v, u] > 0:
                continue
            # The ray of this pixel
            hx = k_inv[0, 0] * u + k_inv[0, 1] * v + k_inv[0, 2]
            hy = k_inv[1, 0] * u + k_inv[1, 1] * v + k_inv[1, 2]
            hz = k_inv[2, 0] * u + k_inv[2, 1] * v + k_inv[2, 2]
            best, pick = max_jump * p, -1
            for k in range(offsets.shape[0]):
                if k == 8 and pick >= 0:  # the inner ring had one
                    break
                y, x = v + offsets[k, 0], u + offsets[k, 1]
                if y < 0 or y >= h or x < 0 or x >= w or not reach[y, x] > 0:
                    continue
                dot = out[y, x, 0] * hx + out[y, x, 1] * hy + out[y, x, 2] * hz
                miss = abs(dot * reach[y, x] + p)  # |predicted - p|, predicted = -dot / d
                if miss <= best:
                    best, pick = miss, k
            if pick >= 0:
                y, x = v + offsets[pick, 0], u + offsets[pick, 1]
                out[v, u, 0], out[v, u, 1], out[v, u, 2] = out[y, x, 0], out[y, x, 1], out[y, x, 2]
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


def reference_box_normals(depth: np.ndarray, K: np.ndarray, radius: int, stride: int,
                          max_jump: float = 0.05, support: int = 4) -> np.ndarray:
    """``normals_from_depth(depth, K, radius=radius, stride=stride, method="box")`` at
    a627dc0, on one thread (its pieces of rows gave the same bits as one piece)."""
    params = np.array([max_jump, *np.asarray(K, np.float64).ravel()])
    inv, rim = _discontinuities(depth.astype(np.float32, copy=False), max_jump)
    top = float(inv.max())
    normals = np.zeros(inv.shape + (3,), dtype=np.float32)
    if not top > 0:
        return normals
    bits = min(24, int((62 - np.log2((2 * radius + 1) * (inv.shape[1] + 1))) // 2))
    scale = float(2.0 ** (bits - np.ceil(np.log2(top))))
    reach = np.zeros(inv.shape, dtype=np.float32)
    fixed = np.empty(inv.shape, dtype=np.int32)
    h = inv.shape[0]
    _fixed_point(inv, rim, scale, 0, h, fixed)
    _box_planes(fixed, radius, scale, _ONE_SURFACE_RMS, params, 0, h, reach, normals)
    stride = max(stride, radius // 2)
    r = radius - radius % stride
    _box_band(inv, rim, reach, params, np.linalg.inv(K), radius, r, stride, support, 0, h,
              normals)
    return normals


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal arrays to the bit (signed zeros included)."""
    return a.dtype == b.dtype and np.array_equal(a.view(np.uint32), b.view(np.uint32))


def random_depth(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """Tilted planes with depth jumps between them, sensor-like noise quantised to mm, holes
    (0, NaN, inf) in blobs and specks, and a cluster of 1-pixel flyers."""
    K = default_intrinsics(w, h)
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], -1)
    depth = np.full((h, w), 3.0)
    for _ in range(6):
        n = rng.normal(size=3)
        n[2] = -abs(n[2]) - 0.5
        n /= np.linalg.norm(n)
        d = rng.uniform(0.8, 4.0)
        region = (rng.uniform(-1, 1) * u + rng.uniform(-1, 1) * v
                  > rng.uniform(-0.5, 1.0) * (h + w) / 2)
        z = np.clip(-d / np.minimum(rays @ n, -0.05), 0.3, 8.0)
        depth = np.where(region, z, depth)
    depth += rng.normal(scale=0.0015, size=depth.shape) * depth ** 2
    depth = np.round(depth, 3).astype(np.float32)
    for _ in range(4):
        y, x, s = rng.integers(0, h), rng.integers(0, w), rng.integers(1, 12)
        depth[max(y - s, 0):y + s, max(x - s, 0):x + s] = 0.0
    specks = rng.random(depth.shape)
    depth[specks < 0.02] = 0.0
    depth[specks > 0.995] = np.nan
    depth[(specks > 0.99) & (specks <= 0.995)] = np.inf
    depth[(specks > 0.98) & (specks <= 0.99)] *= 1.5
    return depth


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("radius,stride", [(6, 2), (3, 1), (9, 3), (4, 4), (1, 1), (2, 1)])
def test_random_depth_gives_the_reference_bits(seed: int, radius: int, stride: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = (int(x) for x in rng.integers(40, 140, size=2))
    depth = random_depth(rng, h, w)
    K = default_intrinsics(w, h)
    new = normals_from_depth(depth, K, radius=radius, stride=stride, method="box")
    assert same_bits(new, reference_box_normals(depth, K, radius, stride))
    assert (np.abs(new).sum(-1) > 0).mean() > 0.5  # planes, not all holes


@pytest.mark.parametrize("shape", [(9, 200), (200, 9), (13, 13), (12, 40)])
def test_images_narrower_than_a_window_give_the_reference_bits(shape: tuple[int, int]) -> None:
    # A 13x13 window (radius 6): rows or columns without a whole window get band fits only.
    h, w = shape
    depth = random_depth(np.random.default_rng(7), h, w)
    K = default_intrinsics(w, h)
    new = normals_from_depth(depth, K, radius=6, stride=2, method="box")
    assert same_bits(new, reference_box_normals(depth, K, 6, 2))


def test_depth_without_a_valid_pixel_gives_zero_normals() -> None:
    depth = np.zeros((30, 40), np.float32)
    depth[3, 4] = np.nan
    normals = normals_from_depth(depth, default_intrinsics(40, 30), method="box")
    assert same_bits(normals, np.zeros((30, 40, 3), np.float32))


def _sensor_frames() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """Two living-room frames (mm / 1000) and the TUM, SUN RGB-D and NYU frames, with the
    intrinsics the benches give them."""
    from monoplane.io.frames import read_depth

    K = intrinsics_matrix(525.0, 525.0, 319.5, 239.5)
    frames = []
    for name in ("00000.png", "00052.png"):
        path = SHARED / "icl-livingroom-dev" / "depth" / name
        if path.is_file():
            frames.append((name, read_depth(path, 1000.0), K))
    real = SHARED / "rgbd-real-frames"
    for name, encoding in (("TUM_depth.png", "tum"), ("SUN_depth.png", "sun-rotated"),
                           ("NYU_depth.pgm", "kinect-disparity")):
        if (real / name).is_file():
            frames.append((name, read_depth(real / name, depth_encoding=encoding), K))
    if not frames:
        pytest.skip(f"no sensor frames under {SHARED}")
    return frames


@pytest.mark.parametrize("threads", ["1", "2", "3"])
def test_sensor_frames_give_the_reference_bits(monkeypatch: pytest.MonkeyPatch,
                                               threads: str) -> None:
    monkeypatch.setenv("OMP_NUM_THREADS", threads)
    for name, depth, K in _sensor_frames():
        new = normals_from_depth(depth, K, method="box")
        assert same_bits(new, reference_box_normals(depth, K, 6, 2)), name


def test_every_pixel_is_written_without_a_zeroed_buffer(monkeypatch: pytest.MonkeyPatch) -> None:
    # The box method allocates its normals uninitialised: the box fits and _box_band must
    # write every pixel between them. NaN-filled buffers show any pixel they miss.
    depth = random_depth(np.random.default_rng(11), 90, 120)
    K = default_intrinsics(120, 90)
    expected = reference_box_normals(depth, K, 6, 2)
    full = np.full

    def garbage(shape, dtype=float):  # NaN in float buffers, ones in the others
        return full(shape, np.nan if np.dtype(dtype).kind == "f" else 1, dtype)

    monkeypatch.setattr(np, "empty", garbage)
    assert same_bits(normals_from_depth(depth, K, radius=6, stride=2, method="box"), expected)
