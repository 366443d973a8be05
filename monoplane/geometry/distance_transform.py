"""The exact Euclidean distance transform of a binary image, as the nearest True pixel of every
pixel: how labels of a subsampled frame reach the pixels left out
(:meth:`monoplane.geometry.cloud.PlaneCloud.image_nearest_sample`)."""

from __future__ import annotations

import numpy as np

from monoplane.jit import kernel


def nearest_true_pixel(mask: np.ndarray) -> np.ndarray:
    """Flat index of the nearest True pixel of every pixel (exact Euclidean distance transform).

    Parameters
    ----------
    mask : numpy.ndarray
        (H, W) bool image with at least one True pixel.

    Returns
    -------
    numpy.ndarray
        (H * W,) int64 flat index ``v * W + u`` of a True pixel at the smallest Euclidean
        distance (ties broken arbitrarily), -1 everywhere when ``mask`` has no True pixel.
    """
    return _nearest_true_pixel(np.ascontiguousarray(mask, dtype=np.bool_))


@kernel
def _nearest_true_pixel(mask: np.ndarray) -> np.ndarray:
    """:func:`nearest_true_pixel`: per column the nearest True row, then per row the lower
    envelope of the parabolas (x - x')² + dy(x')² (Felzenszwalb and Huttenlocher)."""
    h, w = mask.shape
    far = np.inf
    row = np.empty((h, w), dtype=np.int64)  # nearest True row in the pixel's column
    dy2 = np.full((h, w), far)
    last = np.full(w, -1, dtype=np.int64)
    for y in range(h):  # row by row, all columns at once (memory order)
        for x in range(w):
            if mask[y, x]:
                last[x] = y
            row[y, x] = last[x]
    last[:] = -1
    for y in range(h - 1, -1, -1):
        for x in range(w):
            if mask[y, x]:
                last[x] = y
            up, down = row[y, x], last[x]
            if down >= 0 and (up < 0 or down - y < y - up):
                row[y, x] = down
            if row[y, x] >= 0:
                dy2[y, x] = (row[y, x] - y) ** 2
    out = np.full(h * w, -1, dtype=np.int64)
    v = np.empty(w, dtype=np.int64)
    z = np.empty(w + 1)
    for y in range(h):
        k = -1
        for q in range(w):
            fq = dy2[y, q]
            if fq == far:
                continue
            if k < 0:
                k = 0
                v[0] = q
                z[0] = -far
                z[1] = far
                continue
            while True:
                p = v[k]
                s = ((fq + q * q) - (dy2[y, p] + p * p)) / (2.0 * (q - p))
                if s > z[k]:
                    break
                k -= 1
            k += 1
            v[k] = q
            z[k] = s
            z[k + 1] = far
        if k < 0:
            continue
        k = 0
        for x in range(w):
            while z[k + 1] < x:
                k += 1
            out[y * w + x] = row[y, v[k]] * w + v[k]
    return out
