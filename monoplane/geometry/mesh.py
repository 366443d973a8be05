"""Triangle meshes of a reconstruction's planes, for rendering and export.

Every planar pixel on a regular grid (every ``step``-th row and column) is lifted onto its own
plane along its pixel ray, and neighbouring grid pixels are joined into triangles when all three
corners carry the same plane label. The mesh therefore follows the label map's outline exactly
(up to ``step`` pixels) and each triangle lies exactly in one plane.

Coordinates are in the camera frame (OpenCV axes: x right, y down, z forward) and the frame's
depth units. Triangles are wound so that their geometric normal (right-hand rule) equals the
plane normal, i.e. faces the camera that saw them.

A fused multi-view scene's mesh (:func:`scene_mesh`) is the union of each global plane's view
masks on the fused plane, in the scene's world frame.
"""

from __future__ import annotations

import numpy as np

from monoplane.datamodel import (
    Reconstruction,
    Scene,
    pixel_rays,
    plane_to_camera,
    ray_plane_depth,
)
from monoplane.geometry.polygons import PlaneMesh, points_plane_mesh


def planar_mesh(
    rec: Reconstruction, step: int = 2, max_depth: float | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Triangulate the planar pixels of a reconstruction on their planes.

    Parameters
    ----------
    rec : Reconstruction
        Labels (H, W) and planes (P, 4) in the camera frame.
    step : int
        Grid spacing in pixels (>= 1); ``step=2`` keeps a quarter of the pixels as vertices.
    max_depth : float, optional
        Vertices whose planar z-depth exceeds this are dropped, which removes the long slivers a
        plane seen at a grazing angle would produce. Defaults to twice the largest valid input
        depth when the frame has depth, otherwise no limit.

    Returns
    -------
    vertices : numpy.ndarray
        (V, 3) float64 camera-frame points on their planes, depth units.
    triangles : numpy.ndarray
        (T, 3) int32 vertex indices; every triangle's corners share one plane, and its winding
        makes the right-hand normal point to the camera side of that plane.
    vertex_colors : numpy.ndarray
        (V, 3) float64 in [0, 1]: the image colour at each vertex (mid grey without RGB).
    plane_ids : numpy.ndarray
        (V,) int32 plane id of each vertex (1..P, the label value).
    """
    if step < 1:
        raise ValueError(f"step must be >= 1, got {step}")
    frame = rec.frame
    h, w = frame.shape
    rows = np.arange(0, h, step)
    cols = np.arange(0, w, step)
    labels = rec.labels[np.ix_(rows, cols)]
    rays = pixel_rays(frame.K, h, w)[np.ix_(rows, cols)]

    z = np.zeros(labels.shape)
    planar = labels > 0
    if np.any(planar):
        z[planar] = ray_plane_depth(rays[planar], rec.planes[labels[planar] - 1])
    if max_depth is None and frame.depth is not None:
        max_depth = 2.0 * float(frame.depth.max())
    if max_depth is not None:
        z[z > max_depth] = 0.0
    keep = z > 0
    lab = np.where(keep, labels, 0)

    index = np.full(lab.shape, -1, dtype=np.int64)
    index[keep] = np.arange(int(keep.sum()))
    vertices = (rays * z[..., None])[keep]
    plane_ids = lab[keep].astype(np.int32)
    if frame.rgb is not None:
        vertex_colors = frame.rgb[np.ix_(rows, cols)][keep].astype(np.float64) / 255.0
    else:
        vertex_colors = np.full((len(vertices), 3), 0.5)

    # Each grid cell (a, b / c, d) splits into triangles (a, c, b) and (b, c, d). With y down,
    # this image-space winding gives every lifted triangle a right-hand normal pointing to the
    # camera, i.e. along its plane's normal (which faces the camera by convention).
    a, b = lab[:-1, :-1], lab[:-1, 1:]
    c, d = lab[1:, :-1], lab[1:, 1:]
    ia, ib = index[:-1, :-1], index[:-1, 1:]
    ic, id_ = index[1:, :-1], index[1:, 1:]
    upper = (a > 0) & (a == b) & (a == c)
    lower = (d > 0) & (d == b) & (d == c)
    tris = np.concatenate(
        [
            np.stack([ia[upper], ic[upper], ib[upper]], axis=1),
            np.stack([ib[lower], ic[lower], id_[lower]], axis=1),
        ]
    )
    return vertices, tris.astype(np.int32).reshape(-1, 3), vertex_colors, plane_ids


def reconstruction_to_open3d(rec: Reconstruction, step: int = 2):  # -> o3d.geometry.TriangleMesh
    """The planar mesh of :func:`planar_mesh` as an Open3D triangle mesh.

    Parameters
    ----------
    rec : Reconstruction
        Labels and planes in the camera frame.
    step : int
        Pixel stride of the triangulated grid.

    Returns
    -------
    open3d.geometry.TriangleMesh
        Camera frame, depth units, vertex colours from the image, vertex normals computed.
    """
    import open3d as o3d

    vertices, triangles, colors, _ = planar_mesh(rec, step=step)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(vertices),
                                     o3d.utility.Vector3iVector(triangles))
    mesh.vertex_colors = o3d.utility.Vector3dVector(colors)
    mesh.compute_vertex_normals()
    return mesh


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
