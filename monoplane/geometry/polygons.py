"""Plane outlines: image contours lifted onto planes, and their triangulation.

Outlines are polygons in 3D lying on a plane; writers triangulate them (ear clipping in the
plane's 2D basis) because common PLY readers, Open3D's among them, cannot load concave faces.
"""

from __future__ import annotations

import cv2
import numpy as np

from monoplane.types import Reconstruction


def plane_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors spanning the plane, with ``e1 × e2 = normal``."""
    a = np.array([1.0, 0.0, 0.0]) if abs(normal[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(normal, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(normal, e1)


def triangulate_polygon(poly: np.ndarray) -> np.ndarray:
    """Ear-clipping triangulation of a simple 2D polygon.

    Parameters
    ----------
    poly : numpy.ndarray
        (V, 2) vertices of a simple polygon, either winding.

    Returns
    -------
    numpy.ndarray
        (V - 2, 3) int64 vertex indices, each triangle counter-clockwise (positive area);
        fewer rows when degenerate (collinear) vertices are skipped.
    """
    pts = np.asarray(poly, dtype=np.float64)
    idx = list(range(len(pts)))
    x, y = pts[:, 0], pts[:, 1]
    if np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < 0:
        idx.reverse()

    def cross(a: int, b: int, c: int) -> float:
        return float((pts[b, 0] - pts[a, 0]) * (pts[c, 1] - pts[a, 1])
                     - (pts[b, 1] - pts[a, 1]) * (pts[c, 0] - pts[a, 0]))

    tris = []
    while len(idx) > 3:
        n = len(idx)
        for k in range(n):
            a, b, c = idx[k - 1], idx[k], idx[(k + 1) % n]
            if cross(a, b, c) <= 0:
                continue  # reflex or degenerate corner: not an ear
            others = [i for i in idx if i not in (a, b, c)]
            if others:
                o = np.array(others)
                inside = ((_edge(pts, a, b, o) >= 0) & (_edge(pts, b, c, o) >= 0)
                          & (_edge(pts, c, a, o) >= 0))
                if np.any(inside):
                    continue
            tris.append((a, b, c))
            del idx[k]
            break
        else:
            # Only degenerate corners remain (collinear runs): drop one and go on.
            del idx[int(np.argmin([abs(cross(idx[k - 1], idx[k], idx[(k + 1) % n]))
                                   for k in range(n)]))]
    if len(idx) == 3 and cross(*idx) > 0:
        tris.append(tuple(idx))
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


def _edge(pts: np.ndarray, a: int, b: int, o: np.ndarray) -> np.ndarray:
    """Signed area test of points ``o`` against the directed edge ``a -> b``."""
    return ((pts[b, 0] - pts[a, 0]) * (pts[o, 1] - pts[a, 1])
            - (pts[b, 1] - pts[a, 1]) * (pts[o, 0] - pts[a, 0]))


def plane_polygons(rec: Reconstruction, tolerance_px: float = 1.5
                   ) -> list[tuple[int, np.ndarray]]:
    """Outer boundary polygon of every plane region, lifted onto its plane.

    Parameters
    ----------
    rec : Reconstruction
        Planes and label map.
    tolerance_px : float
        Douglas–Peucker simplification tolerance of the image contour, in pixels.

    Returns
    -------
    list of (int, numpy.ndarray)
        ``(plane_id, (V, 3) vertices)`` in the camera frame and depth units, one entry per
        connected region (holes are not cut out).
    """
    K_inv = np.linalg.inv(rec.frame.K)
    polygons = []
    for pid in range(1, rec.num_planes + 1):
        mask = (rec.labels == pid).astype(np.uint8)
        contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        n, d = rec.params[pid - 1, :3], rec.params[pid - 1, 3]
        for contour in contours:
            poly = cv2.approxPolyDP(contour, tolerance_px, True).reshape(-1, 2)
            if len(poly) < 3:
                continue
            rays = np.c_[poly.astype(np.float64), np.ones(len(poly))] @ K_inv.T
            denom = rays @ n
            with np.errstate(divide="ignore", invalid="ignore"):
                z = -d / denom
            if not np.all(np.isfinite(z) & (z > 0)):
                continue  # the region's outline leaves the plane's visible half-space
            polygons.append((pid, rays * z[:, None]))
    return polygons


def triangulate_on_plane(vertices: np.ndarray, normal: np.ndarray) -> list[np.ndarray]:
    """Triangulate a planar 3D polygon.

    Parameters
    ----------
    vertices : numpy.ndarray
        (V, 3) outline lying on a plane with normal ``normal``.
    normal : numpy.ndarray
        (3,) plane normal; triangles wind counter-clockwise around it.

    Returns
    -------
    list of numpy.ndarray
        (3, 3) triangle vertices.
    """
    n = np.asarray(normal, dtype=np.float64)
    e1, e2 = plane_basis(n / np.linalg.norm(n))
    flat = np.stack([vertices @ e1, vertices @ e2], axis=1)
    return [vertices[tri] for tri in triangulate_polygon(flat)]
