"""A point cloud as :func:`monoplane.host.detect.detect_planes` takes it: arrays from Open3D
clouds or array-likes, and normals estimated where none are given."""

from __future__ import annotations

from typing import Any

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.geometry.orientation import orient_normals
from monoplane.host.cloud_config import CloudConfig


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
