"""The planarity test: planes on curved surfaces become non-planar (config table ``[planarity]``).

RANSAC accepts any patch whose points lie within ε of a plane and whose normals lie within
ε_n of its normal, so a cap of a sphere or a strip of a cylinder passes as a plane; a refiner
then grows it. This step runs once after the refiner, on images and clouds alike, and sets to
non-planar (label 0) every final plane whose points and normals show systematic curvature.
Two signs, either one rejects a plane:

1. **Normals that turn across the region.** On a flat region the normal cue scatters around
   one direction by its noise only; on a curved one it turns with position, so it spreads
   far wider. The spread of a plane is the median angle between its normals and their
   dominant direction (:func:`~monoplane.geometry.flatness.spread_of_groups`), measured
   away from the region's border (where the cue blurs across the neighbouring surface). The
   cue's noise is the *noise floor*, the spread of the median planar point
   (:func:`~monoplane.geometry.flatness.noise_floor_deg`): most points of a scene lie on
   flat surfaces. A plane is curved when its spread exceeds the floor by more than
   ``max_extra_spread_deg``.
2. **A quadric that explains the points better than the plane.** In the plane's own frame
   the points' heights are fitted by a plane and by a quadric. A plane is curved when the
   plane leaves ``quadric_ratio`` times the quadric's RMS residual and that residual excess
   is above the noise: noisy or warped depth (monocular cues) bends a flat wall gently, which
   a quadric also absorbs, but never by that ratio.

Thin regions: a region with fewer than :data:`~monoplane.geometry.flatness.MIN_SAMPLES`
points away from its border (a table top seen edge-on, a shelf board, but also a band round
the top of a torus that lies within ε of a plane) has no evidence of curvature there and is
kept. With ``thin_border_px`` set (off by default) such a region is measured again closer to
its border, by the normal test only: a quadric fitted to a strip a few pixels wide is
ill-conditioned across it, while the normals of a curved band still turn (10-21° on the
synthetic tori at 640x480) and those of a flat strip stay near the noise (1.6-3.3°).

Where the measurements come from: images use the frame's normal cue and its 3D points on the
final label map, eroded by ``border_px`` (scaled with the image width, at 256 px); clouds use
the working cloud's points and normals, without the points that have a graph neighbour of
another label. The normal test needs normals that are a cue of their own: normals estimated
from the same depth (``Frame.normals_from_depth``) or the same points (a bare cloud) add no
evidence and are noisy on oblique faces, so then the quadric alone decides. In clouds a third
rule drops *crease strips*, planes too thin to test whose points lie on a plane they touch
(estimated normals blend two faces along their crease, and RANSAC can group such points).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from monoplane.algorithm.region_moments import scene_radius
from monoplane.contracts import param
from monoplane.datamodel import Reconstruction
from monoplane.errors import check_config
from monoplane.geometry.flatness import (
    MIN_SAMPLES,
    interior_samples,
    noise_floor_deg,
    quadric_ratio,
    spread_of_groups,
)


@dataclass
class PlanarityConfig:
    """Parameters of the planarity test (config table ``[planarity]``)."""

    enabled: bool = param(True, "reject final planes whose points and normals show curvature")
    max_extra_spread_deg: float = param(
        4.5, "a plane is curved when its normals spread this many degrees beyond the noise "
        "floor (the spread of the scene's median planar point)")
    min_floor_deg: float = param(
        1.0, "noise floor used at least, degrees (exact normals of a clean cloud have none)")
    quadric_ratio: float = param(
        3.0, "a plane is curved when a quadric fits its points this many times better (RMS) "
        "than the plane (0 disables the quadric test)")
    border_px: int = param(
        2, "image pixels this close to another label are left out of the test (at 256 px "
        "wide, scaled with the width)")
    thin_border_px: float = param(
        0.0, "images: a plane with too few pixels away from border_px is measured this close "
        "to its border instead, by the normal test only (at 256 px wide, scaled with the "
        "width; 0, the default: such planes are kept untested; 1 removes the thin bands on "
        "tori that grid sampling finds, docs/evaluation.md)")
    max_samples: int = param(400, "points sampled per plane for the test")
    inlier_band: float = param(
        0.0, "if > 0, images: the quadric test sees only a plane's pixels within this many ε "
        "of it (ε the RANSAC's, as lowered to the depth noise), not objects a refiner painted "
        "into it (0: all its pixels)")
    max_points: int = param(
        20000, "image pixels sampled for the test, on a regular grid (its speed at any size)")

    def __post_init__(self) -> None:
        check_config([
            (self.max_extra_spread_deg > 0, "max_extra_spread_deg must be positive"),
            (self.min_floor_deg >= 0, "min_floor_deg must be non-negative"),
            (self.quadric_ratio == 0 or self.quadric_ratio > 1,
             "quadric_ratio must be 0 (off) or above 1"),
            (self.border_px >= 0, "border_px must be non-negative"),
            (self.thin_border_px >= 0, "thin_border_px must be non-negative"),
            (self.max_samples >= 30, "max_samples must be at least 30"),
            (self.inlier_band >= 0, "inlier_band must be non-negative"),
            (self.max_points >= 1000, "max_points must be at least 1000"),
        ])


def curved_planes(points: np.ndarray, normals: np.ndarray | None, labels: np.ndarray,
                  num_planes: int, cfg: PlanarityConfig,
                  quadric_labels: np.ndarray | None = None,
                  thin_labels: np.ndarray | None = None) -> np.ndarray:
    """Which planes show curvature, from their points and normals.

    Parameters
    ----------
    points : numpy.ndarray
        (M, 3) points (any frame and unit: the tests are scale-free).
    normals : numpy.ndarray or None
        (M, 3) unit normals in the points' frame, a cue of their own (rows of zeros are
        unknown); None when the only normals were estimated from these points, which tells
        nothing the points do not: the normal test is then skipped.
    labels : numpy.ndarray
        (M,) int plane of each point, 0 = not tested (non-planar, or on a border).
    num_planes : int
        P, the largest label.
    cfg : PlanarityConfig
    quadric_labels : numpy.ndarray, optional
        (M,) int labels the quadric test uses instead of ``labels`` (e.g. without the points
        far from their plane).
    thin_labels : numpy.ndarray, optional
        (M,) int labels, measured closer to the border, of planes with too few points in
        ``labels``: the normal test judges those planes on them, against the noise floor of
        ``labels`` (the quadric does not: it is ill-conditioned across a thin strip).

    Returns
    -------
    numpy.ndarray
        (P,) bool, True for a curved plane (a plane with too few points is never curved).
    """
    curved = np.zeros(num_planes, dtype=bool)
    if num_planes == 0:
        return curved
    if normals is not None:
        spread, count = spread_of_groups(normals, labels, num_planes, cfg.max_samples)
        floor = noise_floor_deg(spread, count)
        if np.isfinite(floor):
            limit = max(floor, cfg.min_floor_deg) + cfg.max_extra_spread_deg
            curved |= spread > limit
            thin = np.flatnonzero(count < MIN_SAMPLES) + 1
            if thin_labels is not None and thin.size:
                spread, _ = spread_of_groups(normals, np.where(np.isin(thin_labels, thin),
                                                               thin_labels, 0),
                                             num_planes, cfg.max_samples)
                curved |= spread > limit
    if cfg.quadric_ratio > 0:
        quadric = labels if quadric_labels is None else quadric_labels
        curved |= quadric_ratio(points, quadric, num_planes, cfg.max_samples) > cfg.quadric_ratio
    return curved


def drop_planes(rec: Reconstruction, drop: np.ndarray) -> Reconstruction:
    """``rec`` with the planes flagged in ``drop`` made non-planar and the rest renumbered.

    Parameters
    ----------
    rec : Reconstruction
    drop : numpy.ndarray
        (P,) bool.

    Returns
    -------
    Reconstruction
        Same frame, config and timings; labels 0..P' in the original order.
    """
    keep = ~np.asarray(drop, dtype=bool)
    remap = np.zeros(rec.num_planes + 1, dtype=np.int32)
    remap[1:][keep] = np.arange(1, int(keep.sum()) + 1, dtype=np.int32)
    assert rec.rmse is not None and rec.support is not None
    return Reconstruction(frame=rec.frame, labels=remap[rec.labels],
                          planes=rec.planes[keep],
                          rmse=rec.rmse[keep], support=rec.support[keep], config=rec.config,
                          timings=rec.timings)


def check_image(rec: Reconstruction, cfg: PlanarityConfig,
                epsilon: float | None = None) -> Reconstruction:
    """The planarity test on a refined image reconstruction.

    Parameters
    ----------
    rec : Reconstruction
        Final planes of one frame; its frame needs depth (and normals, else only the quadric
        test runs).
    cfg : PlanarityConfig
    epsilon : float, optional
        The RANSAC's inlier threshold in unit-sphere units (fraction of the scene radius),
        which ``cfg.inlier_band`` multiplies; without it all of a plane's pixels are tested.

    Returns
    -------
    Reconstruction
        ``rec`` itself when no plane is curved, else a copy without the curved planes.
    """
    frame = rec.frame
    if not cfg.enabled or rec.num_planes == 0 or frame.depth is None:
        return rec
    h, w = frame.shape
    radius = int(round(cfg.border_px * w / 256))
    # A regular grid of at most about max_points pixels measures every plane that matters.
    step = max(1, math.ceil(math.sqrt(h * w / cfg.max_points)))
    inner = interior_samples(rec.labels, frame.depth, radius, step)
    v, u = np.mgrid[0:h:step, 0:w:step]
    rays = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1) @ np.linalg.inv(frame.K).T
    points = rays * frame.depth[::step, ::step].reshape(-1, 1).astype(np.float64)
    normals = (None if frame.normals is None or frame.normals_from_depth
               else frame.normals[::step, ::step].reshape(-1, 3))
    shape_points = inner
    if cfg.inlier_band > 0 and epsilon is not None:
        shape_points = _near_their_plane(points, inner, rec.planes,
                                         cfg.inlier_band * epsilon * scene_radius(
                                             frame.points(), frame.depth > 0))
    thin_radius = int(round(cfg.thin_border_px * w / 256))
    thin_inner = None
    if (normals is not None and cfg.thin_border_px > 0 and thin_radius < radius
            and np.bincount(inner, minlength=rec.num_planes + 1)[1:].min() < MIN_SAMPLES):
        thin_inner = interior_samples(rec.labels, frame.depth, thin_radius, step)
    curved = curved_planes(points, normals, inner, rec.num_planes, cfg,
                           quadric_labels=shape_points, thin_labels=thin_inner)
    if not curved.any():
        return rec
    out = drop_planes(rec, curved)
    out.frame.notes.append(f"planarity: {int(curved.sum())} plane(s) on curved surfaces set "
                           "non-planar")
    return out


def _near_their_plane(points: np.ndarray, labels: np.ndarray, planes: np.ndarray,
                      tolerance: float) -> np.ndarray:
    """``labels`` with every point farther than ``tolerance`` from its plane set to 0.

    Parameters
    ----------
    points : numpy.ndarray
        (M, 3) camera-frame points, depth units.
    labels : numpy.ndarray
        (M,) int labels 0..P.
    planes : numpy.ndarray
        (P, 4) planes ``n · X + d = 0`` (unit normals) of labels 1..P, same frame and units.
    tolerance : float
        Distance in depth units.

    Returns
    -------
    numpy.ndarray
        (M,) int labels.
    """
    on = labels > 0
    p = np.asarray(planes, dtype=np.float64)[labels[on] - 1]
    near = np.zeros(len(labels), dtype=bool)
    near[on] = np.abs(np.einsum("ij,ij->i", points[on], p[:, :3]) + p[:, 3]) <= tolerance
    return np.where(near, labels, 0)


def check_cloud(points: np.ndarray, normals: np.ndarray | None, labels: np.ndarray,
                edges: np.ndarray, planes: np.ndarray, epsilon: float, cfg: PlanarityConfig
                ) -> tuple[np.ndarray, np.ndarray]:
    """The planarity test on a cloud's labels.

    Parameters
    ----------
    points : numpy.ndarray
        (M, 3) working-cloud points.
    normals : numpy.ndarray or None
        (M, 3) unit normals that came with the cloud; None when they were estimated from the
        points (see :func:`curved_planes`).
    labels : numpy.ndarray
        (M,) int labels 0..P.
    edges : numpy.ndarray
        (E, 2) int edges of the cloud's neighbour graph; a point joined to a point of another
        label is on a border and left out of the test.
    planes : numpy.ndarray
        (P, 4) planes ``n · X + d = 0`` of labels 1..P, in the points' frame.
    epsilon : float
        The RANSAC's inlier distance in the points' units.
    cfg : PlanarityConfig

    Returns
    -------
    labels : numpy.ndarray
        (M,) int32 labels 0..P' with the curved planes set to 0 and the others renumbered in
        their order.
    kept : numpy.ndarray
        (P,) bool, the planes kept (rows of the caller's plane array to keep).
    """
    labels = np.asarray(labels, dtype=np.int32)
    num = int(labels.max(initial=0))
    if not cfg.enabled or num == 0:
        return labels, np.ones(num, dtype=bool)
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    border = np.zeros(len(labels), dtype=bool)
    cross = labels[e[:, 0]] != labels[e[:, 1]]
    border[e[cross, 0]] = True
    border[e[cross, 1]] = True
    inner = np.where(border, 0, labels)
    curved = curved_planes(points, normals, inner, num, cfg)
    thin = np.flatnonzero(np.bincount(inner, minlength=num + 1)[1:] < MIN_SAMPLES) + 1
    for p in thin:
        curved[p - 1] |= _crease_strip(points, labels, e[cross], p, planes, epsilon)
    remap = np.zeros(num + 1, dtype=np.int32)
    remap[1:][~curved] = np.arange(1, int((~curved).sum()) + 1, dtype=np.int32)
    return remap[labels], ~curved


def _crease_strip(points: np.ndarray, labels: np.ndarray, cross: np.ndarray, plane: int,
                  planes: np.ndarray, epsilon: float) -> bool:
    """Whether plane ``plane`` (1-based), too thin for the curvature tests, is a strip along a
    crease: PCA normals estimated from a cloud blend two faces' normals along their crease,
    and RANSAC can group those points into a plane of their own. Such a strip is redundant:
    at least 80 % of its points lie within 2 ε of a plane it touches (across the ``cross``
    edges, (E, 2) graph edges between different labels). A thin face of its own (a floor
    seen at a grazing angle) leaves its neighbours' planes and is kept."""
    members = labels == plane
    ends = cross[members[cross[:, 0]] | members[cross[:, 1]]].ravel()
    touching = np.setdiff1d(labels[ends], [0, plane])
    if touching.size == 0:
        return False
    n = planes[touching - 1]
    dist = np.abs(points[members] @ n[:, :3].T + n[:, 3]).min(axis=1)
    return bool(np.mean(dist <= 2.0 * epsilon) >= 0.8)
