"""Colours for figures: colourised depth and normals, shading, and the plane palette.

All images here are RGB uint8 (H, W, 3); convert to BGR only when writing with OpenCV. The plane
palette lives in :mod:`monoplane.palette` (it needs no OpenCV, so every layer can use it) and is
re-exported here for the report modules.
"""

from __future__ import annotations

import cv2
import numpy as np

from monoplane.palette import NON_PLANAR, label_colors, plane_palette

__all__ = [
    "LIGHT_DIRECTION", "NON_PLANAR", "colorize_depth", "colorize_normals", "colormap",
    "depth_range", "label_colors", "plane_palette", "shade",
]


def depth_range(*depths: np.ndarray) -> tuple[float, float]:
    """A robust common display range for one or more depth maps.

    Returns
    -------
    (float, float)
        2nd and 98th percentiles of the valid (> 0) values of all maps together, in the depth's
        units; ``(0, 1)`` when no pixel is valid.
    """
    vals = np.concatenate([d[d > 0].ravel() for d in depths])
    if vals.size == 0:
        return 0.0, 1.0
    lo, hi = np.percentile(vals, [2.0, 98.0])
    if hi <= lo:
        hi = lo + max(abs(lo), 1.0) * 1e-3
    return float(lo), float(hi)


def colorize_depth(
    depth: np.ndarray, vmin: float | None = None, vmax: float | None = None
) -> np.ndarray:
    """Map z-depth to colour (turbo: near = blue, far = red); invalid pixels are black.

    Parameters
    ----------
    depth : numpy.ndarray
        (H, W) float depth, 0 = invalid.
    vmin, vmax : float, optional
        Display range in depth units; defaults to :func:`depth_range` of ``depth``.

    Returns
    -------
    numpy.ndarray
        (H, W, 3) uint8 RGB.
    """
    if vmin is None or vmax is None:
        lo, hi = depth_range(depth)
        vmin = lo if vmin is None else vmin
        vmax = hi if vmax is None else vmax
    scaled = np.clip((depth - vmin) / max(vmax - vmin, 1e-12), 0.0, 1.0)
    rgb = colormap(scaled)
    rgb[~(depth > 0)] = 0
    return rgb


def colormap(values: np.ndarray) -> np.ndarray:
    """Turbo colour map of values in [0, 1].

    Parameters
    ----------
    values : numpy.ndarray
        Any shape, floats in [0, 1].

    Returns
    -------
    numpy.ndarray
        ``values.shape + (3,)`` uint8 RGB.
    """
    v8 = np.round(np.clip(values, 0.0, 1.0) * 255.0).astype(np.uint8)
    bgr = cv2.applyColorMap(v8.reshape(-1, 1), cv2.COLORMAP_TURBO).reshape(*values.shape, 3)
    return bgr[..., ::-1].copy()


def colorize_normals(normals: np.ndarray) -> np.ndarray:
    """Map unit normals to colour the way normal maps are usually shown.

    The OpenCV-frame normal is first expressed in OpenGL's camera axes (x right, y up, z towards
    the viewer) and then mapped by ``(n + 1) / 2``: walls facing the camera come out blue-violet,
    floors green, ceilings pink and side walls red or cyan. All-zero (invalid) normals are black.

    Parameters
    ----------
    normals : numpy.ndarray
        (H, W, 3) float unit normals in the camera frame (OpenCV axes).

    Returns
    -------
    numpy.ndarray
        (H, W, 3) uint8 RGB.
    """
    gl = normals * np.array([1.0, -1.0, -1.0])
    rgb = np.round((np.clip(gl, -1.0, 1.0) + 1.0) * 127.5).astype(np.uint8)
    rgb[~np.any(normals != 0, axis=-1)] = 0
    return rgb


#: Direction the light travels in a camera frame (OpenCV axes): from above, slightly left of
#: and behind the camera, so that floor, facing walls, ceiling and the two side walls of a room
#: all come out with different brightness.
LIGHT_DIRECTION = np.array([0.35, 0.8, 0.45]) / np.linalg.norm([0.35, 0.8, 0.45])


def shade(colors: np.ndarray, normals: np.ndarray, light: np.ndarray = LIGHT_DIRECTION
          ) -> np.ndarray:
    """Darken colours by surface orientation so that planes of one colour still show shape.

    Uses a softened Lambert term, ``0.55 + 0.45 (1 - l · n) / 2``: a surface facing the light
    keeps its colour, one facing away keeps 55 % of it, never black.

    Parameters
    ----------
    colors : numpy.ndarray
        (N, 3) float colours in [0, 1].
    normals : numpy.ndarray
        (N, 3) unit normals, same frame as ``light``.
    light : numpy.ndarray
        (3,) unit direction the light travels.

    Returns
    -------
    numpy.ndarray
        (N, 3) float shaded colours in [0, 1].
    """
    facing = -(normals @ light)
    return colors * (0.55 + 0.45 * (1.0 + facing) / 2.0)[:, None]
