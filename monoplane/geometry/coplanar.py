"""Are two groups of view planes one surface? Coplanarity and contact of their footprints.

A group is a set of view planes (a global plane in the making). Each member is represented by
samples of its mask lifted onto its own plane into the world frame, with the depth of each
sample in the member's camera. Every test is relative to that depth, so it holds in metres and
in SfM units alike, and at any distance from the camera:

* :func:`coplanarity_residual`: the largest, over the members, median distance of a member's
  samples to a plane, divided by their depth;
* :func:`footprint_gap`: the distance between two footprints once both are projected onto a
  common plane, divided by the depth (zero when they overlap).

Planes are ``n · x + d = 0`` with unit ``n``, in the world frame of the samples.
"""

from __future__ import annotations

import numpy as np


def coplanarity_residual(points: list[np.ndarray], depths: list[np.ndarray],
                         plane: np.ndarray) -> float:
    """The largest median relative distance of any member's samples to ``plane``.

    Parameters
    ----------
    points : list of numpy.ndarray
        (N_k, 3) world samples of each member.
    depths : list of numpy.ndarray
        (N_k,) positive depth of each sample in its member's camera, same units.
    plane : numpy.ndarray
        (4,) world plane, unit normal.

    Returns
    -------
    float
        ``max_k median_i |n · x_ki + d| / z_ki``; 0 for no samples.
    """
    worst = 0.0
    for x, z in zip(points, depths, strict=True):
        if len(x):
            worst = max(worst, float(np.median(np.abs(x @ plane[:3] + plane[3]) / z)))
    return worst


def footprint_gap(points_a: np.ndarray, depths_a: np.ndarray, points_b: np.ndarray,
                  depths_b: np.ndarray, plane: np.ndarray) -> float:
    """Relative distance between two footprints on a common plane.

    Both sample sets are projected orthogonally onto ``plane``; the gap is the smallest, over
    pairs of samples, of their distance divided by the larger of their two depths.

    Parameters
    ----------
    points_a, points_b : numpy.ndarray
        (N_a, 3) and (N_b, 3) world samples.
    depths_a, depths_b : numpy.ndarray
        (N_a,) and (N_b,) positive depths of the samples in their cameras.
    plane : numpy.ndarray
        (4,) world plane, unit normal.

    Returns
    -------
    float
        Relative gap (0 where the footprints overlap); inf when a set is empty.
    """
    from scipy.spatial import cKDTree

    if len(points_a) == 0 or len(points_b) == 0:
        return float("inf")
    n = plane[:3]
    a = points_a - np.outer(points_a @ n + plane[3], n)
    b = points_b - np.outer(points_b @ n + plane[3], n)
    tree = cKDTree(a)
    dist, idx = tree.query(b, k=1)
    return float(np.min(dist / np.maximum(depths_a[idx], depths_b)))
