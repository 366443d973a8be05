"""Per-region point moments and the least-squares planes that follow from them.

Split out of :mod:`monoplane.algorithm.regions`: the region clean-up reads the pixels once into
these moments, then fits, compares and unites regions on small matrices.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.jit import inline, kernel


@dataclass(frozen=True)
class RegionMoments:
    """Zeroth, first and second moments of each region's valid 3D points.

    Everything the clean-up asks of a region's points (its least-squares plane, the RMS
    distance of its points to any plane) follows from these moments, and the moments of a
    union of regions are sums. So the pixels are read once, for the connected components, and
    merging, absorbing and the final refit work on R small matrices instead of the image.

    Attributes
    ----------
    count : numpy.ndarray
        (R,) int64 number of valid points of region 1..R.
    total : numpy.ndarray
        (R, 3) float64 sum of ``X - centre`` over the region's points.
    outer : numpy.ndarray
        (R, 3, 3) float64 sum of ``(X - centre)(X - centre)ᵀ``.
    centre : numpy.ndarray
        (3,) float64 common origin of the sums (the mean valid point), which keeps them well
        conditioned; camera frame, depth units.
    """

    count: np.ndarray
    total: np.ndarray
    outer: np.ndarray
    centre: np.ndarray

    @classmethod
    def of(cls, points: np.ndarray, valid: np.ndarray, labels: np.ndarray,
           num: int) -> RegionMoments:
        """Moments of labels 1..num of an (H, W) label map over (H, W, 3) points where valid."""
        labels = np.asarray(labels)
        mask = np.asarray(valid) & (labels > 0)
        points = np.asarray(points, dtype=np.float64)
        centre = _masked_mean(points.reshape(-1, 3), mask.ravel())
        count, total, outer = _moments(points.reshape(-1, 3), mask.ravel(),
                                       labels.ravel().astype(np.int64), int(num), centre)
        return cls(count, total, outer, centre)

    def combine(self, group_of: np.ndarray, num_groups: int) -> RegionMoments:
        """Moments of groups of regions: ``group_of`` (R,) gives each region's group 1..G or 0
        (dropped)."""
        size = num_groups + 1
        group = np.asarray(group_of, dtype=np.int64)

        def add(x: np.ndarray) -> np.ndarray:
            out = np.zeros((size, *x.shape[1:]), dtype=x.dtype)
            np.add.at(out, group, x)
            return out[1:]

        return RegionMoments(add(self.count), add(self.total), add(self.outer), self.centre)

    def planes(self, fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Total-least-squares plane of each region (as :func:`~monoplane.geometry.planes.
        fit_plane`: smallest eigenvector of the scatter, through the centroid, facing the
        camera); regions with fewer than 3 points keep their (R, 4) ``fallback`` plane.

        Returns ``params`` (R, 4), ``rmse`` (R,) (0 without points) and ``support`` (R,).
        """
        n = self.count.astype(np.float64)
        fit = self.count >= 3
        safe = np.maximum(n, 1.0)
        mean = self.total / safe[:, None]
        scatter = self.outer - safe[:, None, None] * mean[:, :, None] * mean[:, None, :]
        params = np.array(fallback, dtype=np.float64).reshape(-1, 4)
        rmse = np.zeros(n.size)
        if fit.any():
            values, vectors = np.linalg.eigh(scatter[fit])
            normal = vectors[:, :, 0]
            d = -np.einsum("rk,rk->r", normal, mean[fit] + self.centre)
            flip = np.where(d < 0, -1.0, 1.0)
            params[fit] = np.column_stack([normal * flip[:, None], d * flip])
            rmse[fit] = np.sqrt(np.maximum(values[:, 0], 0.0) / n[fit])
        # A region with 1-2 points keeps its previous plane; its RMSE is measured against it.
        few = ~fit & (self.count > 0)
        for k in np.flatnonzero(few):
            rmse[k] = self.rms(params[k][None])[k, 0]
        return params, rmse, self.count.copy()

    def rms(self, planes: np.ndarray) -> np.ndarray:
        """(R, H) RMS distance of each region's points to each of (H, 4) planes ``n·X + d = 0``
        (unit n, camera frame); inf for a region without points."""
        p = np.atleast_2d(planes)
        normal = p[:, :3]
        d = p[:, 3] + normal @ self.centre
        square = (np.einsum("hi,rij,hj->rh", normal, self.outer, normal)
                  + 2.0 * d[None, :] * (self.total @ normal.T)
                  + self.count[:, None] * d[None, :] ** 2)
        with np.errstate(divide="ignore", invalid="ignore"):
            out = np.sqrt(np.maximum(square, 0.0) / self.count[:, None])
        return np.where(self.count[:, None] > 0, out, np.inf)


def refit_planes(points: np.ndarray, valid: np.ndarray, labels: np.ndarray,
                 fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares plane of each label on its valid pixels' 3D points.

    Parameters
    ----------
    points : numpy.ndarray
        (H, W, 3) camera-frame points (OpenCV axes), in depth units.
    valid : numpy.ndarray
        (H, W) bool, pixels with a valid depth.
    labels : numpy.ndarray
        (H, W) int labels 0..P.
    fallback : numpy.ndarray
        (P, 4) planes kept for labels with fewer than 3 valid points (e.g. regions the CRF
        grew over invalid depth).

    Returns
    -------
    params : numpy.ndarray
        (P, 4) float64 planes ``n · X + d = 0``, unit normal facing the camera.
    rmse : numpy.ndarray
        (P,) float64 RMS point-to-plane distance of the label's valid points, depth units
        (0 when it has none).
    support : numpy.ndarray
        (P,) int64 number of valid points of each label.
    """
    num = np.asarray(fallback).reshape(-1, 4).shape[0]
    return RegionMoments.of(points, valid, labels, num).planes(fallback)


def scene_radius(points: np.ndarray, valid: np.ndarray) -> float:
    """Largest distance of a valid 3D point from the valid points' centroid.

    The RANSAC normalises the cloud by this radius into the unit sphere; expressing the
    region tolerances as a fraction of it makes them free of the depth's unit and scale.

    Parameters
    ----------
    points, valid : numpy.ndarray
        (H, W, 3) camera-frame points (OpenCV axes, depth units) and the (H, W) bool mask of
        pixels with a valid depth.

    Returns
    -------
    float
        Radius in depth units; 0 when there are no valid points.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    return float(_radius(pts, np.ascontiguousarray(valid, dtype=np.bool_).ravel()))


@kernel
def _radius(points: np.ndarray, valid: np.ndarray) -> float:
    """:func:`scene_radius` of (N, 3) float64 points and their (N,) bool mask, in two passes
    without copying the valid points out."""
    centre = _mean_where(points, valid)  # zeros without valid points: the loop adds nothing
    best = 0.0
    for i in range(points.shape[0]):
        if valid[i]:
            d2 = 0.0
            for c in range(3):
                d2 += (points[i, c] - centre[c]) ** 2
            best = max(best, d2)
    return np.sqrt(best)


@kernel
def _masked_mean(points: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """:func:`_mean_where`, compiled for callers outside the kernels."""
    return _mean_where(points, mask)


@inline
def _mean_where(points: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(3,) float64 mean of the (N, 3) float64 ``points`` where the (N,) bool ``mask`` holds;
    zeros without any. Summed row after row, as ``points[mask].mean(axis=0)`` sums (numpy
    adds whole rows along axis 0, without pairwise blocks), so the result equals it bit for
    bit without gathering the rows."""
    total = np.zeros(3)
    n = 0
    for i in range(mask.shape[0]):
        if mask[i]:
            for c in range(3):
                total[c] += points[i, c]
            n += 1
    if n == 0:
        return total
    return total / n


@kernel
def _moments(points: np.ndarray, mask: np.ndarray, labels: np.ndarray, num: int,
             centre: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`RegionMoments.of` in one pass over the pixels, in raster order (the order
    ``numpy.bincount`` sums in). ``points`` (H W, 3) float64, ``mask`` (H W,) bool, ``labels``
    (H W,) int64; labels above ``num`` are ignored. Returns count (num,) int64, total (num, 3)
    and outer (num, 3, 3) float64."""
    count = np.zeros(num + 1, dtype=np.int64)
    total = np.zeros((num + 1, 3))
    outer = np.zeros((num + 1, 3, 3))
    x = np.empty(3)
    for i in range(labels.shape[0]):
        lab = labels[i]
        if not mask[i] or lab > num:
            continue
        for a in range(3):
            x[a] = points[i, a] - centre[a]
        count[lab] += 1
        for a in range(3):
            total[lab, a] += x[a]
            for b in range(a, 3):
                outer[lab, a, b] += x[a] * x[b]
    for lab in range(num + 1):
        for a in range(3):
            for b in range(a):
                outer[lab, a, b] = outer[lab, b, a]
    return count[1:], total[1:], outer[1:]

