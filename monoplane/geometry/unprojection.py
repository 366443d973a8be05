"""A frame's valid pixels unprojected and normalised into the unit ball, and the samples drawn
from them: the compiled passes of :meth:`monoplane.geometry.cloud.PlaneCloud.from_frame`.

Each pass does what a chain of NumPy calls did (mask, ``flatnonzero``, unprojection, fancy
indexing, casts, ``linalg.norm``) in the same floating-point operations, so the cloud is the
same to the bit; what goes is the temporaries and the extra passes over 300 000 pixels.
"""

from __future__ import annotations

import numpy as np

from monoplane.jit import kernel


@kernel
def valid_points(depth: np.ndarray, normals: np.ndarray, k_inv: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """A frame's valid pixels and their points normalised into the unit ball.

    Parameters
    ----------
    depth : numpy.ndarray
        (H, W) float32 z-depth, 0 where invalid.
    normals : numpy.ndarray
        (H, W, 3) float32 normals, all-zero where invalid.
    k_inv : numpy.ndarray
        (3, 3) float64 inverse intrinsics.

    Returns
    -------
    valid : numpy.ndarray
        (H, W) bool, as :attr:`monoplane.datamodel.Frame.valid` gives it.
    pixels : numpy.ndarray
        (V,) int64 flat indices ``v * W + u`` of the valid pixels, ascending.
    points : numpy.ndarray
        (V, 3) float64 normalised points ``(X - center) / scale`` of the camera-frame points
        ``X = z K^-1 [u, v, 1]``.
    center : numpy.ndarray
        (3,) float64 centroid of the camera-frame points.
    scale : float
        Largest distance of a point from ``center`` (0 when all coincide; the points are then
        only centred).
    """
    h, w = depth.shape
    valid = np.empty((h, w), dtype=np.bool_)
    pixels = np.empty(h * w, dtype=np.int64)
    out = np.empty((h * w, 3))
    center = np.zeros(3)
    n = 0
    for v in range(h):
        for u in range(w):
            ok = depth[v, u] > 0 and (normals[v, u, 0] != 0 or normals[v, u, 1] != 0
                                      or normals[v, u, 2] != 0)
            valid[v, u] = ok
            if not ok:
                continue
            pixels[n] = v * w + u
            z = np.float64(depth[v, u])
            for c in range(3):
                x = z * (k_inv[c, 0] * u + k_inv[c, 1] * v + k_inv[c, 2])
                out[n, c] = x
                center[c] += x
            n += 1
    center /= max(n, 1)
    far = 0.0
    for i in range(n):
        d2 = 0.0
        for c in range(3):
            out[i, c] -= center[c]
            d2 += out[i, c] ** 2
        far = max(far, d2)
    scale = np.sqrt(far)
    points = out[:n]
    if scale > 0:
        points /= scale
    return valid, pixels[:n], points, center, scale


@kernel
def drawn_rows(size: int, drawn: np.ndarray) -> np.ndarray:
    """(M,) int64 the distinct ``drawn`` rows of ``range(size)``, ascending (through a mask:
    linear, where sorting the draw is not)."""
    mask = np.zeros(size, dtype=np.bool_)
    for i in drawn:
        mask[i] = True
    out = np.empty(drawn.shape[0], dtype=np.int64)
    m = 0
    for i in range(size):
        if mask[i]:
            out[m] = i
            m += 1
    return out[:m]


@kernel
def lattice_rows(valid: np.ndarray, rows: np.ndarray, cols: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """The valid pixels on a lattice: their rows among the valid pixels and the lattice's
    nodes.

    ``valid`` (H, W) bool; ``rows`` (R,) and ``cols`` (C,) int64 ascending lattice lines.
    Returns the (M,) int64 rank of each valid lattice pixel among the valid pixels in raster
    order (ascending), and the (R, C) int64 node table: the sample (0..M-1) at each lattice
    node, -1 where the node's pixel is not valid.
    """
    h, w = valid.shape
    on_row = np.zeros(h, dtype=np.bool_)
    on_col = np.zeros(w, dtype=np.bool_)
    row_of = np.zeros(h, dtype=np.int64)
    col_of = np.zeros(w, dtype=np.int64)
    for i in range(rows.shape[0]):
        on_row[rows[i]] = True
        row_of[rows[i]] = i
    for j in range(cols.shape[0]):
        on_col[cols[j]] = True
        col_of[cols[j]] = j
    node = np.full((rows.shape[0], cols.shape[0]), -1, dtype=np.int64)
    chosen = np.empty(rows.shape[0] * cols.shape[0], dtype=np.int64)
    rank = 0
    m = 0
    for v in range(h):
        for u in range(w):
            if not valid[v, u]:
                continue
            if on_row[v] and on_col[u]:
                chosen[m] = rank
                node[row_of[v], col_of[u]] = m
                m += 1
            rank += 1
    return chosen[:m], node


@kernel
def gather_samples(chosen: np.ndarray, pixels: np.ndarray, points: np.ndarray,
                   normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The samples' pixels, points and unit normals.

    ``chosen`` (M,) int64 rows of the valid pixels, ``pixels`` (V,) int64 and ``points``
    (V, 3) float64 the valid pixels and their points, ``normals`` (H * W, 3) float32 the
    frame's normals. Returns (M,) int64 pixels, (M, 3) float64 points and (M, 3) float64
    normals, each divided by its float64 length as ``numpy.linalg.norm`` computes it.
    """
    m = chosen.shape[0]
    keep = np.empty(m, dtype=np.int64)
    out = np.empty((m, 3))
    unit = np.empty((m, 3))
    for i in range(m):
        r = chosen[i]
        p = pixels[r]
        keep[i] = p
        out[i, 0], out[i, 1], out[i, 2] = points[r, 0], points[r, 1], points[r, 2]
        n0 = np.float64(normals[p, 0])
        n1 = np.float64(normals[p, 1])
        n2 = np.float64(normals[p, 2])
        norm = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        unit[i, 0], unit[i, 1], unit[i, 2] = n0 / norm, n1 / norm, n2 / norm
    return keep, out, unit
