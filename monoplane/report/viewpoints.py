"""Where the 3D views stand: frontal, bird's eye and oblique cameras around a planar model.

Virtual cameras orbit the model's centre at a distance that fits its extent into the picture.
A plane seen from behind is left out of a view ("cut-away"): from above a room, the ceiling
would otherwise hide everything, and from the side, a wall would. Each plane keeps the side its
source camera saw, so a plane stays in a view exactly when the virtual eye is on that side.

All coordinates are world coordinates of the model; camera matrices use OpenCV axes (x right,
y down, z forward). For a single view the world is that view's camera frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.geometry.camera import look_at

#: Horizontal field of view of the virtual cameras, degrees.
VIRTUAL_HFOV = 60.0
#: Wider field of view of the cameras that stand inside a room, degrees.
INSIDE_HFOV = 75.0


@dataclass
class Viewpoint:
    """A virtual camera.

    Attributes
    ----------
    name : str
        ``"frontal"``, ``"birdseye"``, ``"oblique"``, ...
    title : str
        Caption for the report.
    K : numpy.ndarray
        (3, 3) intrinsics for the render size.
    world_to_cam : numpy.ndarray
        (4, 4) extrinsics (OpenCV axes).
    eye : numpy.ndarray
        (3,) camera centre in world coordinates.
    """

    name: str
    title: str
    K: np.ndarray
    world_to_cam: np.ndarray
    eye: np.ndarray


def virtual_K(width: int, height: int, hfov_deg: float = VIRTUAL_HFOV) -> np.ndarray:
    """Centred pinhole intrinsics with the given horizontal field of view."""
    f = 0.5 * width / np.tan(np.deg2rad(hfov_deg) / 2.0)
    return np.array([[f, 0.0, width / 2.0], [0.0, f, height / 2.0], [0.0, 0.0, 1.0]])


def model_extent(vertices: np.ndarray) -> tuple[np.ndarray, float]:
    """Robust centre and radius of a point set (ignores the outer 2 % on each axis).

    Returns
    -------
    center : numpy.ndarray
        (3,) midpoint of the 2nd–98th percentile box.
    radius : float
        98th percentile distance from the centre (at least a tiny positive value).
    """
    lo, hi = np.percentile(vertices, [2.0, 98.0], axis=0)
    center = 0.5 * (lo + hi)
    radius = float(np.percentile(np.linalg.norm(vertices - center, axis=1), 98.0))
    return center, max(radius, 1e-6)


def orbit_viewpoints(
    vertices: np.ndarray, up: np.ndarray, forward: np.ndarray, width: int, height: int
) -> list[Viewpoint]:
    """A bird's eye view and two oblique views around a model.

    Parameters
    ----------
    vertices : numpy.ndarray
        (V, 3) model points, world frame.
    up : numpy.ndarray
        (3,) world direction that is "up" (for a single view: the camera's -y axis).
    forward : numpy.ndarray
        (3,) main viewing direction of the source camera(s); the bird's eye view is taken from
        behind them so that the model reads in the same orientation as the image.
    width, height : int
        Render size in pixels.

    Returns
    -------
    list of Viewpoint
        ``birdseye`` (65° above the horizon, from behind), ``oblique`` (30° up, 40° to the
        left) and ``oblique_right`` (30° up, 40° to the right).
    """
    up = np.asarray(up, dtype=np.float64)
    up /= np.linalg.norm(up)
    fwd = np.asarray(forward, dtype=np.float64)
    fwd = fwd - (fwd @ up) * up
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, up)  # with up = -y and forward = z this is +x (OpenCV right)
    center, radius = model_extent(vertices)
    K = virtual_K(width, height)
    half_fov = np.arctan(0.5 * min(width, height) / K[0, 0])
    dist = 1.05 * radius / np.sin(half_fov)

    def at(name: str, title: str, elev_deg: float, azim_deg: float) -> Viewpoint:
        el, az = np.deg2rad(elev_deg), np.deg2rad(azim_deg)
        horiz = -np.cos(az) * fwd + np.sin(az) * right
        eye = center + dist * (np.cos(el) * horiz + np.sin(el) * up)
        # Looking steeply down, "up" in the picture is the forward direction.
        img_up = fwd if elev_deg > 60 else up
        R, t = look_at(eye, center, img_up)
        extrinsics = np.eye(4)
        extrinsics[:3, :3], extrinsics[:3, 3] = R, t
        return Viewpoint(name, title, K, extrinsics, eye)

    return [
        at("birdseye", "bird's eye view", 65.0, 0.0),
        at("oblique", "oblique view from the left", 30.0, -40.0),
        at("oblique_right", "oblique view from the right", 30.0, 40.0),
    ]


def inside_viewpoints(vertices: np.ndarray, up: np.ndarray, forward: np.ndarray,
                      floor_height: float, top_height: float, width: int, height: int
                      ) -> list[Viewpoint]:
    """Two cameras standing inside a room, in its back corners, looking across it and down.

    Parameters
    ----------
    vertices : numpy.ndarray
        (V, 3) model points, world frame.
    up, forward : numpy.ndarray
        (3,) up direction and main viewing direction (made horizontal here), as for
        :func:`orbit_viewpoints`; "back" is ``-forward``.
    floor_height, top_height : float
        ``up · x`` of the floor and of the ceiling (or the model's top).
    width, height : int
        Render size in pixels.

    Returns
    -------
    list of Viewpoint
        ``inside_left`` and ``inside_right``: eyes at 65 % of the room height, 15 % of the
        room's depth in from its back and a quarter of its width out from the middle, looking
        at a point 15 % of the height above the floor, 70 % of the way in, on the other side
        of the middle. The room's extent is the 5th-95th percentile of the vertices.
    """
    up = np.asarray(up, dtype=np.float64)
    up /= np.linalg.norm(up)
    fwd = np.asarray(forward, dtype=np.float64)
    fwd = fwd - (fwd @ up) * up
    fwd /= np.linalg.norm(fwd)
    right = np.cross(fwd, up)
    f0, f1 = np.percentile(vertices @ fwd, [5.0, 95.0])
    r0, r1 = np.percentile(vertices @ right, [5.0, 95.0])
    r_mid, room = 0.5 * (r0 + r1), top_height - floor_height
    K = virtual_K(width, height, INSIDE_HFOV)

    def at(name: str, title: str, side: float) -> Viewpoint:
        eye = ((f0 + 0.15 * (f1 - f0)) * fwd + (r_mid + side * 0.25 * (r1 - r0)) * right
               + (floor_height + 0.65 * room) * up)
        target = ((f0 + 0.7 * (f1 - f0)) * fwd + (r_mid - side * 0.15 * (r1 - r0)) * right
                  + (floor_height + 0.15 * room) * up)
        R, t = look_at(eye, target, up)
        extrinsics = np.eye(4)
        extrinsics[:3, :3], extrinsics[:3, 3] = R, t
        return Viewpoint(name, title, K, extrinsics, eye)

    return [at("inside_left", "inside the room from the back left", -1.0),
            at("inside_right", "inside the room from the back right", 1.0)]


def facing_triangles(
    triangle_planes: np.ndarray, planes: np.ndarray, eye: np.ndarray
) -> np.ndarray:
    """Indices of the triangles whose plane is seen from its front side by a camera at ``eye``.

    Parameters
    ----------
    triangle_planes : numpy.ndarray
        (T,) int row of ``planes`` each triangle lies on.
    planes : numpy.ndarray
        (Q, 4) planes ``n · X + d = 0`` in world coordinates, oriented so that the side the
        source camera saw is positive.
    eye : numpy.ndarray
        (3,) virtual camera centre.

    Returns
    -------
    numpy.ndarray
        (T',) int64 triangle indices to draw.
    """
    side = planes[:, :3] @ eye + planes[:, 3]
    return np.flatnonzero(side[triangle_planes] > 0)


def zoom_to_fit(viewpoint: Viewpoint, points: np.ndarray, width: int, height: int,
                margin: float = 0.04, always: np.ndarray | None = None) -> Viewpoint:
    """Zoom and re-centre a virtual camera so that ``points`` fill the picture.

    Only the intrinsics change (focal length and principal point), which is an exact crop and
    zoom of the same perspective; the eye and viewing direction stay.

    Parameters
    ----------
    viewpoint : Viewpoint
        Camera to adjust.
    points : numpy.ndarray
        (N, 3) world points that should be visible (the ones the view draws); the outer 0.5 %
        on each side may fall outside, so that a few stray points do not shrink the model.
    width, height : int
        Render size in pixels.
    margin : float
        Free border on each side, as a fraction of the picture size.
    always : numpy.ndarray, optional
        (M, 3) world points that must all be in the picture (e.g. camera frusta).

    Returns
    -------
    Viewpoint
        A copy with new ``K``; unchanged when no point lies in front of the camera.
    """
    T, K = viewpoint.world_to_cam, viewpoint.K

    def project(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cam = pts @ T[:3, :3].T + T[:3, 3]
        cam = cam[cam[:, 2] > 1e-9]
        return K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2], K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]

    u, v = project(points)
    if len(u) == 0:
        return viewpoint
    u0, u1 = np.percentile(u, [0.5, 99.5])
    v0, v1 = np.percentile(v, [0.5, 99.5])
    if always is not None and len(always):
        ua, va = project(always)
        if len(ua):
            u0, u1 = min(u0, ua.min()), max(u1, ua.max())
            v0, v1 = min(v0, va.min()), max(v1, va.max())
    s = min((1 - 2 * margin) * width / max(u1 - u0, 1e-9),
            (1 - 2 * margin) * height / max(v1 - v0, 1e-9))
    K2 = K.copy()
    K2[0, 0] *= s
    K2[1, 1] *= s
    K2[0, 2] = width / 2.0 - s * (0.5 * (u0 + u1) - K[0, 2])
    K2[1, 2] = height / 2.0 - s * (0.5 * (v0 + v1) - K[1, 2])
    return Viewpoint(viewpoint.name, viewpoint.title, K2, T, viewpoint.eye)
