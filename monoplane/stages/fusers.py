"""Built-in fusers: match per-view planes across views and fuse them into global planes.

``average`` implements the paper's sparse-view fusion (§III-C and appendix): plane matches come
from SfM keypoint matches with a mutual check, completed by a plane-reprojection IoU check;
matched planes (over any number of views) are fused by the principal eigenvector of
``Σ n_i n_iᵀ`` and the mean offset, in the SfM world frame. Around that, rules that keep the
fusion from over-splitting (docs/multiview.md, "Fusion that does not over-split"): view planes
on curved surfaces are left out, coplanar pieces of one surface are merged (also two planes of
one view), and a plane that one view alone segments is checked against the other views that
see it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from monoplane.contracts import Fuser, Stage, param
from monoplane.datamodel import (
    Reconstruction,
    Scene,
    SfmResult,
    pixel_rays,
    plane_to_camera,
    plane_to_world,
)
from monoplane.errors import InvalidInput
from monoplane.geometry.flatness import noise_floor_deg, normal_spread_deg
from monoplane.geometry.normals import DEFAULT_NORMALS_METHOD, fit_method, normals_from_depth
from monoplane.geometry.plane_matching import (
    consistent_groups,
    fuse_planes,
    geometric_matches,
    keypoint_counts,
    keypoint_plane_matches,
    normal_angles_deg,
    relative_pose,
    reprojection_iou,
    reprojection_plane_matches,
    world_centroids,
)
from monoplane.geometry.plane_merging import CoplanarMerger
from monoplane.geometry.plane_transfer import (
    plane_footprint,
    project_to_view,
    recovered_region,
    replace_plane,
    unlabel_planes,
)
from monoplane.hookspecs import hookimpl


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
    reject_curved: bool = param(
        True, "leave out of fusion the view planes whose normal cue spreads like a curved "
        "surface's (see docs/multiview.md)")
    max_extra_spread_deg: float = param(
        4.0, "a view plane is curved when its normals spread more than this beyond the scene's "
        "noise floor (median angle to their dominant direction, degrees)")
    merge_coplanar: bool = param(
        True, "merge global planes that are coplanar and touch, and let one global plane hold "
        "several planes of a view when they are coplanar (see docs/multiview.md)")
    merge_max_angle_deg: float = param(
        15.0, "normals of merged planes differ by at most this (degrees)")
    merge_max_distance: float = param(
        0.02, "one merged group's view planes lie within this share of their depth of the "
        "other group's plane (median over each plane's pixels)")
    merge_max_gap: float = param(
        0.05, "merged footprints on the common plane come within this share of their depth")
    merge_max_see_through: float = param(
        0.05, "coplanar planes of one view farther apart than merge_max_gap still merge when at "
        "most this share of the pixels between them sees through the plane (see docs)")
    merge_samples: int = param(
        1500, "pixels sampled per view plane for the coplanarity and contact tests")
    see_through_distance: float = param(
        0.1, "a view's depth within this share of itself from the plane agrees with it; "
        "nearer is an occluder, farther sees through the plane")
    check_single_view: bool = param(
        True, "test each global plane seen by one view against the other views that see its "
        "footprint: drop, absorb or recover it (see docs/multiview.md)")
    single_min_visible: float = param(
        0.25, "a view takes part in the test when it sees this share of the plane's samples")
    single_max_contradiction: float = param(
        0.5, "share of the seen samples contradicting the plane that drops it")
    single_min_support: float = param(
        0.5, "share of the seen samples on one global plane that absorbs it there, or on no "
        "plane that lets it be recovered there")


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
        """:meth:`fuse`, also returning the accepted plane correspondences.

        The steps, each configurable (docs/multiview.md, "Fusion that does not over-split"):

        1. view planes on curved surfaces are left out (:meth:`flat_planes`);
        2. plane matches between every pair of views (:meth:`match_planes`) are grouped
           strongest first; two groups holding planes of one view join only when their union
           is coplanar (``merge_*``);
        3. groups that are coplanar and touch, or whose gap one view explains by an occluder,
           are merged (``merge_*``);
        4. a group seen by one view only is checked against the other views that see it:
           dropped, absorbed into another group, or marked for recovery
           (:meth:`check_single_view`);
        5. each group is fused (:func:`~monoplane.geometry.plane_matching.fuse_planes`) and
           planes merged away in some view are recovered there (:meth:`recover_planes`).
        """
        if len(views) != sfm.num_views:
            raise InvalidInput(f"{len(views)} views but {sfm.num_views} SfM cameras")
        for v, (rec, cam) in enumerate(zip(views, sfm.cameras, strict=True)):
            if rec.frame.shape != (cam.height, cam.width):
                raise InvalidInput(
                    f"view {v}: labels are {rec.frame.width}x{rec.frame.height} but the camera "
                    f"is {cam.width}x{cam.height}"
                )
        cfg = self.config
        flat = self.flat_planes(views)
        # Rejected planes are non-planar for every later step: matching, fusion, recovery.
        screened = [unlabel_planes(rec, ~ok) for rec, ok in zip(views, flat, strict=True)]
        matches = self.match_planes(screened, sfm)
        nodes = [(v, local) for v, rec in enumerate(views)
                 for local in range(1, rec.num_planes + 1) if flat[v][local - 1]]
        index = {node: k for k, node in enumerate(nodes)}
        edges = np.array([(index[(m.view_i, m.plane_i)], index[(m.view_j, m.plane_j)])
                          for m in matches], dtype=np.int64).reshape(-1, 2)
        world = [plane_to_world(rec.planes, cam.R, cam.t) if rec.num_planes else
                 np.zeros((0, 4)) for rec, cam in zip(views, sfm.cameras, strict=True)]
        node_planes = np.array([world[v][local - 1] for v, local in nodes]).reshape(-1, 4)
        merger = CoplanarMerger(nodes, node_planes, screened, sfm.cameras,
                                [self._step(rec) for rec in screened], cfg)
        groups = consistent_groups(np.array([v for v, _ in nodes], dtype=np.int64), edges,
                                   np.array([m.strength for m in matches]),
                                   merger.coplanar if cfg.merge_coplanar else None)
        if cfg.merge_coplanar:
            groups = merger.merge(groups)
        absorbed: dict[int, int] = {}
        recoverable: set[int] = set()
        if cfg.check_single_view:
            groups, absorbed, recoverable = self.check_single_view(
                screened, views, sfm, nodes, groups, merger)
        # Report only the matches the grouping kept.
        group_of = {nodes[k]: g for g, members in enumerate(groups) for k in members}
        group_of.update({nodes[k]: g for k, g in absorbed.items()})
        matches = [m for m in matches if group_of.get((m.view_i, m.plane_i), -1)
                   == group_of.get((m.view_j, m.plane_j), -2)]

        planes, links = [], [dict() for _ in views]
        for group in groups:
            members = [nodes[k] for k in group]
            fused = fuse_planes(node_planes[group])
            first = sfm.cameras[members[0][0]]
            if fused[:3] @ first.center + fused[3] < 0:
                fused = -fused
            for v, local in members:
                links[v][local] = len(planes)
            planes.append(fused)
        planes_array = np.array(planes).reshape(-1, 4)
        for k, g in absorbed.items():
            # An absorbed plane becomes its global plane in its camera, as a recovered one:
            # its own fit disagreed with the global plane, the other views' depth did not.
            v, local = nodes[k]
            screened[v] = replace_plane(screened[v], sfm.cameras[v], local, planes_array[g])
            links[v][local] = g
        if cfg.recover_planes:
            screened, links = self.recover_planes(screened, sfm, planes_array, links,
                                                  recoverable)
        # A rejected plane keeps its local label (the view's own segmentation, labels.png) but
        # no link: it is non-planar in the view's global label map.
        out = [replace(s, labels=np.where((s.labels == 0) & (rec.labels > 0)
                                          & ~ok[np.maximum(rec.labels, 1) - 1],
                                          rec.labels, s.labels).astype(np.int32))
               if not ok.all() else s for rec, s, ok in zip(views, screened, flat, strict=True)]
        scene = Scene(cameras=list(sfm.cameras), views=out, planes=planes_array, links=links,
                      points=sfm.points)
        return scene, matches

    def flat_planes(self, views: list[Reconstruction]) -> list[np.ndarray]:
        """Which view planes are flat enough to fuse (the curvature test).

        A plane is rejected as curved when the median angle between its pixels' normals (the
        view's normal cue, away from its border) and their dominant direction exceeds the
        scene's noise floor (:func:`~monoplane.geometry.flatness.noise_floor_deg`, pooled
        over all views: one cue, one noise level) by more than ``max_extra_spread_deg``.

        Parameters
        ----------
        views : list of Reconstruction
            Per-view planes; ``frame.normals`` (camera frame) or, without them, normals
            estimated from ``frame.depth`` with the default cue stage's fit
            (:func:`~monoplane.geometry.normals.fit_method` of ``"auto"``).

        Returns
        -------
        list of numpy.ndarray
            (P_v,) bool per view, True for a plane that takes part in fusion.
        """
        keep = [np.ones(rec.num_planes, dtype=bool) for rec in views]
        if not self.config.reject_curved:
            return keep
        spreads, weights = [], []
        for rec in views:
            width = rec.frame.width
            normals = rec.frame.normals
            if normals is None:
                # The fit the default cue stage would have made, so the test sees the normals
                # the view was segmented with.
                method = fit_method(DEFAULT_NORMALS_METHOD, rec.frame.depth_measured)
                normals = normals_from_depth(rec.frame.depth, rec.frame.K, method=method)
            # The border band scales with the image: the cue blurs over a fixed share of it.
            spread, count = normal_spread_deg(normals, rec.labels, rec.num_planes,
                                              radius=max(1, width // 256),
                                              step=self._step(rec))
            spreads.append(spread)
            weights.append(count)
        floor = noise_floor_deg(np.concatenate(spreads), np.concatenate(weights))
        if not np.isfinite(floor):
            return keep
        for k, spread in enumerate(spreads):
            # A plane too small to measure (NaN) is kept: no evidence either way.
            keep[k] = ~(spread > floor + self.config.max_extra_spread_deg)
        return keep

    def check_single_view(self, views: list[Reconstruction], originals: list[Reconstruction],
                          sfm: SfmResult, nodes: list[tuple[int, int]],
                          groups: list[list[int]], merger: CoplanarMerger
                          ) -> tuple[list[list[int]], dict[int, int], set[int]]:
        """Test each group seen by one view only against the other views that see it.

        A surface that one view alone segments should be one that only that view sees. The
        group's pixels, lifted onto its fused plane, are projected into every other view; a
        view *sees* the group where the projection is in front of the camera and inside the
        image, unless the view's depth there is nearer than the plane by more than
        ``see_through_distance`` (occluded). Views that see at least ``single_min_visible`` of
        the group's samples take part; over them, each seen sample is

        * a *contradiction* when the view's depth lies beyond the plane by more than
          ``see_through_distance`` (the view sees through it) or the view has a curved
          plane there (:meth:`flat_planes`);
        * *support* for global plane ``h`` when the depth agrees and the view's plane there
          belongs to ``h``;
        * *unsegmented* when the depth agrees and the view has no plane there.

        Then, in this order: with ``single_max_contradiction`` of contradictions the group is
        dropped (its view planes stay in the view's labels but become non-planar in its global
        labels); with ``single_min_support`` on one group ``h`` it is absorbed into ``h``
        (linked to it, and re-expressed as ``h``'s plane, whose parameters it does not change);
        with ``single_min_support`` unsegmented it may be recovered in those views
        (:meth:`recover_planes`). Otherwise, and when no view sees it, it stays as it is.

        Parameters
        ----------
        views : list of Reconstruction
            Scale-aligned views without their curved planes (labels 0 there).
        originals : list of Reconstruction
            The same views with their curved planes.
        sfm : SfmResult
            Their cameras.
        nodes : list of (int, int)
            ``(view, local id)`` of each node.
        groups : list of list of int
            Node indices of each group.
        merger : CoplanarMerger
            Fuses a group's plane.

        Returns
        -------
        (list of list of int, dict, set)
            The groups kept, ``absorbed[node] = index of its group in that list``, and the
            indices of the kept single-view groups that may be recovered in other views.
        """
        cfg = self.config
        group_of = np.full(len(nodes), -1)
        for g, members in enumerate(groups):
            group_of[members] = g
        node_index = [np.full(rec.num_planes + 1, -1) for rec in views]
        for k, (v, local) in enumerate(nodes):
            node_index[v][local] = k
        verdicts: dict[int, tuple[str, int]] = {}
        for g, members in enumerate(groups):
            view_set = {nodes[k][0] for k in members}
            if len(view_set) != 1:
                continue
            i = view_set.pop()
            plane = merger.fused(members)
            x = plane_footprint(views[i], sfm.cameras[i], [nodes[k][1] for k in members],
                                plane, self._step(views[i]), cfg.merge_samples)
            contra, unseg, seen, support = self._single_view_evidence(
                views, originals, sfm, i, x, group_of, node_index)
            if seen == 0:
                continue
            best = max(support, key=support.get) if support else -1
            if contra >= cfg.single_max_contradiction * seen:
                verdicts[g] = ("drop", -1)
            elif (best >= 0 and support[best] >= cfg.single_min_support * seen
                  and merger.residual_to(members, merger.fused(groups[best]))
                  <= cfg.merge_max_distance):
                # Its own pixels must lie on ``h`` too: a view that merged this surface into a
                # neighbour would otherwise vouch for the neighbour.
                verdicts[g] = ("absorb", best)
            elif unseg >= cfg.single_min_support * seen:
                verdicts[g] = ("recover", -1)
        # An absorption into a group that is itself dropped or absorbed is not carried out.
        absorb = {g: h for g, (what, h) in verdicts.items()
                  if what == "absorb" and verdicts.get(h, ("keep",))[0] not in ("drop", "absorb")}
        gone = {g for g, (what, _) in verdicts.items() if what == "drop"} | set(absorb)
        new_index = {}
        kept = []
        for g, members in enumerate(groups):
            if g not in gone:
                new_index[g] = len(kept)
                kept.append(members)
        absorbed = {k: new_index[h] for g, h in absorb.items() for k in groups[g]}
        recoverable = {new_index[g] for g, (what, _) in verdicts.items() if what == "recover"}
        return kept, absorbed, recoverable

    def _single_view_evidence(self, views: list[Reconstruction],
                              originals: list[Reconstruction], sfm: SfmResult, i: int,
                              x: np.ndarray, group_of: np.ndarray, node_index: list[np.ndarray]
                              ) -> tuple[int, int, int, dict[int, int]]:
        """What the views other than ``i`` say about a group of view ``i`` (see
        :meth:`check_single_view`).

        Parameters
        ----------
        views, originals : list of Reconstruction
            The views without and with their curved planes.
        sfm : SfmResult
            Their cameras.
        i : int
            The view that alone sees the group.
        x : numpy.ndarray
            (N, 3) world samples of the group on its fused plane.
        group_of : numpy.ndarray
            (nodes,) group index of each node, -1 for none.
        node_index : list of numpy.ndarray
            Per view, node index of each local plane id (-1 for none).

        Returns
        -------
        (int, int, int, dict)
            Contradicting, unsegmented and seen samples over the views taking part, and the
            samples supporting each other group, by group index.
        """
        cfg = self.config
        contra, unseg, seen = 0, 0, 0
        support: dict[int, int] = {}
        for j, (rec, cam) in enumerate(zip(views, sfm.cameras, strict=True)):
            if j == i or len(x) == 0:
                continue
            hit = project_to_view(x, rec.frame.depth, cam, cfg.see_through_distance)
            if hit is None or hit[0].sum() < cfg.single_min_visible * len(x):
                continue
            visible, through, rows, cols = hit
            labels, original = rec.labels[rows, cols], originals[j].labels[rows, cols]
            on = visible & ~through
            # The view's curved planes were removed from ``labels`` only.
            curved = on & (original > 0) & (labels == 0)
            contra += int((visible & through).sum() + curved.sum())
            unseg += int((on & (original == 0)).sum())
            owners = group_of[node_index[j][labels[on & (labels > 0)]]]
            for h, c in zip(*np.unique(owners[owners >= 0], return_counts=True), strict=True):
                support[int(h)] = support.get(int(h), 0) + int(c)
            seen += int(visible.sum())
        return contra, unseg, seen, support

    def recover_planes(self, views: list[Reconstruction], sfm: SfmResult, planes: np.ndarray,
                       links: list[dict[int, int]], single: set[int] | None = None
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
        single : set of int, optional
            Global planes recovered however few views see them (from
            :meth:`check_single_view`).

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
            if len(seen) < cfg.recover_min_views and g not in (single or ()):
                continue
            for i in range(len(views)):
                if i in seen:
                    continue
                rec, cam = views[i], sfm.cameras[i]
                if i not in rays:
                    rays[i] = pixel_rays(cam.K, cam.height, cam.width)
                region = recovered_region(views, sfm.cameras, members[g], i, planes[g], cfg,
                                          self._step(rec), rays[i])
                if region is None:
                    continue
                plane = plane_to_camera(planes[g], cam.R, cam.t)[0]
                labels = rec.labels.copy()
                labels[region] = rec.num_planes + 1
                points = rays[i][region] * rec.frame.depth[region, None]
                rmse = float(np.sqrt(np.mean((points @ plane[:3] + plane[3]) ** 2)))
                views[i] = replace(rec, labels=labels, planes=np.vstack([rec.planes, plane]),
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
        centroids = [world_centroids(rec, cam) for rec, cam in zip(views, sfm.cameras,
                                                                     strict=True)]
        world = [plane_to_world(rec.planes, cam.R, cam.t).reshape(-1, 4)
                 for rec, cam in zip(views, sfm.cameras, strict=True)]
        for i in range(len(views)):
            for j in range(i + 1, len(views)):
                a, b = views[i], views[j]
                if a.num_planes == 0 or b.num_planes == 0:
                    continue
                ci, cj = sfm.cameras[i], sfm.cameras[j]
                angles = normal_angles_deg(a.planes[:, :3] @ ci.R, b.planes[:, :3] @ cj.R)
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
                    iou_ij = reprojection_iou(a.labels, a.planes, ci.K, b.labels, cj.K, R_ji,
                                              t_ji, self._step(b), b.num_planes)
                    iou_ji = reprojection_iou(b.labels, b.planes, cj.K, a.labels, ci.K,
                                              R_ji.T, -R_ji.T @ t_ji, self._step(a), a.num_planes)
                    score = np.maximum(iou_ij, iou_ji.T)
                    for p, q in reprojection_plane_matches(iou_ij, iou_ji,
                                                           cfg.min_reprojection_iou):
                        found.setdefault((int(p), int(q)),
                                         ("reprojection", float(score[p - 1, q - 1])))
                    if cfg.use_geometry:
                        for p, q in geometric_matches(score, angles, centroids[i],
                                                      centroids[j], world[i], world[j], cfg):
                            found.setdefault((p, q), ("geometry",
                                                      0.5 * float(score[p - 1, q - 1])))
                for (p, q), (criterion, strength) in found.items():
                    if angles[p - 1, q - 1] <= cfg.max_normal_angle_deg:
                        out.append(PlaneMatch(i, p, j, q, criterion, strength))
        return out

    def _step(self, rec: Reconstruction) -> int:
        return max(1, rec.frame.width // max(self.config.grid_width, 1))


@hookimpl
def monoplane_register_fusers() -> list[type[Stage]]:
    """Register the built-in fusers."""
    return [AverageFuser]
