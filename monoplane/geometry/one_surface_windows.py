"""Which pixels of a depth map have a fitting window that cannot mix surfaces: the compiled
split of :mod:`monoplane.geometry.normals`' gated method into the pixels fitted from window
sums and the band near depth edges fitted sample by sample.

The tests are window maxima (no float sums), so they are exact whatever the order of the
passes and the rows each thread takes.
"""

from __future__ import annotations

import numpy as np

from monoplane.jit import inline, kernel


@kernel
def _one_surface(z: np.ndarray, labels: np.ndarray, rim: np.ndarray, r: int, max_jump: float,
                 row0: int, row1: int, interior: np.ndarray, band: np.ndarray) -> None:
    """Rows ``row0:row1`` of the (H, W) bool masks ``interior`` and ``band`` of the valid
    pixels (``z > 0``) of the (H, W) float32 depth ``z``.

    A valid pixel is ``interior`` when its ``(2r+1)²`` window (every pixel, cut by the image
    border) cannot mix surfaces: it holds no ``rim`` pixel, the positive ``labels`` ((H, W)
    int32 components of the valid non-rim pixels, 0 elsewhere) in it are all the same, and
    its largest depth divided by ``1 + max_jump r`` (float32) is at most its smallest valid
    depth. The other valid pixels are the ``band``.

    The first two tests are one: the largest of a key that is the label, or the largest
    int32 on a rim, equals the smallest of a key that is the label, the largest int32 on a
    hole, or -1 on a rim, exactly when the window has no rim and one label. Smallest values
    are taken as largest of the negated ones, so the four extremes are window maxima:
    separable, exact, and the same whatever rows a thread takes. Each image row's maxima
    along the row are taken once, into a ring of the ``2r + 1`` rows a window spans (small
    enough to stay in cache), and each output row takes the maxima down that ring.
    """
    h, w = z.shape
    size = 2 * r + 1
    m = w + 2 * r
    scale = np.float32(1.0 + max_jump * r)
    # Blocks of output rows; each holds the maxima along the rows of the rows its windows
    # reach (padded by r values on each side, and rows off the image, that change no
    # maximum), then down the columns in place: row i becomes output row block + i.
    block = 64
    hi = np.empty((block + 2 * r, m), np.int32)
    lo = np.empty((block + 2 * r, m), np.int32)
    zhi = np.empty((block + 2 * r, m), np.float32)
    zlo = np.empty((block + 2 * r, m), np.float32)
    spare_i = np.empty((block + 2 * r) * m, np.int32)
    spare_f = np.empty((block + 2 * r) * m, np.float32)
    big = np.int32(2 ** 31 - 1)
    low = np.float32(-np.inf)
    for v0 in range(row0, row1, block):
        v1 = min(v0 + block, row1)
        rows = v1 - v0 + 2 * r
        for i in range(rows):
            y = v0 - r + i
            if 0 <= y < h:
                _row_maxima(z, labels, rim, y, r, hi[i], lo[i], zhi[i], zlo[i], spare_i,
                            spare_f)
            else:
                hi[i, :], lo[i, :], zhi[i, :], zlo[i, :] = 0, -big, low, low
        n = rows * m
        _window_max(hi.reshape(-1)[:n], spare_i, size, m)
        _window_max(lo.reshape(-1)[:n], spare_i, size, m)
        _window_max(zhi.reshape(-1)[:n], spare_f, size, m)
        _window_max(zlo.reshape(-1)[:n], spare_f, size, m)
        for v in range(v0, v1):
            i = v - v0
            for u in range(w):
                ok = hi[i, u] == -lo[i, u] and zhi[i, u] / scale <= -zlo[i, u]
                valid = z[v, u] > 0
                interior[v, u] = valid and ok
                band[v, u] = valid and not ok


@inline
def _row_maxima(z: np.ndarray, labels: np.ndarray, rim: np.ndarray, y: int, r: int,
                hi: np.ndarray, lo: np.ndarray, zhi: np.ndarray, zlo: np.ndarray,
                spare_i: np.ndarray, spare_f: np.ndarray) -> None:
    """The four keys of :func:`_one_surface` on image row ``y``, each at ``[u + r]`` of its
    1-d buffer (``W + 2r`` long, the ends padded with values that change no maximum), then
    their maxima over the ``2r + 1`` samples from each ``[u]`` on, in place (``spare_i``,
    ``spare_f``: int32 and float32 scratch rows as long)."""
    w = z.shape[1]
    big = np.int32(2 ** 31 - 1)
    low = np.float32(-np.inf)
    for j in range(r):
        hi[j], lo[j], zhi[j], zlo[j] = 0, -big, low, low
        hi[w + r + j], lo[w + r + j], zhi[w + r + j], zlo[w + r + j] = 0, -big, low, low
    for u in range(w):
        lab = labels[y, u]
        on_rim = rim[y, u]
        hi[u + r] = big if on_rim else lab
        lo[u + r] = np.int32(1) if on_rim else (-lab if lab > 0 else -big)
        zhi[u + r] = z[y, u]
        zlo[u + r] = -z[y, u] if z[y, u] > 0 else low
    _window_max(hi, spare_i, 2 * r + 1, 1)
    _window_max(lo, spare_i, 2 * r + 1, 1)
    _window_max(zhi, spare_f, 2 * r + 1, 1)
    _window_max(zlo, spare_f, 2 * r + 1, 1)


@inline
def _window_max(row: np.ndarray, spare: np.ndarray, size: int, unit: int) -> None:
    """``row[j] = max(row[j + unit k] for k < size)`` in place, for every ``j`` whose window
    fits in the 1-d ``row`` (``unit`` 1: along a row; the row length: down the columns of
    rows laid end to end): maxima over windows of 2, 4, 8 ... samples, then of two
    overlapping ones. The passes go from ``row`` to ``spare`` (at least as long) and back,
    each a loop between two arrays that do not overlap, which the compiler vectorises (a loop
    that alternates its source and destination is not)."""
    n = row.shape[0]
    step = 1  # row holds the maxima over windows of `step` samples
    while 4 * step <= size:
        _max_of(row[:n - step * unit], row[step * unit:], spare)
        _max_of(spare[:n - 3 * step * unit], spare[2 * step * unit:], row)
        step *= 4
    if 2 * step <= size:
        _max_of(row[:n - step * unit], row[step * unit:], spare)
        _max_of(spare[:n - (size - step) * unit], spare[(size - 2 * step) * unit:], row)
    elif size > step:
        k = n - (size - step) * unit
        _max_of(row[:k], row[(size - step) * unit:], spare)
        row[:k] = spare[:k]


@inline
def _max_of(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out[j] = max(a[j], b[j])`` over the 1-d ``a`` (``b`` and ``out`` at least as long)."""
    for j in range(a.shape[0]):
        out[j] = max(a[j], b[j])
