"""The plane colours every output shares: a palette whose neighbouring ids differ.

Label pictures, PLY and glTF colours, Rerun annotations and reports all colour plane id ``k``
with row ``k - 1`` of :func:`plane_palette`. It needs only NumPy, so any layer can import it
(the host's cloud result, the exporters, the reports). All colours are RGB uint8.
"""

from __future__ import annotations

import numpy as np

#: Colour of label 0 (non-planar pixels) in label maps.
NON_PLANAR = np.array([40, 40, 40], dtype=np.uint8)

_GOLDEN = 0.618033988749895

#: For each hue sector 0..5, which of (v, p, q, t) (see :func:`_hsv_to_rgb`) is (b, g, r).
_SECTOR_BGR = np.array([[1, 3, 0], [1, 0, 2], [3, 0, 1], [0, 2, 1], [0, 1, 3], [2, 1, 0]])


def _hsv_to_rgb(hsv: np.ndarray) -> np.ndarray:
    """HSV to RGB in 8 bits, hue in [0, 180) as OpenCV stores it.

    The arithmetic is OpenCV's per-pixel ``COLOR_HSV2RGB`` in float32, ``1 - s h`` fused into
    one rounding as its build does, so the palette keeps the colours earlier versions drew
    with OpenCV.

    Parameters
    ----------
    hsv : numpy.ndarray
        (N, 3) uint8: hue in [0, 180), saturation and value in [0, 255].

    Returns
    -------
    numpy.ndarray
        (N, 3) uint8 RGB.
    """
    f32 = np.float32
    hue = hsv[:, 0].astype(f32) * f32(6.0 / 180.0)
    s = hsv[:, 1].astype(f32) * f32(1.0 / 255.0)
    v = hsv[:, 2].astype(f32) * f32(1.0 / 255.0)
    sector = np.floor(hue).astype(np.int64)
    frac = hue - sector.astype(f32)
    sector %= 6

    def one_minus(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        # 1 - a b with a single rounding to float32 (a fused multiply-add): the product of two
        # float32 values is exact in float64
        return (1.0 - a.astype(np.float64) * b.astype(np.float64)).astype(f32)

    table = np.stack([v, v * (f32(1.0) - s), v * one_minus(s, frac),
                      v * one_minus(s, f32(1.0) - frac)], axis=-1)
    bgr = np.take_along_axis(table, _SECTOR_BGR[sector], axis=-1)
    bgr = np.where((s == 0)[:, None], v[:, None], bgr)
    return np.rint(bgr * f32(255.0)).clip(0, 255).astype(np.uint8)[:, ::-1].copy()


def plane_palette(n: int) -> np.ndarray:
    """Distinct, saturated colours for plane ids 1..n.

    Hues advance by the golden ratio, so any run of consecutive ids spreads over the colour
    wheel; brightness and saturation cycle through three levels so that ids whose hues happen to
    be close still differ in lightness. The colour of an id does not depend on ``n``.

    Parameters
    ----------
    n : int
        Number of planes.

    Returns
    -------
    numpy.ndarray
        (n, 3) uint8 RGB; row ``i`` is the colour of plane id ``i + 1``.
    """
    if n <= 0:
        return np.zeros((0, 3), dtype=np.uint8)
    i = np.arange(n)
    hue = (0.05 + i * _GOLDEN) % 1.0
    sat = np.array([0.85, 0.65, 0.95])[i % 3]
    val = np.array([0.95, 0.80, 0.65])[(i // 3) % 3]
    hsv = np.stack([hue * 180.0, sat * 255.0, val * 255.0], axis=-1).astype(np.uint8)
    return _hsv_to_rgb(hsv)


def label_colors(labels: np.ndarray, n_planes: int | None = None) -> np.ndarray:
    """Paint a label map with :func:`plane_palette`.

    Parameters
    ----------
    labels : numpy.ndarray
        (H, W) integer labels, 0 = non-planar.
    n_planes : int, optional
        Palette size; defaults to ``labels.max()``.

    Returns
    -------
    numpy.ndarray
        (H, W, 3) uint8 RGB; non-planar pixels are :data:`NON_PLANAR`.
    """
    n = int(labels.max()) if n_planes is None else int(n_planes)
    lut = np.vstack([NON_PLANAR[None], plane_palette(max(n, int(labels.max())))])
    return lut[labels]
