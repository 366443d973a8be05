"""View planes carried between the views of a scene: a plane's footprint lifted into the
world, where world points land in another view (and whether that view sees them), the region of
a view a global plane should own, and edits of a view's planes.

Used by the ``average`` fuser (:mod:`monoplane.stages.fusers`) to test a plane one view alone
segments and to recover planes a view merged away; ``cfg`` there is any object with the fields
of :class:`RecoverySettings` (the fuser's config).

Frames: world frame of the SfM model; cameras world-to-camera ``x_cam = R x_world + t``
(OpenCV axes); planes ``normal . x + offset = 0``.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Protocol

import cv2
import numpy as np

from monoplane.datamodel import Reconstruction, pixel_rays, plane_to_camera, ray_plane_depth


class RecoverySettings(Protocol):
    """What :func:`recovered_region` reads (the ``average`` fuser's config has these fields)."""

    recover_min_area: float
    recover_max_distance: float


def plane_footprint(rec: Reconstruction, cam: object, locals_: list[int],
                    plane_world: np.ndarray, step: int, max_samples: int) -> np.ndarray:
    """(N, 3) world points: every ``step``-th pixel of the given planes of one view, lifted
    along its ray onto ``plane_world``, thinned evenly to at most ``max_samples``."""
    mask = np.isin(rec.labels[::step, ::step], locals_)
    rays = pixel_rays(cam.K, cam.height, cam.width)[::step, ::step][mask]
    z = ray_plane_depth(rays, plane_to_camera(plane_world, cam.R, cam.t)[0])
    ahead = z > 0
    x = (rays[ahead] * z[ahead, None] - cam.t) @ cam.R
    return x[::max(1, int(np.ceil(len(x) / max(max_samples, 1))))]


def project_to_view(x_world: np.ndarray, depth: np.ndarray, cam: object, tol: float
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Where world points on a plane land in a view, and how the view's depth compares.

    Parameters
    ----------
    x_world : numpy.ndarray
        (N, 3) world points.
    depth : numpy.ndarray
        (H, W) the view's depth, same units.
    cam : Camera
        The view's camera.
    tol : float
        Relative depth tolerance.

    Returns
    -------
    (visible, through, rows, cols) or None
        Over the points that project in front of the camera and inside the image (None if
        there are none): ``visible`` (M,) bool, not occluded (the view's depth is valid and
        not nearer than the point by more than ``tol`` of the point's depth); ``through`` (M,)
        bool, the depth lies beyond the point by more than ``tol``; their pixels (M,) int.
    """
    x = x_world @ cam.R.T + cam.t
    x = x[x[:, 2] > 0]
    if len(x) == 0:
        return None
    uv = x @ cam.K.T
    u = np.rint(uv[:, 0] / uv[:, 2])
    r = np.rint(uv[:, 1] / uv[:, 2])
    inside = (u >= 0) & (u < cam.width) & (r >= 0) & (r < cam.height)
    if not np.any(inside):
        return None
    u, r, z = u[inside].astype(np.int64), r[inside].astype(np.int64), x[inside, 2]
    d = depth[r, u]
    rel = (d - z) / z
    return (d > 0) & (rel >= -tol), rel > tol, r, u


def replace_plane(rec: Reconstruction, cam: object, local: int,
                   plane_world: np.ndarray) -> Reconstruction:
    """``rec`` with plane ``local`` replaced by ``plane_world`` in its camera (RMS error of
    its pixels' depth to it updated)."""
    plane = plane_to_camera(plane_world, cam.R, cam.t)[0]
    mask = rec.labels == local
    rays = pixel_rays(cam.K, cam.height, cam.width)[mask]
    points = rays * rec.frame.depth[mask, None]
    params, rmse = rec.planes.copy(), rec.rmse.copy()
    params[local - 1] = plane
    rmse[local - 1] = float(np.sqrt(np.mean((points @ plane[:3] + plane[3]) ** 2))) if len(
        points) else 0.0
    return replace(rec, planes=params, rmse=rmse)


def drop_planes(rec: Reconstruction, drop: np.ndarray) -> Reconstruction:
    """``rec`` with the pixels of the planes flagged in ``drop`` ((P,) bool) set to 0."""
    if not drop.any():
        return rec
    labels = np.where(drop[np.maximum(rec.labels, 1) - 1], 0, rec.labels)
    return replace(rec, labels=labels.astype(np.int32))


def recovered_region(views: list[Reconstruction], cameras: list, members: list[tuple[int, int]],
                      i: int, plane_world: np.ndarray, cfg: RecoverySettings,
                      step: int, rays_all: np.ndarray) -> np.ndarray | None:
    """(H, W) bool pixels of view ``i`` to relabel onto ``plane_world``, or None (see
    :meth:`monoplane.stages.fusers.AverageFuser.recover_planes`; ``rays_all`` is view ``i``'s
    (H, W, 3) :func:`pixel_rays`). A pass on every ``step``-th pixel finds whether there is
    anything to recover and where; the full-resolution pass runs on that box only."""
    rec, cam = views[i], cameras[i]
    h, w = rec.labels.shape
    min_pixels = cfg.recover_min_area * h * w
    plane = plane_to_camera(plane_world, cam.R, cam.t)[0]

    def candidates(rows: slice, cols: slice) -> np.ndarray:
        rays = rays_all[rows, cols]
        z = ray_plane_depth(rays, plane)
        ahead = z > 0
        x_world = (rays * z[..., None] - cam.t) @ cam.R
        covered = np.zeros(z.shape, dtype=bool)
        for v, local in members:
            other = cameras[v]
            x = x_world @ other.R.T + other.t
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = x @ other.K.T
                u = np.rint(uv[..., 0] / uv[..., 2])
                r = np.rint(uv[..., 1] / uv[..., 2])
            inside = ahead & (x[..., 2] > 0) & (u >= 0) & (u < other.width) & (r >= 0) & (
                r < other.height)
            hit = np.zeros(z.shape, dtype=bool)
            hit[inside] = views[v].labels[r[inside].astype(np.int64),
                                          u[inside].astype(np.int64)] == local
            covered |= hit
        depth = rec.frame.depth[rows, cols]
        labels = rec.labels[rows, cols]
        off = np.abs(depth - z)
        own = np.full(z.shape, np.inf)
        if rec.num_planes:
            z_own = ray_plane_depth(rays, rec.planes[np.maximum(labels, 1) - 1])
            own = np.where(labels > 0, np.abs(depth - z_own), np.inf)
        return covered & (depth > 0) & (off <= cfg.recover_max_distance * depth) & (off < own)

    coarse = candidates(slice(None, None, step), slice(None, None, step))
    if coarse.sum() * step * step < min_pixels:
        return None
    rr, cc = np.nonzero(coarse)
    r0, r1 = max(0, rr.min() * step - step), min(h, rr.max() * step + 2 * step)
    c0, c1 = max(0, cc.min() * step - step), min(w, cc.max() * step + 2 * step)
    fine = candidates(slice(r0, r1), slice(c0, c1))
    n, comp, stats, _ = cv2.connectedComponentsWithStats(fine.astype(np.uint8), connectivity=4)
    if n <= 1:
        return None
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    if stats[best, cv2.CC_STAT_AREA] < min_pixels:
        return None
    region = np.zeros((h, w), dtype=bool)
    region[r0:r1, c0:c1] = comp == best
    return region
