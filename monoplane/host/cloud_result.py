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


def _moved(method: str, new: str) -> None:
    warnings.warn(f"CloudPlaneResult.{method}() is deprecated; use {new}(result) (the method "
                  "goes in 0.3.0)", DeprecationWarning, stacklevel=3)


class CloudPlaneResult(CloudResult):
    """Deprecated name of :class:`~monoplane.datamodel.CloudResult` (same fields; ``num_points``
    is now ``support``), with its former methods."""

    def plane_colors(self) -> np.ndarray:
        """Deprecated: :func:`monoplane.export.open3d_objects.cloud_plane_colors`."""
        from monoplane.export.open3d_objects import cloud_plane_colors

        _moved("plane_colors", "monoplane.export.open3d_objects.cloud_plane_colors")
        return cloud_plane_colors(self)

    def to_open3d(self):  # -> open3d.geometry.PointCloud
        """Deprecated: :func:`monoplane.export.open3d_objects.cloud_to_open3d`."""
        from monoplane.export.open3d_objects import cloud_to_open3d

        _moved("to_open3d", "monoplane.export.open3d_objects.cloud_to_open3d")
        return cloud_to_open3d(self)

    def plane_mesh(self, cell: float | None = None):  # -> PlaneMesh
        """Deprecated: :func:`monoplane.geometry.cloud_mesh.cloud_mesh`."""
        from monoplane.geometry.cloud_mesh import cloud_mesh

        _moved("plane_mesh", "monoplane.geometry.cloud_mesh.cloud_mesh")
        return cloud_mesh(self, cell)

    def plane_meshes(self, cell: float | None = None) -> list:
        """Deprecated: :func:`monoplane.export.open3d_objects.cloud_plane_meshes`."""
        from monoplane.export.open3d_objects import cloud_plane_meshes

        _moved("plane_meshes", "monoplane.export.open3d_objects.cloud_plane_meshes")
        return cloud_plane_meshes(self, cell)

    def planes_document(self) -> dict[str, Any]:
        """Deprecated: :func:`monoplane.export.labels.planes_document`."""
        from monoplane.export.labels import planes_document

        _moved("planes_document", "monoplane.export.labels.planes_document")
        return planes_document(self)
