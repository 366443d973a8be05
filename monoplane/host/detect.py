"""Planes of a point cloud: :func:`detect_planes` for Open3D clouds and (N, 3) arrays.

The cloud goes through the same pipeline as an image, without the pixel grid
(:meth:`monoplane.host.pipeline.Pipeline.run_cloud`): its distinct finite points are
normalised into the unit sphere and subsampled to ``ransac.max_points``, missing normals are
estimated and oriented (``[cloud]``, :class:`~monoplane.host.cloud_config.CloudConfig`;
:mod:`monoplane.host.cloud_input`), the sequential RANSAC, the refiner's ``refine_cloud``
(which must not need pixels; the ``cloud`` preset uses ``graph-crf``) and the planarity test
run on the subsample's kNN graph, and every input point is labelled: a point takes, among the
planes of its few nearest sampled points, the one it is closest to, if its nearest sample is
planar and near enough. Planes are refit by least squares on all their points, in the cloud's
own frame and units.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monoplane.geometry.neighbours import PointIndex
from monoplane.geometry.polygons import PlaneMesh, points_plane_mesh
from monoplane.host.pipeline import Pipeline
from monoplane.palette import NON_PLANAR, plane_palette


@dataclass
class CloudPlaneResult:
    """Planes detected in a point cloud.

    Attributes
    ----------
    points : numpy.ndarray
        (N, 3) float64 input points, input order (non-finite ones included).
    labels : numpy.ndarray
        (N,) int32 plane of each input point, 1..P, 0 = no plane (also for NaN/inf points).
    planes : numpy.ndarray
        (P, 4) float64 ``n · x + d = 0`` with unit ``n``, in the cloud's frame and units;
        ``n`` points to the side the points' normals face.
    rmse : numpy.ndarray
        (P,) RMS point-to-plane distance of each plane's points, input units.
    num_points : numpy.ndarray
        (P,) int64 points per plane.
    centroids : numpy.ndarray
        (P, 3) mean of each plane's points.
    colors : numpy.ndarray or None
        (N, 3) input colours in [0, 1], if any.
    notes : list of str
        What was done to the input (dropped points, estimated normals...).
    config : dict
        The resolved configuration.
    timings : dict
        Seconds per step.
    """

    points: np.ndarray
    labels: np.ndarray
    planes: np.ndarray
    rmse: np.ndarray
    num_points: np.ndarray
    centroids: np.ndarray
    colors: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    config: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def num_planes(self) -> int:
        """Number P of planes."""
        return int(self.planes.shape[0])

    def plane_colors(self) -> np.ndarray:
        """(P + 1, 3) float colours in [0, 1]: row 0 (no plane) grey, then one per plane."""
        lut = np.vstack([NON_PLANAR[None], plane_palette(self.num_planes)])
        return lut.astype(np.float64) / 255.0

    def to_open3d(self):  # -> open3d.geometry.PointCloud
        """The finite input points as an Open3D cloud coloured by plane (grey: no plane)."""
        import open3d as o3d

        finite = np.isfinite(self.points).all(axis=1)
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.points[finite]))
        pcd.colors = o3d.utility.Vector3dVector(self.plane_colors()[self.labels[finite]])
        return pcd

    def plane_mesh(self, cell: float | None = None) -> PlaneMesh:
        """Every plane's area as triangles on the plane, holes left open, faces tagged by plane.

        Each plane's points are projected onto it, rasterised on a grid of ``cell`` (default:
        twice the median point spacing) and outlined with their holes
        (:func:`monoplane.geometry.polygons.points_plane_mesh`).

        Returns
        -------
        PlaneMesh
            Vertices in the cloud's frame and units; ``plane_ids`` 1..P.
        """
        finite = np.isfinite(self.points).all(axis=1)
        if cell is None:
            pts = self.points[finite & (self.labels > 0)]
            if len(pts) >= 2:
                d, _ = PointIndex(pts).query(pts[:: max(1, len(pts) // 2000)], k=2)
                cell = 2.0 * float(np.median(d[:, 1]))
            cell = cell if cell and cell > 0 else 1.0
        parts = []
        for pid in range(1, self.num_planes + 1):
            verts, tris = points_plane_mesh(self.points[self.labels == pid],
                                            self.planes[pid - 1], cell)
            parts.append((pid, verts, tris))
        return PlaneMesh.concatenate(parts)

    def plane_meshes(self, cell: float | None = None) -> list:
        """One Open3D triangle mesh per plane (see :meth:`plane_mesh`), coloured by plane.

        Returns
        -------
        list of open3d.geometry.TriangleMesh
            Index ``i`` is plane ``i + 1``; an empty mesh when a plane has no outline.
        """
        import open3d as o3d

        mesh = self.plane_mesh(cell)
        colors = self.plane_colors()
        meshes = []
        for pid in range(1, self.num_planes + 1):
            tris = mesh.triangles[mesh.plane_ids == pid]
            used, inverse = np.unique(tris, return_inverse=True)
            part = o3d.geometry.TriangleMesh()
            if len(used):
                part.vertices = o3d.utility.Vector3dVector(mesh.vertices[used])
                part.triangles = o3d.utility.Vector3iVector(
                    inverse.reshape(-1, 3).astype(np.int32))
                part.paint_uniform_color(colors[pid])
                part.compute_vertex_normals()
            meshes.append(part)
        return meshes

    def planes_document(self) -> dict[str, Any]:
        """JSON-ready description: one entry per plane (normal, offset, num_points, rmse)."""
        return {
            "num_points": int(self.points.shape[0]),
            "num_planes": self.num_planes,
            "planes": [
                {"id": i + 1, "normal": self.planes[i, :3].tolist(),
                 "offset": float(self.planes[i, 3]), "num_points": int(self.num_points[i]),
                 "rmse": float(self.rmse[i]), "centroid": self.centroids[i].tolist()}
                for i in range(self.num_planes)
            ],
            "notes": list(self.notes),
            "config": self.config,
        }


def detect_planes(cloud: Any, preset: str = "cloud",
                  overrides: dict[str, Any] | list[str] | None = None,
                  pm: Any | None = None) -> CloudPlaneResult:
    """Detect planes in a point cloud with MonoPlane's graph-cut RANSAC.

    Parameters
    ----------
    cloud : open3d.geometry.PointCloud, open3d.t.geometry.PointCloud or array_like
        (N, 3) points in any frame and unit; normals and colours (in [0, 1], or 8-bit for
        tensor clouds) are used when present. Without normals they are estimated (see
        :class:`~monoplane.host.cloud_config.CloudConfig`); without colours the colour term
        is dropped.
    preset : str
        Config preset (default ``cloud``); its refiner must work without pixels.
    overrides : dict or list of str, optional
        ``table.key`` overrides, e.g. ``{"ransac.epsilon": 0.01, "cloud.orient": "consistent"}``.
    pm : pluggy.PluginManager, optional
        Plugin manager providing the stages.

    Returns
    -------
    CloudPlaneResult
        Labels in the input order, planes in the cloud's frame and units, statistics.

    Raises
    ------
    InvalidInput
        Fewer than 3 distinct finite points, or a malformed cloud.
    ConfigError
        Bad overrides, or a refiner that needs pixels (e.g. ``dense-crf``).
    """
    pipe = Pipeline.from_preset(preset, overrides=overrides, pm=pm)
    fit = pipe.run_cloud(cloud)
    return CloudPlaneResult(points=fit.points, labels=fit.labels, planes=fit.planes,
                            rmse=fit.rmse, num_points=fit.support, centroids=fit.centroids,
                            colors=fit.colors, notes=fit.notes, config=pipe.config.to_dict(),
                            timings=fit.timings)
