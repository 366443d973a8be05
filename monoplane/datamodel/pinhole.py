"""Pinhole intrinsics, pixel rays, posed cameras and plane frame changes.

Conventions: see :mod:`monoplane.datamodel`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.errors import InvalidInput


def _check_K(K: np.ndarray, what: str = "K") -> np.ndarray:
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3):
        raise InvalidInput(f"{what} must be a 3x3 matrix, got shape {K.shape}")
    if not np.all(np.isfinite(K)):
        raise InvalidInput(f"{what} has non-finite entries")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InvalidInput(f"{what} focal lengths must be positive, got fx={K[0, 0]}, fy={K[1, 1]}")
    if not np.allclose(K[2], [0.0, 0.0, 1.0]):
        raise InvalidInput(f"{what} last row must be [0, 0, 1], got {K[2].tolist()}")
    if abs(np.linalg.det(K)) < 1e-12:
        raise InvalidInput(f"{what} is not invertible")
    return K


def intrinsics_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """Build a pinhole intrinsics matrix.

    Parameters
    ----------
    fx, fy : float
        Focal lengths in pixels.
    cx, cy : float
        Principal point in pixels (column, row).

    Returns
    -------
    numpy.ndarray
        (3, 3) float64 matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``.
    """
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=np.float64)


def default_intrinsics(width: int, height: int, hfov_deg: float = 60.0) -> np.ndarray:
    """Intrinsics for an image of unknown calibration: a centred pinhole with the given FOV.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    hfov_deg : float
        Horizontal field of view in degrees (60 unless a cue profile knows better).

    Returns
    -------
    numpy.ndarray
        (3, 3) float64, square pixels, principal point at the image centre.
    """
    f = 0.5 * width / np.tan(np.deg2rad(hfov_deg) / 2.0)
    return intrinsics_matrix(f, f, (width - 1) / 2.0, (height - 1) / 2.0)


def pixel_rays(K: np.ndarray, height: int, width: int) -> np.ndarray:
    """Back-projected pixel rays scaled so that their camera-z component is 1.

    Parameters
    ----------
    K : numpy.ndarray
        (3, 3) intrinsics.
    height, width : int
        Image size in pixels.

    Returns
    -------
    numpy.ndarray
        (H, W, 3) float64 rays ``K^-1 [u, v, 1]^T`` in the camera frame (OpenCV axes); a point at
        z-depth ``z`` on pixel ``(u, v)`` is ``z * rays[v, u]``.
    """
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    pix = np.stack([u, v, np.ones_like(u)], axis=-1)
    return pix @ np.linalg.inv(K).T


def ray_plane_depth(rays: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Where rays from the camera centre meet planes: the scale ``z = -d / (n·r)``.

    Parameters
    ----------
    rays : numpy.ndarray
        (..., 3) ray directions ``r`` (e.g. :func:`pixel_rays`, whose z component is 1, so the
        result is a z-depth).
    planes : numpy.ndarray
        (4,) one plane ``(n, d)`` with ``n·X + d = 0`` for every ray, or (..., 4) one per ray,
        in the rays' frame.

    Returns
    -------
    numpy.ndarray
        (...) float64 ``z`` such that ``z * r`` lies on the plane; 0 where the ray is parallel
        to the plane or meets it behind the camera (the depth convention for "invalid").
    """
    rays = np.asarray(rays, dtype=np.float64)
    planes = np.asarray(planes, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = -planes[..., 3] / np.einsum("...i,...i->...", rays, planes[..., :3])
    return np.where(np.isfinite(z) & (z > 0), z, 0.0)


@dataclass
class Camera:
    """A calibrated view in a multi-view scene.

    Attributes
    ----------
    K : numpy.ndarray
        (3, 3) intrinsics in pixels.
    R : numpy.ndarray
        (3, 3) world-to-camera rotation.
    t : numpy.ndarray
        (3,) world-to-camera translation: ``x_cam = R @ x_world + t`` (OpenCV axes).
    width, height : int
        Image size in pixels.
    name : str
        Image name.
    """

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    width: int
    height: int
    name: str = ""

    def __post_init__(self) -> None:
        self.K = _check_K(self.K, f"camera {self.name!r} K")
        self.R = np.asarray(self.R, dtype=np.float64)
        self.t = np.asarray(self.t, dtype=np.float64).reshape(3)
        if self.R.shape != (3, 3) or not np.allclose(self.R @ self.R.T, np.eye(3), atol=1e-6):
            raise InvalidInput(f"camera {self.name!r}: R must be a 3x3 rotation matrix")
        if abs(np.linalg.det(self.R) - 1.0) > 1e-6:
            raise InvalidInput(f"camera {self.name!r}: R must have determinant +1")

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in world coordinates."""
        return -self.R.T @ self.t


def plane_to_world(params: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Express camera-frame planes in the world frame.

    Parameters
    ----------
    params : numpy.ndarray
        (P, 4) planes ``n_c · x_cam + d = 0``.
    R, t : numpy.ndarray
        World-to-camera pose, ``x_cam = R x_world + t``.

    Returns
    -------
    numpy.ndarray
        (P, 4) planes ``n_w · x_world + d_w = 0`` with ``n_w = R^T n_c`` and ``d_w = n_c · t + d``.
    """
    p = np.atleast_2d(np.asarray(params, dtype=np.float64))
    n_w = p[:, :3] @ R
    d_w = p[:, :3] @ t + p[:, 3]
    return np.concatenate([n_w, d_w[:, None]], axis=1)


def plane_to_camera(params: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Inverse of :func:`plane_to_world`: world-frame planes into the camera frame.

    Returns
    -------
    numpy.ndarray
        (P, 4) planes with ``n_c = R n_w`` and ``d = d_w - n_c · t``.
    """
    p = np.atleast_2d(np.asarray(params, dtype=np.float64))
    n_c = p[:, :3] @ R.T
    d_c = p[:, 3] - n_c @ t
    return np.concatenate([n_c, d_c[:, None]], axis=1)
