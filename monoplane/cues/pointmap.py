"""Metric depth and intrinsics from an affine-invariant point map (MoGe-style networks).

Such a network predicts, per pixel, a camera-frame point ``(x, y, z')`` whose depth is known up
to a shift, ``z = z' + shift``, and a global metric scale. Its pinhole camera has square pixels
and the principal point at the image centre, with an unknown focal length. Both unknowns follow
from the projection constraint ``f * (x, y) / (z' + shift) = (u, v)``, where ``(u, v)`` are pixel
coordinates relative to the centre in units of the half image diagonal: for a given shift the
best focal length is a closed-form least-squares ratio, so only the shift is searched.
"""

from __future__ import annotations

import numpy as np

from monoplane.errors import InvalidInput

#: Point-map pixels used for the focal/shift fit (a regular subsample).
FIT_SAMPLES = 64 * 64


def centred_plane_coords(height: int, width: int) -> np.ndarray:
    """Pixel coordinates relative to the image centre, in half-diagonals.

    Returns
    -------
    numpy.ndarray
        (H, W, 2) float64 ``(u, v)``; pixel centres at integer coordinates, the centre at
        ``((W - 1) / 2, (H - 1) / 2)``, x right and y down.
    """
    half_diag = 0.5 * np.hypot(width, height)
    u = (np.arange(width) - (width - 1) / 2) / half_diag
    v = (np.arange(height) - (height - 1) / 2) / half_diag
    return np.stack(np.meshgrid(u, v), axis=-1)


def _subsample(points: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    h, w = valid.shape
    step = max(1, int(np.sqrt(h * w / FIT_SAMPLES)))
    uv = centred_plane_coords(h, w)[::step, ::step]
    sel = valid[::step, ::step]
    return points[::step, ::step][sel].astype(np.float64), uv[sel]


def recover_focal_shift(points: np.ndarray, valid: np.ndarray,
                        focal: float | None = None) -> tuple[float, float]:
    """Focal length and depth shift that make an affine point map a pinhole projection.

    Parameters
    ----------
    points : numpy.ndarray
        (H, W, 3) point map, OpenCV camera axes, depth known up to a shift.
    valid : numpy.ndarray
        (H, W) bool, pixels to use.
    focal : float, optional
        Known focal length in half-diagonals; only the shift is solved then.

    Returns
    -------
    focal : float
        Focal length in units of the half image diagonal (``fx = focal * hypot(W, H) / 2``).
    shift : float
        Add to the point map's z to get (scaled) depth.
    """
    xyz, uv = _subsample(points, valid)
    if len(xyz) < 3:
        raise InvalidInput("the point-map network marked almost no pixel as valid")
    xy, z = xyz[:, :2], xyz[:, 2]
    spread = max(float(np.ptp(z)), 1e-6)

    def projected(shift: float) -> np.ndarray:
        # Keep the depth positive inside the search; the floor only matters far from the fit.
        return xy / np.maximum(z + shift, 1e-3 * spread)[:, None]

    def best_focal(p: np.ndarray) -> float:
        return float(np.sum(p * uv) / max(np.sum(p * p), 1e-12))

    def residual(s: np.ndarray) -> np.ndarray:
        p = projected(float(s[0]))
        f = best_focal(p) if focal is None else focal
        return (f * p - uv).ravel()

    start = max(0.0, 1e-3 * spread - float(z.min()))
    # Imported here: scipy.optimize costs about 0.3 s to import, which every command that
    # merely imports the cue providers (all of them, through the pipeline) would pay.
    from scipy.optimize import least_squares

    shift = float(least_squares(residual, x0=[start], method="lm").x[0])
    f = best_focal(projected(shift)) if focal is None else float(focal)
    if not np.isfinite(f) or f <= 0:
        raise InvalidInput("could not recover a focal length from the network's point map")
    return f, shift


def focal_to_pixels(focal: float, height: int, width: int) -> float:
    """A focal length in half-diagonals, in pixels of an image of this size."""
    return focal * 0.5 * float(np.hypot(width, height))


def focal_from_intrinsics(K: np.ndarray, height: int, width: int) -> float:
    """The mean of ``fx`` and ``fy`` in half-diagonals (square-pixel, centred approximation)."""
    return 0.5 * float(K[0, 0] + K[1, 1]) / (0.5 * float(np.hypot(width, height)))


def depth_from_point_map(points: np.ndarray, mask: np.ndarray | None, scale: float,
                         focal: float | None = None) -> tuple[np.ndarray, float]:
    """Metric z-depth from an affine point map.

    Parameters
    ----------
    points : numpy.ndarray
        (H, W, 3) affine point map.
    mask : numpy.ndarray or None
        (H, W) validity probability; pixels below 0.5 are invalid.
    scale : float
        Metric scale predicted by the network (1 when it has none).
    focal : float, optional
        Known focal length in half-diagonals.

    Returns
    -------
    depth : numpy.ndarray
        (H, W) float32 metric z-depth, 0 = invalid.
    focal : float
        The focal length used, in half-diagonals (recovered when not given).
    """
    finite = np.all(np.isfinite(points), axis=-1)
    valid = finite if mask is None else finite & (mask > 0.5)
    f, shift = recover_focal_shift(points, valid, focal)
    z = (points[..., 2].astype(np.float64) + shift) * scale
    depth = np.where(valid & (z > 0), z, 0).astype(np.float32)
    if not np.any(depth > 0):
        raise InvalidInput("the point-map network returned no positive depth")
    return depth, f
