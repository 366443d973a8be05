"""What several output formats of one result need, computed once per save."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class SharedWork:
    """What several formats of one result need, computed once per :func:`~monoplane.export.save`.

    The plane meshes of a result feed both its PLY and its glTF file; an exporter asks for them
    here rather than triangulating the planes again.
    """

    _meshes: dict[int, Any] = field(default_factory=dict)

    def mesh(self, result: Any):  # -> monoplane.geometry.polygons.PlaneMesh
        """The plane regions of ``result`` as triangles, faces tagged with the plane ids.

        A frame's regions on their planes in the camera frame
        (:func:`~monoplane.geometry.polygons.reconstruction_mesh`), a cloud's in its own frame
        (:func:`~monoplane.geometry.cloud_mesh.cloud_mesh`), a multi-view result's global
        planes in the world frame (:func:`~monoplane.multiview.fusion.scene_mesh`).
        """
        key = id(result)
        if key not in self._meshes:
            kind = result.result_kind
            if kind == "frame":
                from monoplane.geometry.polygons import reconstruction_mesh

                self._meshes[key] = reconstruction_mesh(result)
            elif kind == "cloud":
                from monoplane.geometry.cloud_mesh import cloud_mesh

                self._meshes[key] = cloud_mesh(result)
            else:
                from monoplane.geometry.mesh import scene_mesh

                scene = result.scene if kind == "multiview" else result
                self._meshes[key] = scene_mesh(scene)
        return self._meshes[key]
