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
    labels = np.asarray(labels).ravel()
    if labels.dtype != np.int32:
        # Labels are small: int32 halves the passes' memory traffic against int64.
        labels = labels.astype(np.int64).clip(-1, num_labels + 1).astype(np.int32)
    labels = np.ascontiguousarray(labels)
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

    ``points`` (N, 3) float64, ``labels`` (N,) int32; labels outside 1..P are ignored. Two
    passes (centroid, then centred products) keep the scatter as accurate as a direct fit.
    Each label's sums add its points in order; a run of points of one label adds into
    registers, which leaves every sum as it was and spares a store and a load per point.
    """
    n = np.zeros(num_labels, dtype=np.int64)
    c = np.zeros((num_labels, 3))
    run = -1
    s0 = s1 = s2 = 0.0
    for v in range(points.shape[0]):
        k = labels[v] - 1
        if k != run:
            if run >= 0:
                c[run, 0], c[run, 1], c[run, 2] = s0, s1, s2
            run = k if 0 <= k < num_labels else -1
            if run < 0:
                continue
            s0, s1, s2 = c[run, 0], c[run, 1], c[run, 2]
        elif run < 0:
            continue
        n[run] += 1
        s0 += points[v, 0]
        s1 += points[v, 1]
        s2 += points[v, 2]
    if run >= 0:
        c[run, 0], c[run, 1], c[run, 2] = s0, s1, s2
    for k in range(num_labels):
        if n[k]:
            for j in range(3):
                c[k, j] /= n[k]
    m = np.zeros((num_labels, 6))
    run = -1
    m0 = m1 = m2 = m3 = m4 = m5 = c0 = c1 = c2 = 0.0
    for v in range(points.shape[0]):
        k = labels[v] - 1
        if k != run:
            if run >= 0:
                m[run, 0], m[run, 1], m[run, 2] = m0, m1, m2
                m[run, 3], m[run, 4], m[run, 5] = m3, m4, m5
            run = k if 0 <= k < num_labels else -1
            if run < 0:
                continue
            m0, m1, m2 = m[run, 0], m[run, 1], m[run, 2]
            m3, m4, m5 = m[run, 3], m[run, 4], m[run, 5]
            c0, c1, c2 = c[run, 0], c[run, 1], c[run, 2]
        elif run < 0:
            continue
        x0 = points[v, 0] - c0
        x1 = points[v, 1] - c1
        x2 = points[v, 2] - c2
        m0 += x0 * x0
        m1 += x0 * x1
        m2 += x0 * x2
        m3 += x1 * x1
        m4 += x1 * x2
        m5 += x2 * x2
    if run >= 0:
        m[run, 0], m[run, 1], m[run, 2] = m0, m1, m2
        m[run, 3], m[run, 4], m[run, 5] = m3, m4, m5
    scatter = np.empty((num_labels, 3, 3))
    for k in range(num_labels):
        scatter[k, 0, 0] = m[k, 0]
        scatter[k, 0, 1] = scatter[k, 1, 0] = m[k, 1]
        scatter[k, 0, 2] = scatter[k, 2, 0] = m[k, 2]
        scatter[k, 1, 1] = m[k, 3]
        scatter[k, 1, 2] = scatter[k, 2, 1] = m[k, 4]
        scatter[k, 2, 2] = m[k, 5]
    return n, c, scatter


@kernel
def _label_sq_distances(points: np.ndarray, labels: np.ndarray, planes: np.ndarray,
                        centroid: np.ndarray) -> np.ndarray:
    """(P,) sums of squared distances of each label's points to its (P, 4) plane; a run of
    points of one label adds into a register, as in :func:`_label_moments`."""
    num_labels = planes.shape[0]
    sums = np.zeros(num_labels)
    run = -1
    total = n0 = n1 = n2 = c0 = c1 = c2 = 0.0
    for v in range(points.shape[0]):
        k = labels[v] - 1
        if k != run:
            if run >= 0:
                sums[run] = total
            run = k if 0 <= k < num_labels else -1
            if run < 0:
                continue
            total = sums[run]
            n0, n1, n2 = planes[run, 0], planes[run, 1], planes[run, 2]
            c0, c1, c2 = centroid[run, 0], centroid[run, 1], centroid[run, 2]
        elif run < 0:
            continue
        # Through the centroid, as the fit does: the offset d is rounded, the centroid not.
        r = 0.0
        r += n0 * (points[v, 0] - c0)
        r += n1 * (points[v, 1] - c1)
        r += n2 * (points[v, 2] - c2)
        total += r * r
    if run >= 0:
        sums[run] = total
    return sums
