"""Camera poses built from where a camera is and what it looks at, and the viewing pyramid a
report or a glTF file draws for a camera."""

from __future__ import annotations

import numpy as np


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray, roll_deg: float = 0.0
            ) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera pose of a camera at ``eye`` looking at ``target``.

    Parameters
    ----------
    eye, target : numpy.ndarray
        (3,) world points.
    up : numpy.ndarray
        (3,) world direction that should point up in the picture (camera -y).
    roll_deg : float
        Rotation of the picture about the viewing axis, degrees (positive turns camera x
        towards camera y).

    Returns
    -------
    R, t : numpy.ndarray
        (3, 3) rotation and (3,) translation with ``x_cam = R x_world + t``; OpenCV camera axes
        (x right, y down, z forward).

    Raises
    ------
    ValueError
        If ``up`` is parallel to the viewing direction.
    """
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    up = np.asarray(up, dtype=np.float64)
    y = -(up - (up @ z) * z)
    norm = np.linalg.norm(y)
    if norm < 1e-9:
        raise ValueError("look_at: the up vector is parallel to the viewing direction")
    y /= norm
    x = np.cross(y, z)
    a = np.deg2rad(roll_deg)
    x, y = np.cos(a) * x + np.sin(a) * y, -np.sin(a) * x + np.cos(a) * y
    R = np.stack([x, y, z])
    return R, -R @ eye


def frustum(K: np.ndarray, R: np.ndarray, t: np.ndarray, width: int, height: int,
            size: float) -> tuple[np.ndarray, np.ndarray]:
    """A camera's viewing pyramid as line segments.

    Parameters
    ----------
    K, R, t : numpy.ndarray
        Intrinsics and world-to-camera pose (OpenCV axes).
    width, height : int
        Image size in pixels.
    size : float
        Depth of the pyramid's base, world units.

    Returns
    -------
    points : numpy.ndarray
        (5, 3) world points: centre, then the image corners at depth ``size``.
    edges : numpy.ndarray
        (8, 2) index pairs: four rays and the base rectangle.
    """
    corners = np.array([[0, 0, 1], [width, 0, 1], [width, height, 1], [0, height, 1]], float)
    cam = np.vstack([np.zeros(3), size * corners @ np.linalg.inv(K).T])
    points = (cam - t) @ R
    edges = np.array([[0, 1], [0, 2], [0, 3], [0, 4], [1, 2], [2, 3], [3, 4], [4, 1]])
    return points, edges
