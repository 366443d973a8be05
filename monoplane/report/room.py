"""Which way is up in a point cloud, from gravity-like evidence, and a room cut open for views.

A room scan's largest plane is often a wall that the camera faced, so "up" cannot be the normal
of the largest plane. The floor is the large plane that most of the cloud stands on:

1. **Extreme planes.** A floor (or a ceiling, or an outer wall) bounds the cloud: nearly every
   point lies on one side of it. Each large plane is oriented so that its normal points into
   the cloud, and kept when at least :data:`ONE_SIDED` of the points off it are on that side.
2. **Evidence.** A floor carries things that face the same way: table tops, seats, shelves,
   steps. A candidate's evidence is its own points plus the points of every other plane whose
   normal faces the same way (within :data:`PARALLEL_DEG`).
3. **Hint.** A direction that is roughly up in the cloud's frame, when there is one (the
   camera's -y for clouds in a camera frame, y down), multiplies the evidence of candidates that
   agree with it by up to 3: the back wall a camera faced does not, the floor below it does.
   Without one, evidence alone decides.

The chosen plane's inward normal is "up". The opposing extreme plane, if any, is the ceiling;
heights are measured from the floor along "up".
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.report.render3d import Mesh, clip_triangles

#: A plane bounds the cloud when at least this share of the points off it lie on one side.
ONE_SIDED = 0.9
#: Planes with fewer points than this share of the labelled points are not floor candidates.
MIN_SHARE = 0.02
#: Planes facing the same way within this angle count as evidence for each other, degrees.
PARALLEL_DEG = 15.0
#: Points closer than this fraction of the cloud's extent to a plane count as on it.
ON_PLANE = 0.02
#: Points used to judge the sides of planes (a regular subsample of larger clouds).
MAX_POINTS = 200_000


@dataclass(frozen=True)
class RoomFrame:
    """Up direction and heights of a cloud.

    Attributes
    ----------
    up : numpy.ndarray
        (3,) unit "up" in the cloud's frame.
    floor_height : float
        ``up · x`` on the floor (the lowest height of the cloud when no plane was a floor).
    top_height : float
        ``up · x`` of the ceiling, or of the cloud's top (99th percentile) without a ceiling.
    floor : int or None
        Row of the floor plane in the plane array.
    ceiling : int or None
        Row of the ceiling plane (an extreme plane opposing the floor).
    reason : str
        How "up" was chosen, for the report's notes.
    """

    up: np.ndarray
    floor_height: float
    top_height: float
    floor: int | None
    ceiling: int | None
    reason: str

    def heights(self, points: np.ndarray) -> np.ndarray:
        """(N,) height above the floor of (N, 3) points, cloud units."""
        return np.asarray(points, dtype=np.float64) @ self.up - self.floor_height


def _subsample(points: np.ndarray) -> np.ndarray:
    finite = points[np.isfinite(points).all(axis=1)]
    step = max(1, len(finite) // MAX_POINTS)
    return np.asarray(finite[::step], dtype=np.float64)


def estimate_room_frame(points: np.ndarray, planes: np.ndarray, num_points: np.ndarray,
                        hint: np.ndarray | None = None) -> RoomFrame:
    """Choose "up" from the floor: the large plane most of the cloud stands on.

    Parameters
    ----------
    points : numpy.ndarray
        (N, 3) cloud points (non-finite ones are ignored).
    planes : numpy.ndarray
        (P, 4) planes ``n · x + d = 0``, unit ``n``.
    num_points : numpy.ndarray
        (P,) points per plane.
    hint : numpy.ndarray, optional
        (3,) direction that is roughly up in the cloud's frame, e.g. ``(0, -1, 0)`` in a
        camera frame; ``None`` when nothing is known.

    Returns
    -------
    RoomFrame
        Without any plane bounding the cloud, "up" is the hint (or the largest plane's
        normal, or +z) and heights span the cloud.
    """
    pts = _subsample(points)
    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 4)
    num_points = np.asarray(num_points, dtype=np.float64).reshape(-1)
    hint_unit = None
    if hint is not None and np.linalg.norm(hint) > 0:
        hint_unit = np.asarray(hint, dtype=np.float64) / np.linalg.norm(hint)
    extent = float(np.ptp(pts, axis=0).max()) if len(pts) else 1.0
    tol = ON_PLANE * max(extent, 1e-9)
    oriented = planes.copy()
    extreme = np.zeros(len(planes), bool)
    large = num_points >= MIN_SHARE * max(num_points.sum(), 1.0)
    for i in np.flatnonzero(large):
        s = pts @ planes[i, :3] + planes[i, 3]
        above, below = int(np.count_nonzero(s > tol)), int(np.count_nonzero(s < -tol))
        if below > above:
            oriented[i] = -planes[i]
            above, below = below, above
        extreme[i] = above >= ONE_SIDED * max(above + below, 1)
    normals = oriented[:, :3]
    if not extreme.any():
        up = hint_unit if hint_unit is not None else (
            planes[int(np.argmax(num_points)), :3] if len(planes) else np.array([0.0, 0, 1]))
        return _frame(pts, up, None, None, "no plane bounds the cloud: up is "
                      + ("the given hint" if hint_unit is not None else
                         "the largest plane's normal" if len(planes) else "+z"))
    # Planes facing the same way as a candidate's inward normal (their own normal, the side
    # their points' normals face: table tops face up like the floor) support it.
    facing = planes[:, :3] @ normals.T >= np.cos(np.radians(PARALLEL_DEG))  # (P, P): j for i
    facing |= np.eye(len(planes), dtype=bool)
    support = np.where(facing, num_points[:, None], 0.0).sum(axis=0)
    agree = np.zeros(len(planes)) if hint_unit is None else np.clip(normals @ hint_unit, 0, 1)
    score = np.where(extreme, support * (1.0 + 2.0 * agree), -1.0)
    floor = int(np.argmax(score))
    up = normals[floor]
    cos_par = np.cos(np.radians(PARALLEL_DEG))
    opposing = np.flatnonzero(extreme & (normals @ up <= -cos_par))
    ceiling = int(opposing[np.argmax(num_points[opposing])]) if len(opposing) else None
    how = (f"the floor is plane {floor + 1}: {int(num_points[floor])} points, with nearly all "
           f"of the cloud on one side, and {int(support[floor] - num_points[floor])} more "
           f"points on planes facing the same way")
    if hint_unit is not None:
        how += f"; it is {np.degrees(np.arccos(np.clip(up @ hint_unit, -1, 1))):.0f}° from " \
               f"the up hint"
    if ceiling is not None:
        how += f"; plane {ceiling + 1} opposite it is the ceiling"
    return _frame(pts, up, floor, ceiling, how, oriented)


def _frame(pts: np.ndarray, up: np.ndarray, floor: int | None, ceiling: int | None,
           reason: str, oriented: np.ndarray | None = None) -> RoomFrame:
    up = np.asarray(up, dtype=np.float64) / np.linalg.norm(up)
    h = pts @ up if len(pts) else np.zeros(1)
    # Inward normal n = up on the floor: n · x + d = 0 there, so up · x = -d.
    base = float(-oriented[floor, 3]) if floor is not None and oriented is not None else float(
        np.percentile(h, 1.0))
    if ceiling is not None and oriented is not None:
        # The ceiling's inward normal is about -up: -up · x + d = 0, so up · x = d.
        top = float(oriented[ceiling, 3])
    else:
        top = float(np.percentile(h, 99.0))
    return RoomFrame(up, base, max(top, base + 1e-9), floor, ceiling, reason)


def section_below(mesh: Mesh, triangle_planes: np.ndarray, frame: RoomFrame, cut: float
                  ) -> tuple[Mesh, np.ndarray]:
    """The part of a mesh below a horizontal cut: the room with its ceiling taken off.

    Parameters
    ----------
    mesh : Mesh
        Triangles and vertex colours, cloud frame.
    triangle_planes : numpy.ndarray
        (T,) int plane of each triangle.
    frame : RoomFrame
        Up direction and floor height.
    cut : float
        Height above the floor at which everything is cut away, cloud units.

    Returns
    -------
    mesh : Mesh
        Triangles entirely below the cut, and the lower parts of those crossing it (walls end
        at the cut), on new vertices where cut.
    triangle_planes : numpy.ndarray
        (T',) int64 plane of each triangle of the cut mesh.
    """
    up = frame.up
    # An orthonormal frame whose third axis is the height below the cut, so that the renderer's
    # near-plane clipping (keep z >= 0) does the cutting.
    a = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    basis = np.stack([a, np.cross(up, a), -up])  # rows: two horizontal axes and -height
    local = np.asarray(mesh.points, dtype=np.float64) @ basis.T
    local[:, 2] += cut + frame.floor_height  # cut - height
    colors = np.asarray(mesh.colors, dtype=np.float64)
    triangles = np.asarray(mesh.indices, dtype=np.int64)
    triangle_planes = np.asarray(triangle_planes, dtype=np.int64)
    points, rgb, tris, ids = [np.zeros((0, 3))], [np.zeros((0, 3))], [], []
    offset = 0
    # Plane by plane, so that every new triangle keeps its plane.
    for plane in np.unique(triangle_planes):
        p, c, t = clip_triangles(local, colors, triangles[triangle_planes == plane], 0.0)
        used, inverse = np.unique(t.reshape(-1), return_inverse=True)
        points.append(p[used])
        rgb.append(c[used])
        tris.append(inverse.reshape(-1, 3) + offset)
        ids.append(np.full(len(t), plane, np.int64))
        offset += len(used)
    cut_points = np.concatenate(points)
    cut_points[:, 2] -= cut + frame.floor_height
    return (Mesh(cut_points @ basis, np.concatenate(tris) if tris else np.zeros((0, 3), np.int64),
                 np.concatenate(rgb)),
            np.concatenate(ids) if ids else np.zeros(0, np.int64))
