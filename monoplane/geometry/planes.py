"""Plane primitives: exact 3-point planes, least-squares fits and point-to-plane distances.

Planes are ``(n, d)`` rows with ``n · X + d = 0`` and ``|n| = 1``. Functions here are frame-
agnostic (they work in the camera frame or the normalised RANSAC frame alike); orientation
"towards the camera" means towards the frame's origin, i.e. ``d >= 0``.
"""

from __future__ import annotations

import numpy as np

from monoplane.errors import InvalidInput


def fit_plane(points: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Total-least-squares plane through 3D points.

    The normal is the eigenvector of the (weighted) scatter matrix with the smallest
    eigenvalue; the plane passes through the (weighted) centroid.

    Parameters
    ----------
    points : numpy.ndarray
        (N, 3) points, N >= 3, any frame and unit.
    weights : numpy.ndarray, optional
        (N,) non-negative weights.

    Returns
    -------
    plane : numpy.ndarray
        (4,) float64 ``(nx, ny, nz, d)`` with ``|n| = 1`` and ``d >= 0`` (normal towards the
        origin of the points' frame).
    rmse : float
        Root of the (weighted) mean squared point-to-plane distance, in the points' unit.
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 3:
        raise InvalidInput(f"fit_plane needs (N>=3, 3) points, got {pts.shape}")
    w = np.ones(len(pts)) if weights is None else np.asarray(weights, dtype=np.float64)
    wsum = w.sum()
    if wsum <= 0:
        raise InvalidInput("fit_plane weights sum to zero")
    centroid = (w[:, None] * pts).sum(axis=0) / wsum
    centred = pts - centroid
    scatter = (centred * w[:, None]).T @ centred
    _, vecs = np.linalg.eigh(scatter)
    normal = vecs[:, 0]
    d = -float(normal @ centroid)
    if d < 0:
        normal, d = -normal, -d
    dist = centred @ normal
    rmse = float(np.sqrt((w * dist**2).sum() / wsum))
    return np.concatenate([normal, [d]]), rmse


def planes_from_triplets(triplets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact planes through many 3-point samples at once.

    Parameters
    ----------
    triplets : numpy.ndarray
        (S, 3, 3) points: sample, point, coordinate.

    Returns
    -------
    planes : numpy.ndarray
        (S, 4) float64 unit-normal planes with ``d >= 0``; rows of degenerate samples are zero.
    valid : numpy.ndarray
        (S,) bool, False where the three points are (nearly) collinear.
    """
    t = np.asarray(triplets, dtype=np.float64)
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    normal = np.cross(b - a, c - a)
    norm = np.linalg.norm(normal, axis=1)
    # Scale-aware degeneracy test: |cross| is twice the triangle area, compare to edge lengths².
    edge2 = np.maximum(((b - a) ** 2).sum(1), ((c - a) ** 2).sum(1))
    valid = norm > 1e-9 * np.maximum(edge2, 1e-300)
    planes = np.zeros((len(t), 4))
    n = normal[valid] / norm[valid, None]
    d = -np.einsum("ij,ij->i", n, a[valid])
    flip = d < 0
    n[flip] *= -1
    d[flip] *= -1
    planes[valid, :3] = n
    planes[valid, 3] = d
    return planes, valid


def point_plane_distances(points: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Absolute point-to-plane distances for every (plane, point) pair.

    Parameters
    ----------
    points : numpy.ndarray
        (N, 3) points.
    planes : numpy.ndarray
        (H, 4) unit-normal planes in the same frame.

    Returns
    -------
    numpy.ndarray
        (H, N) float64 distances in the points' unit.
    """
    p = np.atleast_2d(planes)
    return np.abs(p[:, :3] @ np.asarray(points, dtype=np.float64).T + p[:, 3:4])
