"""``CloudPlaneResult``: the former name of :class:`monoplane.datamodel.CloudResult`, kept until
0.3.0 with its former methods.

:func:`monoplane.detect_planes` returns this subclass for one release so that code calling the
old methods keeps working; each method warns and names its replacement, a function outside the
data model (which imports nothing of the geometry, export or report layers).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from monoplane.datamodel import CloudResult
from monoplane.geometry.cloud_mesh import cloud_mesh
from monoplane.geometry.open3d_objects import (
    cloud_plane_colors,
    cloud_plane_meshes,
    cloud_to_open3d,
)


def _moved(method: str, new: str) -> None:
    warnings.warn(f"CloudPlaneResult.{method}() is deprecated; use {new}(result) (the method "
                  "goes in 0.3.0)", DeprecationWarning, stacklevel=3)


class CloudPlaneResult(CloudResult):
    """Deprecated name of :class:`~monoplane.datamodel.CloudResult` (same fields; ``num_points``
    is now ``support``), with its former methods."""

    def plane_colors(self) -> np.ndarray:
        """Deprecated: :func:`monoplane.geometry.open3d_objects.cloud_plane_colors`."""
        _moved("plane_colors", "monoplane.geometry.open3d_objects.cloud_plane_colors")
        return cloud_plane_colors(self)

    def to_open3d(self):  # -> open3d.geometry.PointCloud
        """Deprecated: :func:`monoplane.geometry.open3d_objects.cloud_to_open3d`."""
        _moved("to_open3d", "monoplane.geometry.open3d_objects.cloud_to_open3d")
        return cloud_to_open3d(self)

    def plane_mesh(self, cell: float | None = None):  # -> PlaneMesh
        """Deprecated: :func:`monoplane.geometry.cloud_mesh.cloud_mesh`."""
        _moved("plane_mesh", "monoplane.geometry.cloud_mesh.cloud_mesh")
        return cloud_mesh(self, cell)

    def plane_meshes(self, cell: float | None = None) -> list:
        """Deprecated: :func:`monoplane.geometry.open3d_objects.cloud_plane_meshes`."""
        _moved("plane_meshes", "monoplane.geometry.open3d_objects.cloud_plane_meshes")
        return cloud_plane_meshes(self, cell)

    def planes_document(self) -> dict[str, Any]:
        """Deprecated: the document the former method gave (``planes.json`` of ``monoplane
        cloud`` is now written by the ``labels`` format, with more fields)."""
        _moved("planes_document", "the labels format's planes_document (monoplane.export)")
        return {
            "num_points": int(self.points.shape[0]),
            "num_planes": self.num_planes,
            "planes": [
                {"id": i + 1, "normal": self.planes[i, :3].tolist(),
                 "offset": float(self.planes[i, 3]), "num_points": int(self.support[i]),
                 "rmse": float(self.rmse[i]), "centroid": self.centroids[i].tolist()}
                for i in range(self.num_planes)
            ],
            "notes": list(self.notes),
            "config": self.config,
        }
