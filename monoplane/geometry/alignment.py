"""Scale alignment of a monocular depth map to sparse structure-from-motion depths.

Monocular depths of different views are predicted independently and share no scale. The paper
(appendix, "Sparse-view extension") aligns each view's depth ``D^m`` to the sparse SfM depth
``D^s`` by the scale ``s`` minimising ``‖M (D^s − s D^m)‖²`` with ``M = (D^s > 0)``. Its closed
form is ``s = Σ D^s D^m / Σ (D^m)²``. A few SfM points land on depth discontinuities or are
mismatched, so the solve here is made robust: a median-ratio start, an inlier band on the log
ratio, then the paper's least squares on the inliers only (repeated until the inlier set is
stable).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.errors import InvalidInput


@dataclass(frozen=True)
class ScaleAlignment:
    """Result of :func:`align_scale`.

    Attributes
    ----------
    scale : float
        ``s`` such that ``s * D_mono`` is in SfM units.
    num_points : int
        Sparse depths that fell on valid monocular depth.
    num_inliers : int
        Points inside the inlier band at the final scale.
    residual : float
        RMS of ``D_sfm − s D_mono`` over the inliers, in SfM units.
    relative_residual : float
        RMS of ``(D_sfm − s D_mono) / D_sfm`` over the inliers (unitless).
    """

    scale: float
    num_points: int
    num_inliers: int
    residual: float
    relative_residual: float

    @property
    def inlier_ratio(self) -> float:
        """``num_inliers / num_points``."""
        return self.num_inliers / max(self.num_points, 1)


def sample_depth(depth: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    """Nearest-pixel lookup of a depth map at sub-pixel positions.

    Parameters
    ----------
    depth : numpy.ndarray
        (H, W) depth map, 0 = invalid.
    pixels : numpy.ndarray
        (k, 2) ``(u, v)`` pixel coordinates (pixel centres at integers).

    Returns
    -------
    numpy.ndarray
        (k,) float64 depth at each pixel; 0 outside the image.
    """
    h, w = depth.shape
    uv = np.rint(np.asarray(pixels, dtype=np.float64)).astype(np.int64).reshape(-1, 2)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    out = np.zeros(len(uv))
    out[inside] = depth[uv[inside, 1], uv[inside, 0]]
    return out


def align_scale(mono_depth: np.ndarray, pixels: np.ndarray, sfm_depth: np.ndarray,
                log_tolerance: float = 0.2, min_points: int = 5,
                max_iterations: int = 10) -> ScaleAlignment:
    """Robust scale between a monocular depth map and sparse SfM depths.

    Parameters
    ----------
    mono_depth : numpy.ndarray
        (H, W) monocular z-depth ``D^m`` (any unit; 0 = invalid).
    pixels : numpy.ndarray
        (k, 2) pixel coordinates ``(u, v)`` of the sparse SfM observations in this view.
    sfm_depth : numpy.ndarray
        (k,) z-depth ``D^s`` of the observed 3D points in this camera, SfM units (> 0).
    log_tolerance : float
        Inlier band: a point is an inlier when ``|log(D^s / (s D^m))|`` is at most this
        (0.2 is about ±20 %).
    min_points : int
        Fewest valid correspondences (and inliers) accepted.
    max_iterations : int
        Cap on the inlier/least-squares alternation.

    Returns
    -------
    ScaleAlignment
        Scale, inlier count and residuals.

    Raises
    ------
    InvalidInput
        With fewer than ``min_points`` usable correspondences or inliers.
    """
    d_s = np.asarray(sfm_depth, dtype=np.float64).reshape(-1)
    d_m = sample_depth(np.asarray(mono_depth), pixels)
    if d_m.shape != d_s.shape:
        raise InvalidInput(f"{len(d_m)} pixels but {len(d_s)} sparse depths")
    ok = (d_m > 0) & (d_s > 0) & np.isfinite(d_s)
    d_s, d_m = d_s[ok], d_m[ok]
    if len(d_s) < min_points:
        raise InvalidInput(
            f"scale alignment needs at least {min_points} SfM points on valid depth, "
            f"got {len(d_s)}"
        )
    log_ratio = np.log(d_s / d_m)
    scale = float(np.exp(np.median(log_ratio)))
    inliers = np.zeros(len(d_s), dtype=bool)
    for _ in range(max_iterations):
        new = np.abs(log_ratio - np.log(scale)) <= log_tolerance
        if new.sum() < min_points:
            raise InvalidInput(
                f"scale alignment: only {int(new.sum())} of {len(d_s)} SfM points agree with "
                "the monocular depth up to one scale"
            )
        if np.array_equal(new, inliers):
            break
        inliers = new
        # Closed form of min_s ‖M (D^s − s D^m)‖² restricted to the inliers.
        scale = float(d_s[inliers] @ d_m[inliers] / (d_m[inliers] @ d_m[inliers]))
    res = d_s[inliers] - scale * d_m[inliers]
    return ScaleAlignment(
        scale=scale,
        num_points=int(len(d_s)),
        num_inliers=int(inliers.sum()),
        residual=float(np.sqrt(np.mean(res**2))),
        relative_residual=float(np.sqrt(np.mean((res / d_s[inliers]) ** 2))),
    )
