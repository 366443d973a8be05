"""The depth noise a frame shows, measured on its own planes: ε where the sensor is precise.

The RANSAC's ε is a fraction of the scene radius (the largest distance of a valid point from
the centroid, :mod:`monoplane.geometry.cloud`). That suits depth whose error grows with the
scene (monocular networks, which the paper tuned ε = 0.02 on), but not a depth sensor, whose
noise does not care how far the farthest pixel is: one TUM frame (Kinect) sees 0.1 % of its
pixels through a window at 9 m, so ε = 0.02 of its 9.6 m radius is 19 cm, while the sensor's
noise at the desk (2.4 m) is about 1 cm. A globe within 19 cm of the cabinet front beside it,
and the bottles and the bag 10-20 cm in front of a partition, then pass as plane inliers.

:func:`noise_limited_epsilon` measures the noise on the planes a first search found (robust
scale of the point-to-plane distances of their inliers: the inliers' spread is the noise,
whatever ε let in; the noise of a triangulating sensor grows with z², so it is taken at the
far end of the planes' depths) and returns ``factor × σ`` when that is well below ε. Depth
from a network (smooth, but bent at the scale of the scene) leaves residuals of the order of
ε, so ε stays.
"""

from __future__ import annotations

import numpy as np

#: Robust standard deviation of a normal distribution from its median absolute value.
MAD_TO_SIGMA = 1.4826


def plane_residual_sigma(points: np.ndarray, depth: np.ndarray, labels: np.ndarray,
                         planes: np.ndarray, quantile: float = 0.9) -> float:
    """Depth noise on a frame's planes, at the far end of their depths.

    Triangulating sensors (Kinect, structured light, stereo) have noise that grows with the
    square of the depth, so the point-to-plane distances are divided by ``z²`` before their
    robust scale is taken, and the result is given at the ``quantile`` depth of the labelled
    points: a threshold from it still holds the far planes of a scene. For a sensor whose
    noise does not grow with depth this errs on the side of a larger threshold.

    Parameters
    ----------
    points : numpy.ndarray
        (N, 3) points (any frame and unit).
    depth : numpy.ndarray
        (N,) depth of each point along the optical axis (any unit, positive).
    labels : numpy.ndarray
        (N,) int plane of each point, 0 = none, ``i`` = ``planes[i - 1]``.
    planes : numpy.ndarray
        (P, 4) unit-normal planes ``n · x + d = 0`` in the points' frame.
    quantile : float
        Depth quantile of the labelled points at which σ is given.

    Returns
    -------
    float
        ``1.4826 × median(|distance| / z²) × z_q²`` in the points' unit; NaN with fewer than
        3 labelled points.
    """
    labels = np.asarray(labels).ravel()
    on = labels > 0
    if on.sum() < 3:
        return float("nan")
    p = np.asarray(planes, dtype=np.float64)[labels[on] - 1]
    dist = np.abs(np.einsum("ij,ij->i", np.asarray(points, dtype=np.float64)[on], p[:, :3])
                  + p[:, 3])
    z = np.asarray(depth, dtype=np.float64).ravel()[on]
    per_z2 = MAD_TO_SIGMA * float(np.median(dist / z ** 2))
    return per_z2 * float(np.quantile(z, quantile)) ** 2


def noise_limited_epsilon(epsilon: float, sigma: float, factor: float,
                          floor: float = 0.1) -> float:
    """ε lowered to ``factor × σ`` when the measured noise allows, never below ``floor × ε``.

    Parameters
    ----------
    epsilon : float
        The configured inlier threshold (unit-sphere units).
    sigma : float
        Measured depth noise in the same units (:func:`plane_residual_sigma`); NaN keeps ε.
    factor : float
        Inlier band in noise deviations (3: about 99 % of Gaussian noise); 0 keeps ε.
    floor : float
        Lowest result as a fraction of ε: exact synthetic depth has σ ≈ 0, and a threshold at
        the rounding of the plane fits would split every face.

    Returns
    -------
    float
        The threshold to use, in ``[floor × epsilon, epsilon]``.
    """
    if factor <= 0 or not np.isfinite(sigma):
        return float(epsilon)
    return float(np.clip(factor * sigma, floor * epsilon, epsilon))
