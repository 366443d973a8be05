"""A point cloud's planes as Open3D objects, in the plane palette (grey: no plane)."""

from __future__ import annotations

import numpy as np

from monoplane.datamodel import CloudResult
from monoplane.geometry.cloud_mesh import cloud_mesh
from monoplane.palette import NON_PLANAR, plane_palette


def cloud_plane_colors(result: CloudResult) -> np.ndarray:
    """(P + 1, 3) float colours in [0, 1]: row 0 (no plane) grey, then one per plane."""
    lut = np.vstack([NON_PLANAR[None], plane_palette(result.num_planes)])
    return lut.astype(np.float64) / 255.0


def cloud_to_open3d(result: CloudResult):  # -> open3d.geometry.PointCloud
    """The finite input points as an Open3D cloud coloured by plane (grey: no plane)."""
    import open3d as o3d

    finite = np.isfinite(result.points).all(axis=1)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(result.points[finite]))
    pcd.colors = o3d.utility.Vector3dVector(cloud_plane_colors(result)[result.labels[finite]])
    return pcd


def cloud_plane_meshes(result: CloudResult, cell: float | None = None) -> list:
    """One Open3D triangle mesh per plane (see :func:`~monoplane.geometry.cloud_mesh.cloud_mesh`),
    coloured by plane.

    Returns
    -------
    list of open3d.geometry.TriangleMesh
        Index ``i`` is plane ``i + 1``; an empty mesh when a plane has no outline.
    """
    import open3d as o3d

    mesh = cloud_mesh(result, cell)
    colors = cloud_plane_colors(result)
    meshes = []
    for pid in range(1, result.num_planes + 1):
        tris = mesh.triangles[mesh.plane_ids == pid]
        used, inverse = np.unique(tris, return_inverse=True)
        part = o3d.geometry.TriangleMesh()
        if len(used):
            part.vertices = o3d.utility.Vector3dVector(mesh.vertices[used])
            part.triangles = o3d.utility.Vector3iVector(inverse.reshape(-1, 3).astype(np.int32))
            part.paint_uniform_color(colors[pid])
            part.compute_vertex_normals()
        meshes.append(part)
    return meshes
