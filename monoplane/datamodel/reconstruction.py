"""Planes recovered from one frame: :class:`Reconstruction`.

Conventions: see :mod:`monoplane.datamodel`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np

from monoplane.datamodel.frame import Frame
from monoplane.datamodel.pinhole import pixel_rays, ray_plane_depth
from monoplane.datamodel.planeset import PlaneSet, as_planes, deprecated_name
from monoplane.errors import InvalidInput


def orient_towards_camera(params: np.ndarray) -> np.ndarray:
    """Normalise planes and flip them so that the normal faces the camera (``d >= 0``).

    Parameters
    ----------
    params : numpy.ndarray
        (P, 4) or (4,) planes ``(nx, ny, nz, d)`` in the camera frame.

    Returns
    -------
    numpy.ndarray
        Same shape, float64, with ``|n| = 1`` and ``d >= 0``.
    """
    p = np.array(params, dtype=np.float64)
    single = p.ndim == 1
    p = np.atleast_2d(p)
    norm = np.linalg.norm(p[:, :3], axis=1, keepdims=True)
    if np.any(norm == 0):
        raise InvalidInput("plane with a zero normal")
    p = p / norm
    # A plane through the camera centre has no "facing" side; use -z as the tie-break.
    sign = np.where(np.abs(p[:, 3]) > 1e-12, np.sign(p[:, 3]), -np.sign(p[:, 2] + 1e-300))
    p *= sign[:, None]
    return p[0] if single else p


@dataclass(init=False)
class Reconstruction(PlaneSet):
    """Planes recovered from one frame.

    Attributes
    ----------
    frame : Frame
        The frame (with cues) the planes were recovered from.
    labels : numpy.ndarray
        (H, W) int32 label map: 0 = non-planar, ``i`` in 1..P = plane ``planes[i - 1]``.
    planes : numpy.ndarray
        (P, 4) float64 planes ``(nx, ny, nz, d)``, ``n · X + d = 0`` in the camera frame
        (OpenCV axes) and the frame's depth units, normal facing the camera. Formerly
        ``params`` (still accepted, with a DeprecationWarning, until 0.3.0).
    rmse : numpy.ndarray
        (P,) float64 RMS point-to-plane distance of each plane's pixels, in depth units.
    support : numpy.ndarray
        (P,) int64 number of 3D points that voted for the plane in the fit.
    config : dict
        The resolved pipeline config that produced this result (for reproducibility).
    timings : dict
        Seconds spent per stage.

    ``ids`` (:class:`~monoplane.datamodel.planeset.PlaneSet`) are the label values 1..P.
    """

    result_kind: ClassVar[str] = "frame"

    frame: Frame
    labels: np.ndarray
    planes: np.ndarray
    rmse: np.ndarray
    support: np.ndarray
    config: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

    def __init__(self, frame: Frame, labels: np.ndarray, planes: np.ndarray | None = None,
                 rmse: np.ndarray | None = None, support: np.ndarray | None = None,
                 config: dict | None = None, timings: dict | None = None, *,
                 params: np.ndarray | None = None) -> None:
        if params is not None:  # the old name wins: dataclasses.replace passes both
            deprecated_name("Reconstruction", "params", "planes")
            planes = params
        if planes is None:
            raise InvalidInput("Reconstruction needs planes")
        self.frame = frame
        labels = np.asarray(labels)
        if labels.shape != frame.shape:
            raise InvalidInput(
                f"labels must have the frame's shape {frame.shape}, got {labels.shape}"
            )
        if not np.issubdtype(labels.dtype, np.integer):
            raise InvalidInput(f"labels must be integers, got {labels.dtype}")
        self.labels = labels.astype(np.int32)
        rows = as_planes(planes, "plane parameters")
        self.planes = orient_towards_camera(rows) if rows.shape[0] else rows
        n = self.planes.shape[0]
        if self.labels.size and (self.labels.min() < 0 or self.labels.max() > n):
            raise InvalidInput(f"labels must lie in 0..{n} for {n} planes")
        self.rmse = np.zeros(n) if rmse is None else np.asarray(rmse, dtype=np.float64)
        self.support = (self.area_px.copy() if support is None
                        else np.asarray(support, dtype=np.int64))
        if self.rmse.shape != (n,) or self.support.shape != (n,):
            raise InvalidInput(f"rmse and support must have shape ({n},)")
        self.config = {} if config is None else config
        self.timings = {} if timings is None else timings

    @property
    def params(self) -> np.ndarray:
        """Deprecated name of :attr:`planes`."""
        deprecated_name("Reconstruction", "params", "planes")
        return self.planes

    @property
    def area_px(self) -> np.ndarray:
        """(P,) int64 pixel count of each plane in the label map."""
        counts = np.bincount(self.labels.ravel(), minlength=self.num_planes + 1)
        return counts[1:].astype(np.int64)

    @property
    def colors(self) -> np.ndarray:
        """(P, 3) uint8 mean image colour of each plane (grey when the frame has no RGB)."""
        out = np.full((self.num_planes, 3), 128, dtype=np.uint8)
        if self.frame.rgb is None or self.num_planes == 0:
            return out
        flat = self.labels.ravel()
        counts = np.bincount(flat, minlength=self.num_planes + 1)[1:]
        rgb = self.frame.rgb.reshape(-1, 3).astype(np.float64)
        for c in range(3):
            sums = np.bincount(flat, weights=rgb[:, c], minlength=self.num_planes + 1)[1:]
            out[:, c] = np.where(counts > 0, sums / np.maximum(counts, 1), 128).astype(np.uint8)
        return out

    def planar_depth(self) -> np.ndarray:
        """Depth implied by each pixel's plane along that pixel's ray.

        Returns
        -------
        numpy.ndarray
            (H, W) float32 z-depth in the frame's depth units; 0 on non-planar pixels and where
            the ray does not meet its plane in front of the camera.
        """
        rays = pixel_rays(self.frame.K, *self.frame.shape)
        out = np.zeros(self.frame.shape, dtype=np.float32)
        mask = self.labels > 0
        if not np.any(mask):
            return out
        out[mask] = ray_plane_depth(rays[mask], self.planes[self.labels[mask] - 1])
        return out
