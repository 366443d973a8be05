"""Global planes of a multi-view run: the fuser and adjuster calls, and what a fused scene
yields per plane (its surface mesh, its colour, each view's global label map).

Frames: world frame of the SfM model; cameras world-to-camera ``x_cam = R x_world + t``
(OpenCV axes); global planes ``normal . x_world + offset = 0``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from monoplane.datamodel import Reconstruction, Scene, SfmResult, plane_to_camera, ray_plane_depth
from monoplane.geometry.polygons import PlaneMesh, points_plane_mesh
from monoplane.stages.base import Adjuster, Fuser

if TYPE_CHECKING:
    from monoplane.host.pipeline import Pipeline


def fuse_and_adjust(pipe: Pipeline, views: list[Reconstruction], sfm: SfmResult,
                    scales: list[float], timings: dict[str, float]
                    ) -> tuple[Scene, Scene, SfmResult, list[Any], dict[str, Any]]:
    """Run the configured fuser, then the adjuster, on scale-aligned views.

    Parameters
    ----------
    pipe : Pipeline
        Its ``fuser`` and ``adjuster`` stages are used.
    views : list of Reconstruction
        Per registered view, its planes with the depth in scene units.
    sfm : SfmResult
        Cameras and sparse points of those views, in scene units.
    scales : list of float
        Each view's depth scale (recorded on the scene).
    timings : dict
        Receives the seconds of ``fuser`` and ``adjuster``.

    Returns
    -------
    (Scene, Scene, SfmResult, list, dict)
        The refined scene, the scene as fused (before the adjuster), the SfM result with the
        refined cameras, the plane correspondences the fuser kept and the adjuster's report.
    """
    fuser = pipe.stage("fuser", Fuser)
    fused, plane_matches = pipe.call("fuser", fuser.name,
                                     lambda: fuser.fuse_with_matches(views, sfm), "multiview",
                                     timings)
    fused.scales = list(scales)
    adjuster = pipe.stage("adjuster", Adjuster)
    scene, sfm, adjustment = pipe.call("adjuster", adjuster.name,
                                       lambda: adjuster.adjust(fused, sfm), "multiview", timings)
    return scene, fused, sfm, plane_matches, adjustment


def scene_mesh(scene: Scene, step: int = 2, max_cells: int = 512) -> PlaneMesh:
    """Every global plane's surface: the union of its views' masks on the fused plane.

    Every ``step``-th mask pixel of each linked view plane is lifted along its ray onto the
    fused plane (pixels whose lifted depth disagrees with the view's own plane by more than a
    factor 2 are dropped, which removes grazing-angle slivers). The union is triangulated by
    :func:`~monoplane.geometry.polygons.points_plane_mesh` at about the pixel footprint, holes
    left open.

    Parameters
    ----------
    scene : Scene
        Fused scene.
    step : int
        Pixel stride used when lifting masks.
    max_cells : int
        Cap on the raster size per side.

    Returns
    -------
    PlaneMesh
        World-frame triangles; ``plane_ids`` are global plane ids (0-based, as in scene.json).
    """
    from monoplane.datamodel import pixel_rays

    members: dict[int, list[tuple[int, int]]] = {}
    for v, table in enumerate(scene.links):
        for local, glob in table.items():
            members.setdefault(glob, []).append((v, local))
    rays_cache: dict[int, np.ndarray] = {}
    parts = []
    for g, plane in enumerate(scene.planes):
        points, footprints = [], []
        for v, local in members.get(g, []):
            rec, cam = scene.views[v], scene.cameras[v]
            if v not in rays_cache:
                rays_cache[v] = pixel_rays(cam.K, cam.height, cam.width)[::step, ::step]
            mask = rec.labels[::step, ::step] == local
            rays = rays_cache[v][mask]
            z = ray_plane_depth(rays, plane_to_camera(plane, cam.R, cam.t)[0])
            z_own = ray_plane_depth(rays, rec.planes[local - 1])
            ok = (z > 0) & (z_own > 0) & (z < 2 * z_own) & (z_own < 2 * z)
            if not np.any(ok):
                continue
            x_cam = rays[ok] * z[ok, None]
            points.append((x_cam - cam.t) @ cam.R)
            footprints.append(np.median(z[ok]) * step / cam.K[0, 0])
        if points:
            verts, tris = points_plane_mesh(np.concatenate(points), plane,
                                            float(np.median(footprints)), max_cells=max_cells)
            parts.append((g, verts, tris))
    return PlaneMesh.concatenate(parts)


def scene_plane_colors(scene: Scene) -> np.ndarray:
    """(G, 3) uint8 area-weighted mean colour of each global plane over its views."""
    g = scene.planes.shape[0]
    sums = np.zeros((g, 3))
    weights = np.zeros(g)
    for v, table in enumerate(scene.links):
        colors, area = scene.views[v].colors, scene.views[v].area_px
        for local, glob in table.items():
            sums[glob] += area[local - 1] * colors[local - 1]
            weights[glob] += area[local - 1]
    out = np.full((g, 3), 128, np.uint8)
    ok = weights > 0
    out[ok] = np.clip(sums[ok] / weights[ok, None], 0, 255).astype(np.uint8)
    return out

def global_label_map(labels: np.ndarray, links: dict[int, int]) -> np.ndarray:
    """(H, W) uint16 map of global plane ids + 1 (0 = non-planar) from a view's local labels."""
    lut = np.zeros(int(labels.max()) + 1, dtype=np.uint16)
    for local, glob in links.items():
        if local < len(lut):
            lut[local] = glob + 1
    return lut[labels]
