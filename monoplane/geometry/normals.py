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
   equal however steep it is. The nearer pixel of the pair (the larger inverse depth) is a
   *rim* pixel;
2. valid, non-rim pixels are split into 4-connected components, which the rims separate;
3. a non-rim pixel fits only neighbours of its own component whose relative inverse-depth
   difference stays within ``max_jump`` plus its own local step per pixel of offset (this also
   catches edges that do not close a component); a rim pixel fits only neighbours within
   ``max_jump`` of its own depth, which excludes the farther side.

Windows that provably see one surface (no rim, one component, small depth range: exact
window maxima, :mod:`monoplane.geometry.one_surface_windows`) are fitted from window sums of
the masked moments, taken for the whole image at once with separable filters; only the band
near depth edges goes through the per-neighbour gating above. The discontinuities, the
one-surface test and the fits are compiled kernels (:mod:`monoplane.jit`) split by rows over
the frame's threads, and the components share the threads with the filters: at 640x480 with
the defaults they take about a quarter of the CPU time of the NumPy version they replaced
(same decisions, normals equal to float rounding), and the ninth round's reorganisation
returns the same bits again (docs/evaluation.md).

``method="box"`` (the default's choice, ``"auto"``, on a sensor's metric depth:
:func:`fit_method`) skips the components, the separable filters and most of the
per-neighbour gating. A pixel's whole window (every pixel, no stride) is *one surface* when
it lies in the image, holds valid non-rim samples only and its inverse depth follows one line
to ``_ONE_SURFACE_RMS`` (relative RMS); its fit comes from window sums of fixed-point inverse
depth, which are exact integers, so they can run from one row and column to the next (O(1)
per pixel) and do not depend on the thread split. A pixel
without such a window of its own lies in the window of nearby ones that have one: it takes
the normal of the one, among 16 offsets within ``radius``, whose plane predicts its inverse
depth best (within ``max_jump``). What is left (rim pixels, slivers narrower than a window)
is fitted sample by sample as in 3., without the components. About half the gated method's
CPU at 640x480 since the ninth round's speed-up of the gated fit; on noisy sensor depth its
normals are closer to the truth (docs/design.md, "Depth-only sensor frames").

Holes (depth 0, NaN or inf) contribute nothing and get a zero normal. Pixels without enough
well-spread support (fewer than ``min_support`` accepted neighbours, or all on a line) get a
zero normal too, which downstream code treats as invalid.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

import cv2
import numpy as np

from monoplane.errors import InvalidInput
from monoplane.geometry.normal_kernels import (
    _box_band,
    _box_planes,
    _fit_band,
    _fit_interior,
    _fixed_point,
    _inverse_depth,
    _rims,
)
from monoplane.geometry.one_surface_windows import _one_surface
from monoplane.jit import chunks, run_threaded

#: The fitting methods of :func:`normals_from_depth`.
NORMALS_METHODS = ("gated", "box")

#: What a cue stage's ``normals_method`` may name: a fitting method, or ``"auto"``
#: (:func:`fit_method`).
NORMALS_CHOICES = ("auto", *NORMALS_METHODS)

#: The ``normals_method`` of every cue stage that does not state one: its config default and
#: what :func:`cue_normals_from_depth` uses when the options name no method.
DEFAULT_NORMALS_METHOD = "auto"

#: Rows of the image per threaded piece of the fit below which one thread does it all.
_THREADED_ROWS = 64

#: Pieces of rows per thread for the fits near depth edges, whose cost is uneven over rows.
_PIECES = 4

#: Relative RMS of inverse depth about its fitted line above which a box window is taken to
#: hold more than one surface (a crease, a blurred edge) and is not fitted.
_ONE_SURFACE_RMS = 0.0125


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


def fit_method(choice: str, measured: bool) -> str:
    """The fitting method of :func:`normals_from_depth` that a cue stage's ``normals_method``
    names for one depth map.

    ``"auto"`` is ``"box"`` on a sensor's metric depth (``measured``) and ``"gated"`` on a
    network's or a relative depth. On sensor depth the box fit is the more accurate (median
    error 3.0° against 5.2° on Kinect-like noise) and faster (8-9 against 12-16 ms wall at
    640x480); the network-cue tables were measured with the gated fit (docs/design.md,
    "Depth-only sensor frames").

    Parameters
    ----------
    choice : {"auto", "gated", "box"}
        The configured value.
    measured : bool
        Whether the depth is a sensor's metric measurement
        (:attr:`monoplane.datamodel.Frame.depth_measured`).

    Returns
    -------
    str
        One of :data:`NORMALS_METHODS`.
    """
    if choice != "auto":
        return choice
    return "box" if measured else "gated"


def cue_normals_from_depth(depth: np.ndarray, K: np.ndarray, options: Mapping[str, Any],
                           measured: bool) -> tuple[np.ndarray, str]:
    """A cue stage's normals from one depth map, with the frame note that says how.

    Resolves the options' ``method`` (default :data:`DEFAULT_NORMALS_METHOD`) for this depth
    map with :func:`fit_method`, then runs :func:`normals_from_depth`.

    Parameters
    ----------
    depth : numpy.ndarray
        (H, W) z-depth (see :func:`normals_from_depth`).
    K : numpy.ndarray
        (3, 3) pinhole intrinsics in pixels.
    options : mapping
        Keyword arguments of :func:`normals_from_depth`, whose ``method`` may also be
        ``"auto"`` or missing (a cue stage's ``normals_options()``); not modified.
    measured : bool
        Whether the depth is a sensor's metric measurement
        (:attr:`monoplane.datamodel.Frame.depth_measured`).

    Returns
    -------
    normals : numpy.ndarray
        (H, W, 3) float32 unit normals, camera frame, as :func:`normals_from_depth` returns.
    note : str
        The frame note naming the fitting method used.
    """
    kwargs = dict(options)
    method = fit_method(kwargs.pop("method", DEFAULT_NORMALS_METHOD), measured)
    normals = normals_from_depth(depth, K, method=method, **kwargs)
    return normals, f"normals: estimated from depth (edge-aware inverse-depth fits, {method})"


def normals_from_depth(depth: np.ndarray, K: np.ndarray, *, radius: int | None = None,
                       stride: int | None = None, max_jump: float = 0.05,
                       min_support: int = 4, method: str = "gated") -> np.ndarray:
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
    method : {"gated", "box"}
        ``"gated"``: every pixel near a depth edge fits its window samples one by one,
        gated to its own side. ``"box"``: full windows of one surface are fitted from
        exact window sums over every pixel (``stride`` unused there), and a pixel near an
        edge takes the plane of a nearby such window that holds it (see the module notes);
        faster, as accurate on planes.

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
    if method not in NORMALS_METHODS:
        raise InvalidInput(f"method must be one of {', '.join(NORMALS_METHODS)}, got {method!r}")
    params = np.array([max_jump, K[0, 0], K[0, 1], K[0, 2], K[1, 0], K[1, 1], K[1, 2],
                       K[2, 0], K[2, 1], K[2, 2]], dtype=np.float64)
    support = max(min_support, 3)
    if method == "box":
        return _box_normals(depth, max_jump, params, K, radius, stride, support,
                            _ONE_SURFACE_RMS)
    return _gated_normals(depth, max_jump, params, radius, stride, support)


def _gated_normals(depth: np.ndarray, max_jump: float, params: np.ndarray, radius: int,
                   stride: int, support: int) -> np.ndarray:
    """The ``gated`` method of :func:`normals_from_depth`."""
    z = np.where(np.isfinite(depth), depth, 0).astype(np.float32, copy=False)
    inv, rim = _discontinuities(z, max_jump)
    valid = z > 0
    r = radius - radius % stride
    # Window sums: full-footprint kernels with zero taps between the strided samples; zero
    # padding outside the image acts like holes.
    steps = np.arange(-r, r + 1, stride)
    one = np.zeros(2 * r + 1, dtype=np.float32)
    one[steps + r] = 1.0
    ramp = one * np.arange(-r, r + 1, dtype=np.float32)
    sums = np.empty((4,) + z.shape, dtype=np.float32)
    filters: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = [
        (valid.view(np.uint8), one, one), (inv, ramp, one), (inv, one, ramp), (inv, one, one)]
    # The components (4-connected, of the valid non-rim pixels; only equality of labels
    # matters) and the four filters are independent OpenCV calls, which release the GIL: they
    # share the threads, the components first since they take longest.
    labels = run_threaded([
        functools.partial(_components, valid & ~rim),
        *(functools.partial(cv2.sepFilter2D, img, cv2.CV_32F, kx, ky, dst=sums[k],
                            borderType=cv2.BORDER_CONSTANT)
          for k, (img, kx, ky) in enumerate(filters))])[0]
    # A window without rims, with a single component and a small depth range cannot mix
    # surfaces, so its masked fit reduces to the sums above. Only the band near depth edges
    # needs per-neighbour gating.
    interior = np.empty(z.shape, dtype=np.bool_)
    band = np.empty(z.shape, dtype=np.bool_)
    run_threaded([functools.partial(_one_surface, z, labels, rim, r, float(max_jump), a, b,
                                    interior, band)
                  for a, b in chunks(z.shape[0], _THREADED_ROWS)])
    normals = np.zeros(z.shape + (3,), dtype=np.float32)

    def fit(a: int, b: int) -> None:
        _fit_interior(inv, interior, sums, params, r, stride, support, a, b, normals)
        _fit_band(inv, labels, rim, band, params, r, stride, support, a, b, normals)

    # The band's cost follows the depth edges: smaller pieces keep the threads busy alike.
    run_threaded([functools.partial(fit, a, b)
                  for a, b in chunks(z.shape[0], _THREADED_ROWS // _PIECES, _PIECES)])
    return normals


def _components(mask: np.ndarray) -> np.ndarray:
    """(H, W) int32 labels of the 4-connected components of the (H, W) bool ``mask``, 0
    off it."""
    return cv2.connectedComponents(mask.view(np.uint8), connectivity=4, ltype=cv2.CV_32S)[1]


def _discontinuities(z: np.ndarray, max_jump: float) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) float32 inverse depth (0 on holes) and bool rim mask (the near side of each
    depth discontinuity, :func:`~monoplane.geometry.normal_kernels._rims`) of (H, W) float32
    depth ``z``, in pieces of rows on the frame's threads."""
    inv = np.empty(z.shape, dtype=np.float32)
    rim = np.empty(z.shape, dtype=np.bool_)
    pieces = chunks(z.shape[0], _THREADED_ROWS)
    run_threaded([functools.partial(_inverse_depth, z, a, b, inv) for a, b in pieces])
    run_threaded([functools.partial(_rims, inv, float(max_jump), a, b, rim) for a, b in pieces])
    return inv, rim


def _box_normals(depth: np.ndarray, max_jump: float, params: np.ndarray, K: np.ndarray,
                 radius: int, stride: int, support: int, tol: float) -> np.ndarray:
    """The ``box`` method of :func:`normals_from_depth`."""
    # Holes need no zeroing here: the inverse depth of 0, NaN and inf is 0 either way.
    inv, rim = _discontinuities(depth.astype(np.float32, copy=False), max_jump)
    top = float(inv.max())
    if not top > 0:
        return np.zeros(inv.shape + (3,), dtype=np.float32)
    # 2^bits steps up to the largest inverse depth, with 2^(2 bits) * (2 radius + 1) * (W + 1)
    # below 2^62: it bounds every int64 sum (the widest, a window's Σ u' × column sum, is
    # below 2^bits (2 radius + 1)² W), so none overflows: 24 bits at 640x480, 22 at 1920x1080.
    bits = min(24, int((62 - np.log2((2 * radius + 1) * (inv.shape[1] + 1))) // 2))
    scale = float(2.0 ** (bits - np.ceil(np.log2(top))))
    reach = np.zeros(inv.shape, dtype=np.float32)
    # Not zeroed: the box fits write their pixels, :func:`_box_band` every other one.
    normals = np.empty(inv.shape + (3,), dtype=np.float32)
    fixed = np.empty(inv.shape, dtype=np.int32)
    pieces = chunks(inv.shape[0], _THREADED_ROWS)
    run_threaded([functools.partial(_fixed_point, inv, rim, scale, a, b, fixed)
                  for a, b in pieces])
    run_threaded([functools.partial(_box_planes, fixed, radius, scale, tol, params, a, b,
                                    reach, normals) for a, b in pieces])
    # The pixels left to the per-sample fit are few but slow (a sample costs as much as a
    # whole box fit): a sparser grid, every r/2 pixels.
    stride = max(stride, radius // 2)
    r = radius - radius % stride
    k_inv = np.linalg.inv(K)
    # Their cost follows the depth edges, which a frame may hold mostly in one half: smaller
    # pieces, handed to whichever thread is free, keep the threads busy alike.
    run_threaded([functools.partial(_box_band, inv, rim, reach, params, k_inv, radius, r,
                                    stride, support, a, b, normals)
                  for a, b in chunks(inv.shape[0], _THREADED_ROWS // _PIECES, _PIECES)])
    return normals
