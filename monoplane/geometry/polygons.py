"""Plane regions as triangle meshes: outlines with holes, triangulated on their planes.

A plane region is a 2D occupancy (a label mask in the image, or points rasterised on the plane).
Its outlines come from OpenCV's two-level contour hierarchy (``RETR_CCOMP``: outer boundaries
and the holes inside them), are simplified with Douglas–Peucker, triangulated with ``earcut``
(mapbox-earcut) so that holes stay open, and then placed on the plane. A wall's mesh therefore
leaves out the box standing in front of it.

Two entry points share that path:

* :func:`mask_plane_mesh`: an image mask lifted along the pixel rays onto the plane (camera
  frame, depth units);
* :func:`points_plane_mesh`: 3D points near a plane, projected onto it and rasterised into an
  occupancy grid of a given cell size (any frame, e.g. a fused multi-view scene or a point
  cloud).

Every triangle is wound so that its right-hand normal is the plane normal ``n`` of
``n·X + d = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import mapbox_earcut
import numpy as np

from monoplane.datamodel import Reconstruction, ray_plane_depth


@dataclass
class PlaneMesh:
    """Triangles of several plane regions, each face tagged with its plane.

    Attributes
    ----------
    vertices : numpy.ndarray
        (V, 3) float64 points on their planes.
    triangles : numpy.ndarray
        (T, 3) int64 vertex indices; each triangle's right-hand normal is its plane's normal.
    plane_ids : numpy.ndarray
        (T,) int64 plane id of each face (the label value, or the caller's id).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    plane_ids: np.ndarray

    @classmethod
    def empty(cls) -> PlaneMesh:
        """A mesh without faces."""
        return cls(np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64))

    @classmethod
    def concatenate(cls, parts: list[tuple[int, np.ndarray, np.ndarray]]) -> PlaneMesh:
        """Join ``(plane_id, vertices (V, 3), triangles (T, 3))`` parts into one mesh."""
        parts = [p for p in parts if len(p[2])]
        if not parts:
            return cls.empty()
        offsets = np.cumsum([0] + [len(v) for _, v, _ in parts[:-1]])
        return cls(np.concatenate([v for _, v, _ in parts]).astype(np.float64),
                   np.concatenate([t + o for (_, _, t), o in zip(parts, offsets, strict=True)]),
                   np.concatenate([np.full(len(t), pid, np.int64) for pid, _, t in parts]))


def plane_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane, with ``e1 × e2 = normal`` (``normal`` unit, (3,))."""
    a = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(normal, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)


def mask_outlines(mask: np.ndarray, tolerance: float = 1.5
                  ) -> list[tuple[np.ndarray, list[np.ndarray]]]:
    """Outer boundaries of a binary mask's regions, each with the holes inside it.

    Parameters
    ----------
    mask : numpy.ndarray
        (H, W) bool or integer, non-zero inside.
    tolerance : float
        Douglas–Peucker tolerance in pixels; holes that simplify to fewer than 3 vertices are
        dropped.

    Returns
    -------
    list of (numpy.ndarray, list of numpy.ndarray)
        ``(outer (V, 2), [hole (Vh, 2), ...])`` float64 ``(x, y)`` pixel coordinates of boundary
        pixel centres, one entry per connected region (8-connected). An island inside a hole is
        a region of its own.
    """
    grid = np.ascontiguousarray(mask != 0, dtype=np.uint8)
    contours, hierarchy = cv2.findContours(grid, cv2.RETR_CCOMP, cv2.CHAIN_APPROX_SIMPLE)
    if hierarchy is None:
        return []
    hierarchy = hierarchy.reshape(-1, 4)  # next, previous, first child, parent

    def simplified(i: int) -> np.ndarray:
        return cv2.approxPolyDP(contours[i], tolerance, True).reshape(-1, 2).astype(np.float64)

    out = []
    for i, (_, _, child, parent) in enumerate(hierarchy):
        if parent != -1:
            continue
        outer = simplified(i)
        if len(outer) < 3:
            continue
        holes = []
        while child != -1:
            hole = simplified(child)
            if len(hole) >= 3:
                holes.append(hole)
            child = hierarchy[child, 0]
        out.append((outer, holes))
    return out


def triangulate_outline(outer: np.ndarray, holes: list[np.ndarray]
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate a 2D polygon with holes (earcut).

    Parameters
    ----------
    outer : numpy.ndarray
        (V, 2) outer ring, either winding, not closed (first vertex not repeated).
    holes : list of numpy.ndarray
        (Vh, 2) rings inside it.

    Returns
    -------
    vertices : numpy.ndarray
        (V + sum Vh, 2) float64: the outer ring then each hole.
    triangles : numpy.ndarray
        (T, 3) int64 indices into ``vertices``, counter-clockwise in the ``(x, y)`` axes;
        empty for a degenerate (zero-area) outline.
    """
    rings = [np.asarray(outer, np.float64)] + [np.asarray(h, np.float64) for h in holes]
    vertices = np.concatenate(rings)
    ends = np.cumsum([len(r) for r in rings]).astype(np.uint32)
    tris = mapbox_earcut.triangulate_float64(vertices, ends).astype(np.int64).reshape(-1, 3)
    a, b, c = (vertices[tris[:, k]] for k in range(3))
    cross = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    tris = tris[cross != 0]
    flip = cross[cross != 0] < 0
    tris[flip] = tris[flip][:, ::-1]
    return vertices, tris


def _wind_along(vertices: np.ndarray, triangles: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Reorder each triangle so that its right-hand normal points along ``normal``."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    flip = np.cross(b - a, c - a) @ normal < 0
    out = triangles.copy()
    out[flip] = out[flip][:, ::-1]
    return out


def mask_plane_mesh(mask: np.ndarray, plane: np.ndarray, K: np.ndarray,
                    tolerance_px: float = 1.5) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate an image region on its plane, holes left open.

    Parameters
    ----------
    mask : numpy.ndarray
        (H, W) bool, the region's pixels.
    plane : numpy.ndarray
        (4,) ``(n, d)`` with ``n·X + d = 0``, camera frame (OpenCV axes), depth units.
    K : numpy.ndarray
        (3, 3) intrinsics.
    tolerance_px : float
        Outline simplification tolerance in pixels.

    Returns
    -------
    vertices : numpy.ndarray
        (V, 3) float64 camera-frame points on the plane.
    triangles : numpy.ndarray
        (T, 3) int64; right-hand normals along ``n``. An outline with a vertex whose ray misses
        the plane's visible half-space is left out.
    """
    K_inv = np.linalg.inv(K)
    n = np.asarray(plane[:3], np.float64)
    parts = []
    for outer, holes in mask_outlines(mask, tolerance_px):
        flat, tris = triangulate_outline(outer, holes)
        rays = np.c_[flat, np.ones(len(flat))] @ K_inv.T
        z = ray_plane_depth(rays, plane)
        if not np.all(z > 0):
            continue  # the outline leaves the plane's visible half-space
        verts = rays * z[:, None]
        parts.append((0, verts, _wind_along(verts, tris, n)))
    mesh = PlaneMesh.concatenate(parts)
    return mesh.vertices, mesh.triangles


def points_plane_mesh(points: np.ndarray, plane: np.ndarray, cell: float,
                      max_cells: int = 1024, closing: int = 1, tolerance_cells: float = 1.0
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate the area that points cover on a plane, holes left open.

    The points are projected onto the plane and rasterised into an occupancy grid of square
    cells; a morphological closing fills gaps between neighbouring samples; the grid's outlines
    with their holes are triangulated and mapped back onto the plane.

    Parameters
    ----------
    points : numpy.ndarray
        (N, 3) points on or near the plane, in the plane's frame and units.
    plane : numpy.ndarray
        (4,) ``(n, d)`` with ``n·X + d = 0``; ``n`` need not be unit length.
    cell : float
        Grid cell size in the points' units: about the sample spacing.
    max_cells : int
        Cap on the grid size per side; ``cell`` grows for larger extents.
    closing : int
        Radius in cells of the closing (0: none); gaps up to ``2 * closing`` cells are filled.
    tolerance_cells : float
        Outline simplification tolerance in cells.

    Returns
    -------
    vertices : numpy.ndarray
        (V, 3) float64 points on the plane.
    triangles : numpy.ndarray
        (T, 3) int64; right-hand normals along ``n``.
    """
    pts = np.asarray(points, np.float64).reshape(-1, 3)
    scale = float(np.linalg.norm(plane[:3]))
    if len(pts) == 0 or not cell > 0 or not scale > 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    n, d = np.asarray(plane[:3], np.float64) / scale, float(plane[3]) / scale
    e1, e2 = plane_basis(n)
    origin = -d * n
    uv = np.stack([(pts - origin) @ e1, (pts - origin) @ e2], axis=1)
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    cell = max(float(cell), float((hi - lo).max()) / max(max_cells, 1))
    pad = closing + 1
    ij = np.floor((uv - lo) / cell).astype(np.int64) + pad
    grid = np.zeros((int(ij[:, 1].max()) + pad + 1, int(ij[:, 0].max()) + pad + 1), np.uint8)
    grid[ij[:, 1], ij[:, 0]] = 1
    if closing > 0:
        kernel = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * closing + 1,) * 2)
        grid = cv2.morphologyEx(grid, cv2.MORPH_CLOSE, kernel)
    parts = []
    for outer, holes in mask_outlines(grid, tolerance_cells):
        flat, tris = triangulate_outline(outer, holes)
        a = (flat[:, 0] - pad + 0.5) * cell + lo[0]
        b = (flat[:, 1] - pad + 0.5) * cell + lo[1]
        verts = origin + a[:, None] * e1 + b[:, None] * e2
        parts.append((0, verts, _wind_along(verts, tris, n)))
    mesh = PlaneMesh.concatenate(parts)
    return mesh.vertices, mesh.triangles


def reconstruction_mesh(rec: Reconstruction, tolerance_px: float = 1.5) -> PlaneMesh:
    """Every plane region of a reconstruction, triangulated on its plane with holes open.

    Parameters
    ----------
    rec : Reconstruction
        Labels (H, W) and planes (P, 4) in the camera frame.
    tolerance_px : float
        Outline simplification tolerance in pixels.

    Returns
    -------
    PlaneMesh
        Camera-frame mesh in depth units; ``plane_ids`` are the label values 1..P.
    """
    parts = []
    for pid in range(1, rec.num_planes + 1):
        verts, tris = mask_plane_mesh(rec.labels == pid, rec.planes[pid - 1], rec.frame.K,
                                      tolerance_px)
        parts.append((pid, verts, tris))
    return PlaneMesh.concatenate(parts)
