"""Built-in fusers: match per-view planes across views and fuse them into global planes.

``average`` implements the paper's sparse-view fusion (§III-C and appendix): plane matches come
from SfM keypoint matches with a mutual check, completed by a plane-reprojection IoU check;
matched planes (over any number of views) are fused by the principal eigenvector of
``Σ n_i n_iᵀ`` and the mean offset, in the SfM world frame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from monoplane.datamodel import (
    Reconstruction,
    Scene,
    SfmResult,
    pixel_rays,
    plane_to_camera,
    plane_to_world,
    ray_plane_depth,
)
from monoplane.errors import InvalidInput
from monoplane.geometry.plane_matching import (
    consistent_groups,
    fuse_planes,
    keypoint_counts,
    keypoint_plane_matches,
    normal_angles_deg,
    relative_pose,
    reprojection_iou,
    reprojection_plane_matches,
)
from monoplane.hookspecs import hookimpl
from monoplane.stages.base import Fuser, Stage, param


@dataclass
class AverageConfig:
    """Parameters of the ``average`` fuser."""

    use_keypoints: bool = param(True, "match planes through SfM keypoint matches")
    min_keypoint_matches: int = param(
        10, "a keypoint plane match needs more than this many keypoint matches")
    mutual_ratio: float = param(
        0.6, "share of a plane's keypoint matches that must land in the candidate, both ways")
    use_reprojection: bool = param(True, "match planes by reprojection overlap (IoU)")
    min_reprojection_iou: float = param(
        0.5, "IoU, in the visible region, a reprojected plane needs with its match")
    max_normal_angle_deg: float = param(
        30.0, "matched planes' normals may differ by at most this in the world frame (deg)")
    use_geometry: bool = param(
        True, "also match planes that overlap some and agree closely in 3D (see docs)")
    geometry_min_iou: float = param(
        0.2, "reprojection IoU a geometric match needs at least")
    geometry_max_angle_deg: float = param(
        10.0, "world normals of a geometric match differ by at most this (deg)")
    geometry_max_distance: float = param(
        0.05, "each plane's 3D centroid lies within this share of its depth of the other plane")
    grid_width: int = param(
        160, "reprojection check resolution: every (width // grid_width)-th pixel row and "
        "column of a view is warped (all pixels below 320 px)")
    recover_planes: bool = param(
        True, "give a view the global planes that other views see where it merged them into a "
        "neighbour (see docs/multiview.md)")
    recover_min_views: int = param(
        2, "views that must see a global plane before it is recovered in another view")
    recover_max_distance: float = param(
        0.1, "a recovered pixel's depth lies within this share of itself from the global plane")
    recover_min_area: float = param(
        0.001, "smallest recovered region, as a share of the view's pixels")


@dataclass
class PlaneMatch:
    """One accepted correspondence between planes of two views (1-based local ids).

    ``strength`` orders matches when global planes are formed: ``1 + share`` for keypoint
    matches (``share`` the smaller of the two mutual keypoint shares, so any keypoint match
    outranks any reprojection match), the IoU score for reprojection matches and half the IoU
    for geometric matches.
    """

    view_i: int
    plane_i: int
    view_j: int
    plane_j: int
    criterion: str
    strength: float = 1.0


class AverageFuser(Fuser):
    """Keypoint + reprojection plane matching, eigenvector-normal and mean-offset fusion."""

    name = "average"
    Config = AverageConfig

    def fuse(self, views: list[Reconstruction], sfm: SfmResult) -> Scene:
        """Fuse scale-aligned per-view planes into global planes.

        Parameters
        ----------
        views : list of Reconstruction
            One per camera of ``sfm``, in the same order; planes in each camera's frame and in
            SfM units (depth already scale-aligned), label maps at the cameras' resolution.
        sfm : SfmResult
            Cameras, keypoints and pairwise keypoint matches.

        Returns
        -------
        Scene
            Global planes in the SfM world frame, each oriented to face the first camera that
            sees it, and ``links[v][local] = global``.
        """
        return self.fuse_with_matches(views, sfm)[0]

    def fuse_with_matches(self, views: list[Reconstruction],
                          sfm: SfmResult) -> tuple[Scene, list[PlaneMatch]]:
        """:meth:`fuse`, also returning the accepted plane correspondences."""
        if len(views) != sfm.num_views:
            raise InvalidInput(f"{len(views)} views but {sfm.num_views} SfM cameras")
        for v, (rec, cam) in enumerate(zip(views, sfm.cameras, strict=True)):
            if rec.frame.shape != (cam.height, cam.width):
                raise InvalidInput(
                    f"view {v}: labels are {rec.frame.width}x{rec.frame.height} but the camera "
                    f"is {cam.width}x{cam.height}"
                )
        matches = self.match_planes(views, sfm)
        nodes = [(v, local) for v, rec in enumerate(views)
                 for local in range(1, rec.num_planes + 1)]
        index = {node: k for k, node in enumerate(nodes)}
        edges = np.array([(index[(m.view_i, m.plane_i)], index[(m.view_j, m.plane_j)])
                          for m in matches], dtype=np.int64).reshape(-1, 2)
        groups = consistent_groups(np.array([v for v, _ in nodes], dtype=np.int64), edges,
                                   np.array([m.strength for m in matches]))
        # Report only the matches the consistent grouping kept.
        group_of = {nodes[k]: g for g, members in enumerate(groups) for k in members}
        matches = [m for m in matches
                   if group_of[(m.view_i, m.plane_i)] == group_of[(m.view_j, m.plane_j)]]

        world = [plane_to_world(rec.params, cam.R, cam.t) if rec.num_planes else
                 np.zeros((0, 4)) for rec, cam in zip(views, sfm.cameras, strict=True)]
        planes, links = [], [dict() for _ in views]
        for group in groups:
            members = [nodes[k] for k in group]
            fused = fuse_planes(np.array([world[v][local - 1] for v, local in members]))
            first = sfm.cameras[members[0][0]]
            if fused[:3] @ first.center + fused[3] < 0:
                fused = -fused
            for v, local in members:
                links[v][local] = len(planes)
            planes.append(fused)
        planes_array = np.array(planes).reshape(-1, 4)
        views = list(views)
        if self.config.recover_planes:
            views, links = self.recover_planes(views, sfm, planes_array, links)
        scene = Scene(cameras=list(sfm.cameras), views=views, planes=planes_array, links=links,
                      points=sfm.points)
        return scene, matches

    def recover_planes(self, views: list[Reconstruction], sfm: SfmResult, planes: np.ndarray,
                       links: list[dict[int, int]]
                       ) -> tuple[list[Reconstruction], list[dict[int, int]]]:
        """Relabel a view's pixels onto a global plane that other views see and it merged away.

        A view's segmentation sometimes swallows a small plane into a larger neighbour while
        the other views keep it apart; the views then disagree on that surface. For every
        global plane seen in at least ``recover_min_views`` views and every other view ``i``:
        the members' masks are carried into view ``i`` through the global plane (each pixel of
        ``i`` is lifted onto the plane and projected into the member views). The pixels they
        cover whose depth in view ``i`` lies on the global plane (within
        ``recover_max_distance`` of their depth) and closer to it than to their own plane
        become a new plane of view ``i``, linked to the global plane: the largest such
        4-connected region, when it covers ``recover_min_area`` of the view.

        Parameters
        ----------
        views : list of Reconstruction
            Scale-aligned views (camera frames, SfM units).
        sfm : SfmResult
            Their cameras.
        planes : numpy.ndarray
            (G, 4) global planes, world frame.
        links : list of dict
            ``links[v][local] = global``.

        Returns
        -------
        (list of Reconstruction, list of dict)
            Views with recovered planes appended (new local ids ``P + 1``, ...), and the links.
        """
        cfg = self.config
        views, links = list(views), [dict(t) for t in links]
        members: dict[int, list[tuple[int, int]]] = {}
        for v, table in enumerate(links):
            for local, g in table.items():
                members.setdefault(g, []).append((v, local))
        rays: dict[int, np.ndarray] = {}  # each view's pixel rays, computed once
        for g in sorted(members):
            seen = {v for v, _ in members[g]}
            if len(seen) < cfg.recover_min_views:
                continue
            for i in range(len(views)):
                if i in seen:
                    continue
                rec, cam = views[i], sfm.cameras[i]
                if i not in rays:
                    rays[i] = pixel_rays(cam.K, cam.height, cam.width)
                region = _recovered_region(views, sfm.cameras, members[g], i, planes[g], cfg,
                                           self._step(rec), rays[i])
                if region is None:
                    continue
                plane = plane_to_camera(planes[g], cam.R, cam.t)[0]
                labels = rec.labels.copy()
                labels[region] = rec.num_planes + 1
                points = rays[i][region] * rec.frame.depth[region, None]
                rmse = float(np.sqrt(np.mean((points @ plane[:3] + plane[3]) ** 2)))
                views[i] = replace(rec, labels=labels, params=np.vstack([rec.params, plane]),
                                   rmse=np.append(rec.rmse, rmse),
                                   support=np.append(rec.support, int(region.sum())))
                links[i][rec.num_planes + 1] = g
        return views, links

    def match_planes(self, views: list[Reconstruction], sfm: SfmResult) -> list[PlaneMatch]:
        """Plane correspondences between every pair of views.

        Returns
        -------
        list of PlaneMatch
            Accepted pairs; ``criterion`` is ``"keypoints"`` or ``"reprojection"``.
        """
        cfg = self.config
        out: list[PlaneMatch] = []
        centroids = [_world_centroids(rec, cam) for rec, cam in zip(views, sfm.cameras,
                                                                      strict=True)]
        world = [plane_to_world(rec.params, cam.R, cam.t).reshape(-1, 4)
                 for rec, cam in zip(views, sfm.cameras, strict=True)]
        for i in range(len(views)):
            for j in range(i + 1, len(views)):
                a, b = views[i], views[j]
                if a.num_planes == 0 or b.num_planes == 0:
                    continue
                ci, cj = sfm.cameras[i], sfm.cameras[j]
                angles = normal_angles_deg(a.params[:, :3] @ ci.R, b.params[:, :3] @ cj.R)
                found: dict[tuple[int, int], tuple[str, float]] = {}
                pairs = sfm.matches.get((i, j))
                if cfg.use_keypoints and pairs is not None and len(pairs):
                    counts = keypoint_counts(a.labels, b.labels, sfm.keypoints[i],
                                             sfm.keypoints[j], pairs)
                    rows = np.maximum(counts[1:, 1:].sum(axis=1), 1)
                    cols = np.maximum(counts[1:, 1:].sum(axis=0), 1)
                    for p, q in keypoint_plane_matches(counts, cfg.min_keypoint_matches,
                                                       cfg.mutual_ratio):
                        c = counts[p, q]
                        share = min(c / rows[p - 1], c / cols[q - 1])
                        found[(int(p), int(q))] = ("keypoints", 1.0 + float(share))
                if cfg.use_reprojection:
                    R_ji, t_ji = relative_pose(ci.R, ci.t, cj.R, cj.t)
                    iou_ij = reprojection_iou(a.labels, a.params, ci.K, b.labels, cj.K, R_ji,
                                              t_ji, self._step(b))
                    iou_ji = reprojection_iou(b.labels, b.params, cj.K, a.labels, ci.K,
                                              R_ji.T, -R_ji.T @ t_ji, self._step(a))
                    score = np.maximum(iou_ij, iou_ji.T)
                    for p, q in reprojection_plane_matches(iou_ij, iou_ji,
                                                           cfg.min_reprojection_iou):
                        found.setdefault((int(p), int(q)),
                                         ("reprojection", float(score[p - 1, q - 1])))
                    if cfg.use_geometry:
                        for p, q in _geometric_matches(score, angles, centroids[i],
                                                       centroids[j], world[i], world[j], cfg):
                            found.setdefault((p, q), ("geometry",
                                                      0.5 * float(score[p - 1, q - 1])))
                for (p, q), (criterion, strength) in found.items():
                    if angles[p - 1, q - 1] <= cfg.max_normal_angle_deg:
                        out.append(PlaneMatch(i, p, j, q, criterion, strength))
        return out

    def _step(self, rec: Reconstruction) -> int:
        return max(1, rec.frame.width // max(self.config.grid_width, 1))


def _world_centroids(rec: Reconstruction, cam: object) -> np.ndarray:
    """(P, 4) world centroid of each plane's pixels (lifted on its plane) and its mean depth."""
    from monoplane.datamodel import pixel_rays

    out = np.full((rec.num_planes, 4), np.nan)
    if rec.num_planes == 0:
        return out
    depth = rec.planar_depth()[::2, ::2]
    labels = rec.labels[::2, ::2]
    rays = pixel_rays(cam.K, cam.height, cam.width)[::2, ::2]
    ok = (labels > 0) & (depth > 0)
    x = rays[ok] * depth[ok, None]
    lab = labels[ok] - 1
    count = np.bincount(lab, minlength=rec.num_planes)
    has = count > 0
    for axis in range(3):
        out[has, axis] = np.bincount(lab, weights=x[:, axis], minlength=rec.num_planes)[
            has] / count[has]
    out[has, 3] = out[has, 2]
    out[:, :3] = (out[:, :3] - cam.t) @ cam.R
    return out


def _recovered_region(views: list[Reconstruction], cameras: list, members: list[tuple[int, int]],
                      i: int, plane_world: np.ndarray, cfg: AverageConfig,
                      step: int, rays_all: np.ndarray) -> np.ndarray | None:
    """(H, W) bool pixels of view ``i`` to relabel onto ``plane_world``, or None (see
    :meth:`AverageFuser.recover_planes`; ``rays_all`` is view ``i``'s (H, W, 3)
    :func:`pixel_rays`). A pass on every ``step``-th pixel finds whether there is anything to
    recover and where; the full-resolution pass runs on that box only."""
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
            z_own = ray_plane_depth(rays, rec.params[np.maximum(labels, 1) - 1])
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


def _geometric_matches(score: np.ndarray, angles: np.ndarray, cent_i: np.ndarray,
                       cent_j: np.ndarray, world_i: np.ndarray, world_j: np.ndarray,
                       cfg: AverageConfig) -> list[tuple[int, int]]:
    """Plane pairs that overlap some (IoU) and agree in 3D: normals and centroid distances.

    This catches a plane that one view segments larger than another (e.g. together with a
    coplanar neighbour), whose IoU stays below the reprojection threshold.
    """
    out = []
    for p, q in np.argwhere(score >= cfg.geometry_min_iou):
        if angles[p, q] > cfg.geometry_max_angle_deg:
            continue
        ci, cj = cent_i[p], cent_j[q]
        if not (np.isfinite(ci).all() and np.isfinite(cj).all()):
            continue
        d_ij = abs(world_j[q, :3] @ ci[:3] + world_j[q, 3]) / max(ci[3], 1e-9)
        d_ji = abs(world_i[p, :3] @ cj[:3] + world_i[p, 3]) / max(cj[3], 1e-9)
        if max(d_ij, d_ji) <= cfg.geometry_max_distance:
            out.append((int(p) + 1, int(q) + 1))
    return out


@hookimpl
def monoplane_register_fusers() -> list[type[Stage]]:
    """Register the built-in fusers."""
    return [AverageFuser]
