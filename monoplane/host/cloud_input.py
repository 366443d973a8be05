"""A point cloud as the pipeline takes it (:meth:`monoplane.host.pipeline.Pipeline.run_cloud`),
and its planes in its own frame and units.

1. :func:`cloud_arrays`: points, normals and colours of an Open3D cloud or an array;
2. :func:`prepare_cloud`: non-finite points are set aside (label 0) and exact duplicates
   collapsed, so neither can break the search or the normal estimation; the distinct points
   are normalised into the unit sphere (``ransac.epsilon`` keeps its meaning) and, for the
   search, subsampled to ``ransac.max_points``; missing normals are estimated
   (:func:`cue_normals_from_depth`: Open3D's PCA over ``cloud.normals_knn`` neighbours, oriented as
   ``cloud.orient`` says);
3. after the search and the refiner, :meth:`CloudInput.fit` refits every plane by least
   squares on all its distinct points, in the cloud's frame and units, turns it to the side
   its points' normals face, and gives the labels back in the input's order.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from monoplane.algorithm.plane_refit import refit_and_renumber
from monoplane.datamodel import CloudResult
from monoplane.errors import InvalidInput
from monoplane.geometry.cloud import PlaneCloud, normalised_cloud
from monoplane.geometry.orientation import orient_normals
from monoplane.host.cloud_config import CloudConfig
from monoplane.io.checks import MAX_MAGNITUDE


def cloud_arrays(cloud: Any) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(N, 3) points, optional normals and colours of any supported cloud type."""
    import open3d as o3d

    normals = colors = None
    if isinstance(cloud, o3d.geometry.PointCloud):
        points = np.asarray(cloud.points, dtype=np.float64)
        if cloud.has_normals():
            normals = np.asarray(cloud.normals, dtype=np.float64)
        if cloud.has_colors():
            colors = np.asarray(cloud.colors, dtype=np.float64)
    elif isinstance(cloud, o3d.t.geometry.PointCloud):
        if "positions" not in cloud.point:
            raise InvalidInput("the tensor point cloud has no 'positions' attribute")
        points = cloud.point.positions.numpy().astype(np.float64)
        if "normals" in cloud.point:
            normals = cloud.point.normals.numpy().astype(np.float64)
        if "colors" in cloud.point:
            colors = cloud.point.colors.numpy().astype(np.float64)
            if colors.size and colors.max() > 1.0:  # 8-bit colours
                colors = colors / 255.0
    else:
        try:
            points = np.asarray(cloud, dtype=np.float64)
        except (TypeError, ValueError):
            raise InvalidInput(
                f"cloud must be an open3d PointCloud (legacy or tensor) or an (N, 3) array, "
                f"got {type(cloud).__name__}") from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise InvalidInput(f"points must have shape (N, 3), got {points.shape}")
    return points, normals, colors


def estimate_normals(points: np.ndarray, cfg: CloudConfig) -> np.ndarray:
    """Unit normals of ``points`` by Open3D PCA, oriented as ``cfg.orient`` says."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    k = min(cfg.normals_knn, len(points))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=k))
    if cfg.orient == "consistent" and len(points) > 3:
        pcd.orient_normals_consistent_tangent_plane(min(15, len(points) - 1))
        return np.asarray(pcd.normals, dtype=np.float64)
    normals = np.asarray(pcd.normals, dtype=np.float64)
    if cfg.orient == "auto":
        return orient_normals(points, normals, np.asarray(cfg.viewpoint, dtype=np.float64))
    towards = np.asarray(cfg.viewpoint, dtype=np.float64) - points
    return np.where(((normals * towards).sum(axis=1) < 0)[:, None], -normals, normals)


@dataclass
class CloudInput:
    """A point cloud prepared for the search (:func:`prepare_cloud`).

    Its finite distinct points are normalised into the unit sphere (``cloud.all_points``), the
    search runs on a subsample of them (``cloud.points``, ``ransac.max_points`` at most) with
    oriented unit normals, and :meth:`fit` turns labels of all distinct points into planes in
    the input's frame and units, labels in the input's order.

    Attributes
    ----------
    points : numpy.ndarray
        (N, 3) float64 input points.
    colors : numpy.ndarray or None
        (N, 3) input colours in [0, 1], None when absent or unusable.
    unique : numpy.ndarray
        (U, 3) float64 distinct finite points, input units.
    index : numpy.ndarray
        (N,) int64 row of ``unique`` of each input point, -1 for non-finite ones.
    normals : numpy.ndarray or None
        (U, 3) given normals of ``unique`` (not normalised); None when estimated.
    cloud : PlaneCloud
        The normalised cloud the search runs on; ``cloud.sampled`` (or all of ``unique``)
        says which rows of ``unique`` it holds.
    notes : list of str
        What was done to the input.
    """

    points: np.ndarray
    colors: np.ndarray | None
    unique: np.ndarray
    index: np.ndarray
    normals: np.ndarray | None
    cloud: PlaneCloud
    notes: list[str]

    @property
    def own_normals(self) -> bool:
        """The normals came with the cloud (they were not estimated from its points)."""
        return self.normals is not None

    def fit(self, labels: np.ndarray, timings: dict[str, float]) -> CloudResult:
        """Planes refit on all their distinct points, oriented by their normals.

        Parameters
        ----------
        labels : numpy.ndarray
            (U,) int32 plane of each row of ``unique`` (:meth:`PlaneCloud.propagate`).
        timings : dict
            Seconds per step, returned with the fit.

        Returns
        -------
        CloudResult
            Labels in the input order, planes in the cloud's frame and units; no config (the
            pipeline adds its own).
        """
        renumber, params, rmse, support = refit_and_renumber(self.unique, labels,
                                                             int(labels.max(initial=0)))
        labels = renumber[labels]
        centroids = np.zeros((params.shape[0], 3))
        if params.shape[0]:
            planar = labels > 0
            np.add.at(centroids, labels[planar] - 1, self.unique[planar])
            centroids /= support[:, None]
            flip = (self._mean_normals(labels, params.shape[0]) * params[:, :3]).sum(axis=1) < 0
            params[flip] *= -1
        out = np.zeros(self.points.shape[0], dtype=np.int32)
        finite = self.index >= 0
        out[finite] = labels[self.index[finite]]
        return CloudResult(points=self.points, labels=out, planes=params.reshape(-1, 4),
                           rmse=rmse, support=support, centroids=centroids, colors=self.colors,
                           notes=self.notes, timings=timings)

    def _mean_normals(self, labels: np.ndarray, count: int) -> np.ndarray:
        """(count, 3) sum of the normals of each plane's points: all of them when every
        distinct point has one (given, or estimated on all), else the sampled ones."""
        sums = np.zeros((count, 3))
        sampled = self.cloud.sampled
        if self.normals is not None or sampled is None:
            normals = self.normals if self.normals is not None else self.cloud.normals
            planar = labels > 0
            np.add.at(sums, labels[planar] - 1, normals[planar])
        else:
            lab_s = labels[sampled]
            np.add.at(sums, lab_s[lab_s > 0] - 1, self.cloud.normals[lab_s > 0])
        return sums


def prepare_cloud(cloud: Any, cfg: CloudConfig, max_points: int, rng: np.random.Generator,
                  timings: dict[str, float]) -> CloudInput:
    """Check a cloud, set its non-finite and duplicate points aside, normalise the rest into
    the unit sphere, subsample them for the search and give them oriented normals.

    Parameters
    ----------
    cloud : open3d.geometry.PointCloud, open3d.t.geometry.PointCloud or array_like
        (N, 3) points with optional normals and colours (see :func:`cloud_arrays`).
    cfg : CloudConfig
        How missing normals are estimated and oriented.
    max_points : int
        Most points the search runs on (``ransac.max_points``).
    rng : numpy.random.Generator
        Source of the subsample (the RANSAC's generator, drawn from first).
    timings : dict
        Seconds of ``prepare`` and ``normals`` are added to it.

    Raises
    ------
    InvalidInput
        Malformed arrays, coordinates beyond :data:`~monoplane.io.checks.MAX_MAGNITUDE`,
        fewer than 3 distinct finite points, or points too close together to normalise.
    """
    t = time.perf_counter()
    points, normals, colors = cloud_arrays(cloud)
    notes: list[str] = []
    finite, normals, colors = _checked(points, normals, colors, notes)
    finite_idx = np.flatnonzero(finite)
    unique, first, inverse = np.unique(points[finite_idx], axis=0, return_index=True,
                                       return_inverse=True)
    if len(unique) < 3:
        raise InvalidInput(f"the cloud has {len(unique)} distinct finite point(s); a plane "
                           "needs at least 3")
    if len(unique) < len(finite_idx):
        notes.append(f"{len(finite_idx) - len(unique)} duplicate points share their twin's label")
    index = np.full(points.shape[0], -1, dtype=np.int64)
    index[finite_idx] = inverse.ravel()
    u_normals = normals[finite_idx[first]] if normals is not None else None
    u_colors = colors[finite_idx[first]] if colors is not None else None
    norm_pts, center, scale = normalised_cloud(unique)
    sample = np.arange(len(unique))
    if len(unique) > max_points:
        sample = np.sort(rng.choice(len(unique), size=max_points, replace=False))
        notes.append(f"search on {max_points} of {len(unique)} points; all labelled")
    timings["prepare"] = time.perf_counter() - t
    t = time.perf_counter()
    if u_normals is None:
        s_normals = estimate_normals(unique[sample], cfg)
        notes.append(f"normals estimated (PCA, {cfg.normals_knn} neighbours, "
                     f"oriented: {cfg.orient})")
    else:
        s_normals = u_normals[sample] / np.linalg.norm(u_normals[sample], axis=1, keepdims=True)
    timings["normals"] = time.perf_counter() - t
    subsampled = sample.size < len(unique)
    plane_cloud = PlaneCloud.from_points(
        norm_pts[sample], s_normals, None if u_colors is None else u_colors[sample], center,
        scale, all_points=norm_pts if subsampled else None,
        sampled=sample if subsampled else None)
    return CloudInput(points, colors, unique, index, u_normals, plane_cloud, notes)


def _checked(points: np.ndarray, normals: np.ndarray | None, colors: np.ndarray | None,
             notes: list[str]) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The (N,) finite-point mask, and the normals and colours, None where unusable (noted).

    Raises
    ------
    InvalidInput
        Normals or colours of another shape than the points, or coordinates beyond
        :data:`~monoplane.io.checks.MAX_MAGNITUDE`.
    """
    for what, arr in (("normals", normals), ("colors", colors)):
        if arr is not None and arr.shape != points.shape:
            raise InvalidInput(f"{what} must have shape {points.shape}, got {arr.shape}")
    finite = np.isfinite(points).all(axis=1)
    huge = finite & (np.abs(points) > MAX_MAGNITUDE).any(axis=1)
    if huge.any():
        first = int(np.argmax(huge))
        raise InvalidInput(f"{int(huge.sum())} point(s) have coordinates beyond "
                           f"±{MAX_MAGNITUDE:.3g} (the first is point {first})")
    if normals is not None:
        # Judged by the largest component: squaring one near 1e300 would overflow.
        size = np.abs(normals).max(axis=1)
        ok_n = np.isfinite(normals).all(axis=1) & (size > 1e-12) & (size <= MAX_MAGNITUDE)
        if not ok_n[finite].all():
            notes.append("some given normals are zero, non-finite or absurdly long: all "
                         "normals re-estimated")
            normals = None
    if colors is not None and not ((colors[finite] >= 0) & (colors[finite] <= 1)).all():
        notes.append("colours outside [0, 1] or not finite: colour term dropped")
        colors = None
    if not finite.all():
        notes.append(f"{int((~finite).sum())} NaN/inf points left unlabelled")
    return finite, normals, colors
