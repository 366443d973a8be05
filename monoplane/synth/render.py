"""Ray-cast rendering of a :class:`~monoplane.synth.scene.Layout` with exact geometry.

Open3D's ``RaycastingScene`` runs on the CPU. Rays are the pinhole rays ``K^-1 [u, v, 1]`` (camera
z component 1) rotated into the world, so ``t_hit`` is the z-depth directly. On planar surfaces
the depth and normal are then recomputed in float64 from the surface's exact plane, so they agree
with the ground-truth plane parameters to rounding; curved surfaces keep the ray-cast depth of
their (fine) mesh and the interpolated analytic vertex normals.

Colour: procedural albedo (see :mod:`monoplane.synth.texture`) under an ambient term plus one
point light with distance falloff and hard shadows, then mild sensor noise. Lighting is
Lambertian, so a surface point looks the same from every view.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from monoplane.datamodel import pixel_rays, plane_to_camera
from monoplane.synth.scene import Layout

if TYPE_CHECKING:
    import open3d as o3d

_AMBIENT = 0.35
_DIFFUSE = 0.8
_FALLOFF = 0.06  # 1 / (1 + k r^2) light attenuation, r in metres
_SHADOW = 0.45  # fraction of the direct light kept in shadow (soft bounce light)
_SENSOR_NOISE = 1.5  # std of additive noise, 8-bit levels


def _rows_times(x: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``x @ M`` for (N, 3) rows, spelled out: numpy hands ``(N, 3) @ (3, 3)`` to OpenBLAS, which
    was measured 15x slower than this for 300k rows on the 2-core test machine."""
    return x[:, :1] * M[0] + x[:, 1:2] * M[1] + x[:, 2:] * M[2]


@dataclass
class RenderedView:
    """Exact per-pixel output of one camera.

    Attributes
    ----------
    rgb : numpy.ndarray
        (H, W, 3) uint8 image.
    depth : numpy.ndarray
        (H, W) float32 z-depth in metres (every pixel hits the closed room).
    normals : numpy.ndarray
        (H, W, 3) float32 unit normals in the camera frame (x right, y down, z forward), facing
        the camera.
    surface : numpy.ndarray
        (H, W) int32 index into ``layout.surfaces``.
    planes_cam : numpy.ndarray
        (S, 4) float64 camera-frame plane of every surface (NaN rows for curved surfaces).
    """

    rgb: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    surface: np.ndarray
    planes_cam: np.ndarray


def make_raycaster(layout: Layout) -> o3d.t.geometry.RaycastingScene:
    """Build the ray-casting acceleration structure of a layout (shared by its views)."""
    import open3d as o3d  # seconds to import: only when a scene is rendered

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(layout.vertices), o3d.core.Tensor(layout.triangles))
    return scene


def world_planes(layout: Layout) -> np.ndarray:
    """(S, 4) float64 world plane of every surface, NaN rows for curved surfaces."""
    out = np.full((len(layout.surfaces), 4), np.nan)
    for i, s in enumerate(layout.surfaces):
        if s.plane is not None:
            out[i] = s.plane
    return out


def render_view(raycaster: o3d.t.geometry.RaycastingScene, layout: Layout, K: np.ndarray,
                R: np.ndarray, t: np.ndarray, width: int, height: int,
                rng: np.random.Generator) -> RenderedView:
    """Render one pinhole view.

    Parameters
    ----------
    raycaster : open3d.t.geometry.RaycastingScene
        From :func:`make_raycaster` for ``layout``.
    layout : Layout
    K : numpy.ndarray
        (3, 3) intrinsics in pixels.
    R, t : numpy.ndarray
        World-to-camera pose, ``x_cam = R x_world + t`` (OpenCV camera axes).
    width, height : int
        Image size in pixels.
    rng : numpy.random.Generator
        Source of the sensor noise.

    Returns
    -------
    RenderedView
    """
    import open3d as o3d  # loaded already by make_raycaster

    rays_cam = pixel_rays(K, height, width).reshape(-1, 3)
    center = -R.T @ t
    # World direction R^T d of every ray; its camera-z component stays 1, so t_hit is z-depth.
    dirs = _rows_times(rays_cam, R)
    rays = np.concatenate([np.broadcast_to(center, dirs.shape), dirs], axis=1)
    hit = raycaster.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
    t_hit = hit["t_hit"].numpy().astype(np.float64)
    if not np.all(np.isfinite(t_hit)):
        raise RuntimeError(f"{int(np.sum(~np.isfinite(t_hit)))} rays escaped the room")
    prim = hit["primitive_ids"].numpy().astype(np.int64)
    bary = hit["primitive_uvs"].numpy().astype(np.float64)
    surface = layout.tri_surface[prim]

    tri = layout.triangles[prim]
    vn = layout.vertex_normals.astype(np.float64)
    n_w = ((1.0 - bary[:, :1] - bary[:, 1:]) * vn[tri[:, 0]] + bary[:, :1] * vn[tri[:, 1]]
           + bary[:, 1:] * vn[tri[:, 2]])
    depth = t_hit.copy()

    planes_w = world_planes(layout)
    planes_c = np.full_like(planes_w, np.nan)
    planar_ids = np.flatnonzero(np.isfinite(planes_w[:, 0]))
    planes_c[planar_ids] = plane_to_camera(planes_w[planar_ids], R, t)
    planar_px = np.isfinite(planes_w[surface, 0])
    pc = planes_c[surface[planar_px]]
    depth[planar_px] = -pc[:, 3] / np.einsum("ij,ij->i", rays_cam[planar_px], pc[:, :3])
    n_w[planar_px] = planes_w[surface[planar_px], :3]
    n_w /= np.sqrt(np.einsum("ij,ij->i", n_w, n_w))[:, None]
    # Mesh normals of curved objects point outwards, which faces the camera; the flip only
    # guards grazing silhouette pixels where interpolation can tip them over.
    facing = np.where(np.einsum("ij,ij->i", n_w, dirs) > 0, -1.0, 1.0)
    n_w *= facing[:, None]
    n_c = _rows_times(n_w, R.T)

    points = center + depth[:, None] * dirs
    albedo = np.zeros_like(points)
    order = np.argsort(surface, kind="stable")
    sids, starts = np.unique(surface[order], return_index=True)
    for sid, idx in zip(sids, np.split(order, starts[1:]), strict=True):
        surf = layout.surfaces[sid]
        albedo[idx] = surf.material.albedo(surf.texture_coords(points[idx]))

    to_light = layout.light - points
    dist = np.sqrt(np.einsum("ij,ij->i", to_light, to_light))
    lambert = np.clip(np.einsum("ij,ij->i", n_w, to_light) / dist, 0.0, None)
    shadow_rays = np.concatenate([np.broadcast_to(layout.light, points.shape), -to_light], axis=1)
    occluded = raycaster.test_occlusions(o3d.core.Tensor(shadow_rays.astype(np.float32)),
                                         tnear=0.0, tfar=0.998).numpy()
    direct = lambert / (1.0 + _FALLOFF * dist**2) * np.where(occluded, _SHADOW, 1.0)
    shade = _AMBIENT + _DIFFUSE * direct
    rgb = 255.0 * albedo * shade[:, None] + rng.normal(0.0, _SENSOR_NOISE, albedo.shape)
    rgb = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)

    return RenderedView(
        rgb=rgb.reshape(height, width, 3),
        depth=depth.reshape(height, width).astype(np.float32),
        normals=n_c.reshape(height, width, 3).astype(np.float32),
        surface=surface.reshape(height, width).astype(np.int32),
        planes_cam=planes_c,
    )
