"""Triangle meshes of a point cloud's planes (the cloud analogue of
:func:`monoplane.geometry.polygons.reconstruction_mesh`)."""

from __future__ import annotations

import numpy as np

from monoplane.datamodel import CloudResult
from monoplane.geometry.neighbours import PointIndex
from monoplane.geometry.polygons import PlaneMesh, points_plane_mesh


def cloud_mesh(result: CloudResult, cell: float | None = None) -> PlaneMesh:
    """Every plane's area as triangles on the plane, holes left open, faces tagged by plane.

    Each plane's points are projected onto it, rasterised on a grid of ``cell`` and outlined
    with their holes (:func:`monoplane.geometry.polygons.points_plane_mesh`).

    Parameters
    ----------
    result : CloudResult
        Points (N, 3), labels (N,) and planes (P, 4) in the cloud's frame and units.
    cell : float, optional
        Grid cell in the cloud's units; default twice the median spacing of the planar points
        (1 when it cannot be measured).

    Returns
    -------
    PlaneMesh
        Vertices in the cloud's frame and units; ``plane_ids`` 1..P.
    """
    finite = np.isfinite(result.points).all(axis=1)
    if cell is None:
        pts = result.points[finite & (result.labels > 0)]
        if len(pts) >= 2:
            d, _ = PointIndex(pts).query(pts[:: max(1, len(pts) // 2000)], k=2)
            cell = 2.0 * float(np.median(d[:, 1]))
        cell = cell if cell and cell > 0 else 1.0
    parts = []
    for pid in range(1, result.num_planes + 1):
        verts, tris = points_plane_mesh(result.points[result.labels == pid],
                                        result.planes[pid - 1], cell)
        parts.append((pid, verts, tris))
    return PlaneMesh.concatenate(parts)
