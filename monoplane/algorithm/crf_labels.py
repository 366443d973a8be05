"""Final full-resolution labels of the dense CRF run on a coarse grid (:mod:`.densecrf`).

Every pixel's label is the argmax over labels of ``message - unary``, with the coarse
messages bilinearly upsampled (``cv2.resize``), or with exact messages at the band pixels
whose upsampled ones leave the two best labels close. Most pixels need not read their
upsampled messages at all: where every coarse cell that the interpolation of a pixel can
draw on has the same best label by a gap larger than anything the pixel's unary can add,
that label wins (:func:`certified_cells`), exactly as the argmax would decide it. The others
interpolate their messages from the coarse cells where they need them
(:func:`bilinear_taps`), with the float32 arithmetic of ``cv2.resize``, instead of reading a
whole upsampled (H, W, L) array.
"""

from __future__ import annotations

import cv2
import numpy as np

from monoplane.jit import inline, kernel

#: Slack of the certificate, relative to the largest coarse message: the float32 bilinear
#: interpolation (weights summing to 1) and the subtraction of the unary round by a few
#: units of 2^-24 of it, far below this.
_SLACK = 1e-3


def certified_cells(coarse: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Which coarse cells decide the labels of their pixels without the upsampled messages.

    A pixel's bilinear interpolation reads coarse cells of the 3 x 3 neighbourhood of its own
    block only. When all of them have the same best label ``a`` and each leads every other
    label by at least ``g``, the interpolated messages lead by ``g`` less the rounding; the
    unary lowers ``a`` against another label by at most ``u_other - u_own`` (at a pixel
    observed with another plane), and by nothing at a pixel observed with ``a`` or a uniform
    one. So the argmax is ``a`` wherever ``g`` beats that by the returned slack.

    Parameters
    ----------
    coarse : numpy.ndarray
        (hs, ws, L) float32 coarse messages (what is upsampled), L >= 2.

    Returns
    -------
    label : numpy.ndarray
        (hs ws,) int64 the label every 3 x 3 neighbourhood (clipped at the border) agrees on,
        -1 where it does not.
    gap : numpy.ndarray
        (hs ws,) float64 the smallest lead of the best label over that neighbourhood.
    slack : float
        What the lead must exceed beyond the unary's advantage.
    """
    hs, ws, num = coarse.shape
    best, lead, largest = _best_two(np.ascontiguousarray(coarse).reshape(-1, num))
    square = np.ones((3, 3), np.uint8)
    # Erosion and dilation pad with +inf and -inf: the minimum and maximum over the window
    # clipped at the border. Labels are small integers, exact in float32.
    grid = best.reshape(hs, ws).astype(np.float32)
    agree = (cv2.erode(grid, square) == cv2.dilate(grid, square)).ravel()
    gap = cv2.erode(lead.reshape(hs, ws), square).ravel()
    label = np.where(agree, best, -1).astype(np.int64)
    return label, gap, _SLACK * (1.0 + largest)


@kernel
def _best_two(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Per row of the (N, L) float32 ``values`` (L >= 2): the first largest entry's index
    (N,) int64, its lead over the second largest (N,) float64 (0 when two share the
    maximum), and the largest magnitude of all, in float64 (exact from float32): what
    ``argmax``, a partition and ``abs().max()`` of the float64 values give, in one pass."""
    n, num = values.shape
    best = np.empty(n, np.int64)
    lead = np.empty(n)
    largest = 0.0
    for i in range(n):
        first = np.float64(values[i, 0])
        arg = 0
        second = -np.inf
        largest = max(largest, abs(first))
        for j in range(1, num):
            v = np.float64(values[i, j])
            largest = max(largest, abs(v))
            if v > first:
                second = first
                first = v
                arg = j
            elif v > second:
                second = v
        best[i] = arg
        lead[i] = first - second
    return best, lead, largest


#: Label counts whose ``cv2.resize`` does not take the arithmetic :func:`bilinear_taps`
#: reproduces (OpenCV has separate code for images of 1, 3 and 4 channels): there the coarse
#: messages are upsampled by ``cv2.resize`` itself.
RESIZED_LABEL_COUNTS = (1, 3, 4)


def bilinear_taps(size: int, coarse_size: int, step: int, clamp_weights: bool
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The two coarse cells and weights that ``cv2.resize(..., INTER_LINEAR)`` of a
    ``coarse_size`` axis to ``coarse_size * step`` gives each of the first ``size`` pixels.

    OpenCV maps pixel ``i`` to the float32 position ``(i + 0.5) * scale - 0.5`` (``scale``
    the float64 ratio of the sizes) and weighs its floor and the next cell by ``1 - f`` and
    ``f``, the float32 fraction. Outside the coarse range the cells are clamped to the edge;
    along the width the weights become ``(1, 0)`` there as well (``clamp_weights``; a copy of
    the edge cell, as ``c * 1 + c * 0`` is ``c``), along the height they stay (measured on
    images of 2 and 5-47 channels: the interpolation of :func:`_interpolate` is then ``cv2``'s bit
    for bit).

    Returns
    -------
    cells : numpy.ndarray
        (size, 2) int64 coarse indices.
    weights : numpy.ndarray
        (size, 2) float32 weights.
    """
    scale = coarse_size / (coarse_size * step)
    pos = ((np.arange(size) + 0.5) * scale - 0.5).astype(np.float32)
    low = np.floor(pos).astype(np.int64)
    frac = (pos - low).astype(np.float32)
    cells = np.clip(np.stack([low, low + 1], axis=1), 0, coarse_size - 1)
    if clamp_weights:
        edge = (low < 0) | (low >= coarse_size - 1)
        frac[edge] = 0.0
        cells[edge, 1] = cells[edge, 0]
    return cells, np.stack([np.float32(1.0) - frac, frac], axis=1)


@inline
def _interpolate(coarse: np.ndarray, rows: np.ndarray, row_w: np.ndarray, cols: np.ndarray,
                 col_w: np.ndarray, y: int, x: int, out: np.ndarray) -> None:
    """Fill the (L,) float32 ``out`` with the coarse messages interpolated at pixel (y, x)
    with the taps of :func:`bilinear_taps`: along the width first, then along the height, in
    float32 (as ``cv2.resize``)."""
    r0, r1, c0, c1 = rows[y, 0], rows[y, 1], cols[x, 0], cols[x, 1]
    b0, b1, a0, a1 = row_w[y, 0], row_w[y, 1], col_w[x, 0], col_w[x, 1]
    for label in range(out.shape[0]):
        top = coarse[r0, c0, label] * a0 + coarse[r0, c1, label] * a1
        bottom = coarse[r1, c0, label] * a0 + coarse[r1, c1, label] * a1
        out[label] = top * b0 + bottom * b1


@inline
def _unary(label: int, observed: int, u_own: np.float32, u_other: np.float32,
           u_uniform: np.float32, uniform_nonplanar: bool) -> np.float32:
    """The unary of ``label`` at a pixel observed with label ``observed`` (see
    :func:`upsampled_labels`)."""
    if uniform_nonplanar and observed == 0:
        return u_uniform
    return u_own if label == observed else u_other


@kernel
def upsampled_labels(coarse: np.ndarray, rows: np.ndarray, row_w: np.ndarray,
                     cols: np.ndarray, col_w: np.ndarray, fine: np.ndarray,
                     labels: np.ndarray, band: np.ndarray,
                     u_own: np.float32, u_other: np.float32, u_uniform: np.float32,
                     uniform_nonplanar: bool, margin: float, cell_label: np.ndarray,
                     cell_gap: np.ndarray, step: int, easy_gap: float,
                     hard_gap: float, y0: int, y1: int, out: np.ndarray,
                     close: np.ndarray) -> None:
    """Rows ``y0:y1`` of the (H, W) int32 ``out``: argmax over labels of ``message - unary``
    at full resolution with the upsampled messages, and at the ``band`` pixels in these rows
    whether the two best labels lie less than ``margin`` nats apart (``close``).

    The upsampled messages are interpolated from the (hs, ws, L) float32 ``coarse`` ones
    with the taps of :func:`bilinear_taps` (``rows`` and ``row_w`` (≥H, 2) along the height,
    ``cols`` and ``col_w`` (≥W, 2) along the width) when ``fine`` is empty (0, 0, L); else
    they are read from ``fine`` (≥H, ≥W, L) float32, ``cv2.resize``'s upsampling, and the
    taps are not read. ``labels`` (H, W) int32 observed
    labels, ``band`` (K,) int64 ascending flat pixels, ``close`` (K,) bool; the unary of a
    pixel is ``u_own`` at its label and ``u_other`` elsewhere, or ``u_uniform`` everywhere for
    label 0 when ``uniform_nonplanar``. float32 arithmetic and the first maximum, as
    ``(fine - unary).argmax(axis=1)`` gives. A pixel outside the band whose block (``step``
    pixels a side) has a ``cell_label`` (:func:`certified_cells`) gets it without its
    messages when the block's ``cell_gap`` exceeds ``easy_gap`` (the pixel is observed with
    that label or uniform) or ``hard_gap`` (another label). Pixels are independent, so row
    blocks run on parallel threads.
    """
    w = labels.shape[1]
    ws = coarse.shape[1]
    num = coarse.shape[2]
    resized = fine.shape[0] > 0
    message = np.empty(num, np.float32)
    # The band is ascending: a pointer walks it along the raster order of the rows.
    k = np.searchsorted(band, y0 * w)
    for y in range(y0, y1):
        row = (y // step) * ws
        for x in range(w):
            lab = labels[y, x]
            in_band = k < band.shape[0] and band[k] == y * w + x
            if not in_band:
                cell = row + x // step
                a = cell_label[cell]
                if a >= 0:
                    easy = a == lab or (uniform_nonplanar and lab == 0)
                    if cell_gap[cell] > (easy_gap if easy else hard_gap):
                        out[y, x] = a
                        continue
            if resized:
                message[:] = fine[y, x]
            else:
                _interpolate(coarse, rows, row_w, cols, col_w, y, x, message)
            best = -np.inf
            second = -np.inf
            arg = 0
            for label in range(num):
                u = _unary(label, lab, u_own, u_other, u_uniform, uniform_nonplanar)
                e = np.float32(message[label] - u)
                if e > best:
                    second = best
                    best = e
                    arg = label
                elif e > second:
                    second = e
            out[y, x] = arg
            if in_band:
                close[k] = best - second < margin
                k += 1


@kernel
def exact_labels(exact: np.ndarray, labels: np.ndarray, pixels: np.ndarray,
                 u_own: np.float32, u_other: np.float32, u_uniform: np.float32,
                 uniform_nonplanar: bool, out: np.ndarray) -> None:
    """:func:`upsampled_labels`' argmax at the (K,) int64 flat ``pixels`` of ``out``, from
    their (K, L) float32 ``exact`` messages instead."""
    w = labels.shape[1]
    for k in range(pixels.shape[0]):
        y, x = pixels[k] // w, pixels[k] % w
        lab = labels[y, x]
        best = -np.inf
        arg = 0
        for label in range(exact.shape[1]):
            u = _unary(label, lab, u_own, u_other, u_uniform, uniform_nonplanar)
            e = np.float32(exact[k, label] - u)
            if e > best:
                best = e
                arg = label
        out[y, x] = arg
