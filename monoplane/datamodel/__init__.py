"""The data model that flows between stages: Frame, Reconstruction, CloudResult, Camera, Scene,
SfmResult, and the plane-set vocabulary they share (:mod:`.planeset`).

Conventions used everywhere in monoplane
----------------------------------------
* Camera frame is OpenCV's: x right, y down, z forward (into the scene).
* Pixel ``(u, v)`` is column ``u``, row ``v``; pixel centres are at integer coordinates.
* A plane is ``(n, d)`` with ``n · X + d = 0`` for points ``X`` on it, ``|n| = 1`` and ``n``
  facing the camera, i.e. ``n · X < 0`` on the plane, hence ``d > 0`` for planes that do not
  pass through the camera centre.
* Depth is z-depth (distance along the optical axis), not ray length. ``0`` marks an invalid
  pixel. Plane offsets are in the depth's units.

This package imports nothing of the project but :mod:`monoplane.errors` and
:mod:`monoplane.jit` (which loads numba only when a kernel first runs), so every other module
can depend on it. Writing outputs lives in :mod:`monoplane.io.frames`
(``monoplane.save_reconstruction``) and meshes in :mod:`monoplane.geometry.mesh`
(``reconstruction_to_open3d``).
"""

from __future__ import annotations

from monoplane.datamodel.cloud import CloudResult
from monoplane.datamodel.frame import DEPTH_KINDS, DepthKind, Frame
from monoplane.datamodel.pinhole import (
    Camera,
    default_intrinsics,
    intrinsics_matrix,
    pixel_rays,
    plane_to_camera,
    plane_to_world,
    ray_plane_depth,
)
from monoplane.datamodel.planeset import RESULT_KINDS, PlaneSet
from monoplane.datamodel.reconstruction import Reconstruction, orient_towards_camera
from monoplane.datamodel.scene import Scene, SfmResult, global_label_map, scene_plane_colors

__all__ = [
    "DEPTH_KINDS", "RESULT_KINDS", "Camera", "CloudResult", "DepthKind", "Frame", "PlaneSet",
    "Reconstruction", "Scene", "SfmResult",
    "default_intrinsics", "global_label_map", "intrinsics_matrix", "orient_towards_camera",
    "pixel_rays", "plane_to_camera", "plane_to_world", "ray_plane_depth", "scene_plane_colors",
]
