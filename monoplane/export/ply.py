"""The ``ply`` output format: plane regions as ASCII PLY triangle meshes, points as PLY clouds.

* a frame: ``planes.ply``, every plane region triangulated on its plane with its holes left
  open, each face carrying its ``plane_id`` (:func:`~monoplane.export.files.write_plane_mesh_ply`);
* a point cloud: ``planes.ply`` likewise, and ``labelled.ply``, the points coloured by plane
  (grey: no plane);
* a multi-view result: ``scene.ply`` (the global planes, ids 0..G-1, in the world frame) and
  ``points.ply`` (the sparse SfM points).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from monoplane.contracts.exporter import Exporter
from monoplane.datamodel import scene_plane_colors
from monoplane.errors import InvalidInput
from monoplane.export.files import write_plane_mesh_ply, write_points_ply
from monoplane.export.shared import SharedWork
from monoplane.geometry.open3d_objects import cloud_plane_colors, cloud_to_open3d
from monoplane.hookspecs import hookimpl


def _write(result: Any, folder: Path, shared: SharedWork) -> None:
    kind = result.result_kind
    mesh = shared.mesh(result)
    if kind == "frame":
        write_plane_mesh_ply(folder / "planes.ply", mesh, result.colors)
    elif kind == "cloud":
        import open3d as o3d

        if not o3d.io.write_point_cloud(str(folder / "labelled.ply"), cloud_to_open3d(result)):
            raise InvalidInput(f"cannot write {folder / 'labelled.ply'}")
        colors = np.round(cloud_plane_colors(result)[1:] * 255).astype(np.uint8)
        write_plane_mesh_ply(folder / "planes.ply", mesh, colors)
    else:
        write_plane_mesh_ply(folder / "scene.ply", mesh, scene_plane_colors(result.scene),
                             first_id=0)
        write_points_ply(folder / "points.ply", result.sfm.points, result.sfm.colors)


EXPORTER = Exporter(
    name="ply",
    files={"frame": ("planes.ply",), "cloud": ("labelled.ply", "planes.ply"),
           "multiview": ("scene.ply", "points.ply")},
    write=_write,
    summary="plane regions as PLY triangle meshes (faces tagged plane_id); points as PLY",
)


@hookimpl
def monoplane_register_exporters() -> list[Exporter]:
    return [EXPORTER]
