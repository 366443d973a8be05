"""Plane primitives: exact 3-point planes, least-squares fits and point-to-plane distances.

Planes are ``(n, d)`` rows with ``n · X + d = 0`` and ``|n| = 1``. Functions here are frame-
agnostic (they work in the camera frame or the normalised RANSAC frame alike); orientation
"towards the camera" means towards the frame's origin, i.e. ``d >= 0``.
"""

from __future__ import annotations

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.geometry.hypotheses import triplet_planes
from monoplane.jit import kernel


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
    t = np.ascontiguousarray(triplets, dtype=np.float64)
    if t.ndim != 3 or t.shape[1:] != (3, 3):
        raise InvalidInput(f"triplets must have shape (S, 3, 3), got {t.shape}")
    return triplet_planes(t)


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


def fit_planes_per_label(points: np.ndarray, labels: np.ndarray, num_labels: int
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Total-least-squares plane of every label's points (see :func:`fit_plane`).

    Parameters
    ----------
    points : numpy.ndarray
        (N, 3) points.
    labels : numpy.ndarray
        (N,) int labels in 0..num_labels; label 0 is ignored.
    num_labels : int
        Number of labels P.

    Returns
    -------
    params : numpy.ndarray
        (P, 4) planes with ``d >= 0``; NaN rows for labels with fewer than 3 points.
    rmse : numpy.ndarray
        (P,) RMS point-to-plane distance (NaN where no plane was fit).
    count : numpy.ndarray
        (P,) int64 number of points of each label.
    """
    labels = np.ascontiguousarray(np.asarray(labels).ravel(), dtype=np.int64)
    pts = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
    if labels.shape[0] != pts.shape[0]:
        raise InvalidInput(f"{pts.shape[0]} points but {labels.shape[0]} labels")
    count, centroid, scatter = _label_moments(pts, labels, int(num_labels))
    params = np.full((num_labels, 4), np.nan)
    rmse = np.full(num_labels, np.nan)
    fit = np.flatnonzero(count >= 3)
    if fit.size:
        _, vecs = np.linalg.eigh(scatter[fit])
        normal = vecs[:, :, 0]
        d = -np.einsum("pc,pc->p", normal, centroid[fit])
        flip = d < 0
        normal[flip] *= -1.0
        d[flip] *= -1.0
        params[fit, :3] = normal
        params[fit, 3] = d
        rmse[fit] = np.sqrt(_label_sq_distances(pts, labels, params, centroid)[fit] / count[fit])
    return params, rmse, count


@kernel
def _label_moments(points: np.ndarray, labels: np.ndarray, num_labels: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(P,) int64 counts, (P, 3) centroids and (P, 3, 3) centred scatter matrices per label.

    ``points`` (N, 3) float64, ``labels`` (N,) int64; labels outside 1..P are ignored. Two
    passes (centroid, then centred products) keep the scatter as accurate as a direct fit.
    """
    count = np.zeros(num_labels, dtype=np.int64)
    centroid = np.zeros((num_labels, 3))
    for v in range(points.shape[0]):
        k = labels[v] - 1
        if 0 <= k < num_labels:
            count[k] += 1
            for c in range(3):
                centroid[k, c] += points[v, c]
    for k in range(num_labels):
        if count[k]:
            for c in range(3):
                centroid[k, c] /= count[k]
    scatter = np.zeros((num_labels, 3, 3))
    for v in range(points.shape[0]):
        k = labels[v] - 1
        if 0 <= k < num_labels:
            x0 = points[v, 0] - centroid[k, 0]
            x1 = points[v, 1] - centroid[k, 1]
            x2 = points[v, 2] - centroid[k, 2]
            scatter[k, 0, 0] += x0 * x0
            scatter[k, 0, 1] += x0 * x1
            scatter[k, 0, 2] += x0 * x2
            scatter[k, 1, 1] += x1 * x1
            scatter[k, 1, 2] += x1 * x2
            scatter[k, 2, 2] += x2 * x2
    for k in range(num_labels):
        scatter[k, 1, 0] = scatter[k, 0, 1]
        scatter[k, 2, 0] = scatter[k, 0, 2]
        scatter[k, 2, 1] = scatter[k, 1, 2]
    return count, centroid, scatter


@kernel
def _label_sq_distances(points: np.ndarray, labels: np.ndarray, planes: np.ndarray,
                        centroid: np.ndarray) -> np.ndarray:
    """(P,) sums of squared distances of each label's points to its (P, 4) plane."""
    num_labels = planes.shape[0]
    out = np.zeros(num_labels)
    for v in range(points.shape[0]):
        k = labels[v] - 1
        if 0 <= k < num_labels:
            # Through the centroid, as the fit does: the offset d is rounded, the centroid not.
            r = 0.0
            for c in range(3):
                r += planes[k, c] * (points[v, c] - centroid[k, c])
            out[k] += r * r
    return out
