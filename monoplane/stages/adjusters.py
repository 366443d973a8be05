"""Built-in adjusters: joint plane–camera refinement of a fused multi-view scene.

``plane-ba`` refines camera poses, per-view depth scales, global planes and the sparse SfM
points together (:mod:`monoplane.geometry.plane_adjustment`): SfM reprojection errors plus the
point-to-plane distances of a subsample of each view's plane pixels to their global plane. A
solve that raises its own objective (robust cost) is rejected and leaves the scene as fused.
``none`` leaves the scene as fused (the paper stops there).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from monoplane.contracts import Adjuster, Stage, param
from monoplane.datamodel import Scene, SfmResult, pixel_rays, plane_to_camera, plane_to_world
from monoplane.errors import InvalidInput
from monoplane.geometry.plane_adjustment import AdjustmentProblem, AdjustmentResult, adjust
from monoplane.geometry.plane_matching import fuse_planes
from monoplane.hookspecs import hookimpl


@dataclass
class PlaneBundleConfig:
    """Parameters of the ``plane-ba`` adjuster."""

    samples_per_plane: int = param(
        64, "plane pixels sampled per view plane for the point-to-plane term")
    sigma_px: float = param(1.0, "expected SfM reprojection noise (pixels)")
    sigma_rel: float = param(
        0.1, "expected relative depth noise of plane pixels (point-to-plane term weight); "
        "monocular depth warps by several percent, so this is loose")
    lift: str = param(
        "planar", "depth that lifts the plane pixels: 'planar' (each view's own plane fit, "
        "which carries its normal cues) or 'cues' (the scale-aligned monocular depth)")
    sigma_normal_deg: float = param(
        1.0, "expected angle between a view plane's normal and its global plane's (degrees)")
    sigma_point: float = param(
        0.03, "expected distance of an SfM point seen inside a plane to that plane, relative "
        "to its depth (0 drops the term)")
    prior_rot_deg: float = param(
        0.5, "pose prior: expected rotation change of a view (degrees)")
    prior_t_rel: float = param(
        0.003, "pose prior: expected translation change, as a share of the view's median "
        "plane depth")
    multi_view_only: bool = param(
        True, "refine only global planes seen in two or more views (others follow their view)")
    refine_points: bool = param(
        True, "refine the SfM points too (False: hold them as COLMAP adjusted them)")
    min_sfm_points: int = param(
        50, "fewest SfM points inside planes to refine at all (when sigma_point > 0): they "
            "are the only multi-view evidence on the planes; without them the plane terms "
            "follow the monocular depth's warps and move the poses the wrong way "
            "(docs/multiview.md)")
    max_evaluations: int = param(20, "cap on the solver's residual evaluations")
    figure_tolerance: float = param(
        math.inf, "also reject a solution that raises a reported figure (reprojection, plane "
        "pixels, normals, SfM points on planes) by more than this share (inf: judge by the "
        "objective alone; 0.05 keeps only solves that worsen no figure)")
    seed: int = param(0, "seed of the plane-pixel subsampling")


class NoAdjuster(Adjuster):
    """Leave the fused scene unchanged (the paper's sparse-view pipeline)."""

    name = "none"

    def adjust(self, scene: Scene, sfm: SfmResult) -> tuple[Scene, SfmResult, dict[str, Any]]:
        """Return the inputs unchanged and an empty report."""
        return scene, sfm, {}


class PlaneBundleAdjuster(Adjuster):
    """Least squares over poses, depth scales, global planes and points (sparse Jacobian)."""

    name = "plane-ba"
    Config = PlaneBundleConfig

    def adjust(self, scene: Scene, sfm: SfmResult) -> tuple[Scene, SfmResult, dict[str, Any]]:
        """Refine ``scene``; see :meth:`monoplane.contracts.Adjuster.adjust`.

        The report holds ``accepted``: when the solution's robust cost is above the initial
        one, or (with a finite ``figure_tolerance``) it raises one of the figures the report
        gives (:data:`~monoplane.geometry.plane_adjustment.FIGURES`), ``scene`` and ``sfm``
        are returned as given, with ``accepted = False``, ``reason`` and the rejected
        solution's summary under ``rejected``.
        """
        cfg = self.config
        n_views = len(scene.cameras)
        if n_views < 2 or scene.planes.shape[0] == 0:
            return scene, sfm, {}
        members: dict[int, list[tuple[int, int]]] = {}
        for v, table in enumerate(scene.links):
            for local, glob in table.items():
                members.setdefault(glob, []).append((v, local))
        refined = sorted(g for g, m in members.items()
                         if len(m) >= (2 if cfg.multi_view_only else 1))
        row = {g: k for k, g in enumerate(refined)}
        if cfg.lift not in ("planar", "cues"):
            raise InvalidInput(f"adjuster.lift must be 'planar' or 'cues', got {cfg.lift!r}")
        samples = self._plane_samples(scene, row)
        pp_point, pp_plane, pp_depth = (self._points_on_planes(scene, sfm, row)
                                        if cfg.sigma_point > 0 else
                                        (np.zeros(0, np.int64),) * 2 + (np.zeros(0),))
        if cfg.sigma_point > 0 and len(pp_point) < cfg.min_sfm_points:
            return scene, sfm, {
                "accepted": False,
                "reason": f"{len(pp_point)} SfM points inside planes, fewer than "
                          f"adjuster.min_sfm_points = {cfg.min_sfm_points}: nothing anchors the "
                          "planes but the monocular depth"}
        prob = self._problem(scene, sfm, refined, samples, (pp_point, pp_plane, pp_depth))
        res = adjust(prob, max_evaluations=cfg.max_evaluations, refine_points=cfg.refine_points,
                     figure_tolerance=cfg.figure_tolerance)
        report = {"accepted": res.accepted, "before": res.before, "after": res.after,
                  "converged": res.success, "message": res.message,
                  "planes_refined": len(refined),
                  "depth_scale_factors": [float(s) for s in res.scales]}
        if not res.accepted:
            # The solve raised its own objective: the scene, cameras, scales and points stay
            # exactly as fused; the report keeps what the solver reached, for diagnosis.
            report.update(reason=res.reason, rejected=res.rejected)
            return scene, sfm, report
        new_scene, new_sfm = self._apply(scene, sfm, res, members, row, refined)
        return new_scene, new_sfm, report

    def _plane_samples(self, scene: Scene, row: dict[int, int]) -> dict[str, list]:
        """The point-to-plane and normal terms' data: per view plane linked to a refined global
        plane (``row[global]`` its row in the solve), its normal and up to
        ``samples_per_plane`` of its pixels lifted into its camera (``lift``).

        Returns
        -------
        dict
            Lists to concatenate: ``samp_view``, ``samp_plane`` and ``samp_x`` (pixels, camera
            frame), ``norm_view``, ``norm_plane`` and ``norm_m`` (normals, camera frame).
        """
        cfg = self.config
        rng = np.random.default_rng(cfg.seed)
        out: dict[str, list] = {k: [] for k in ("samp_view", "samp_plane", "samp_x",
                                                "norm_view", "norm_plane", "norm_m")}
        for v, (rec, cam) in enumerate(zip(scene.views, scene.cameras, strict=True)):
            depth = rec.planar_depth() if cfg.lift == "planar" else rec.frame.depth
            rays = None
            for local, glob in scene.links[v].items():
                if glob not in row:
                    continue
                out["norm_view"].append(v)
                out["norm_plane"].append(row[glob])
                m = rec.planes[local - 1, :3]
                # Same side as the global plane (both normally face the cameras).
                out["norm_m"].append(m if (cam.R.T @ m) @ scene.planes[glob, :3] >= 0 else -m)
                idx = np.flatnonzero((rec.labels.ravel() == local) & (depth.ravel() > 0))
                if len(idx) == 0:
                    continue
                if rays is None:
                    rays = pixel_rays(cam.K, cam.height, cam.width).reshape(-1, 3)
                pick = rng.choice(idx, size=min(cfg.samples_per_plane, len(idx)), replace=False)
                out["samp_x"].append(rays[pick] * depth.ravel()[pick, None])
                out["samp_view"].append(np.full(len(pick), v))
                out["samp_plane"].append(np.full(len(pick), row[glob]))
        return out

    def _problem(self, scene: Scene, sfm: SfmResult, refined: list[int],
                 samples: dict[str, list], on_planes: tuple[np.ndarray, np.ndarray, np.ndarray]
                 ) -> AdjustmentProblem:
        """The least-squares problem: the SfM observations, the plane samples
        (:meth:`_plane_samples`) and the SfM points on planes (:meth:`_points_on_planes`)."""
        cfg = self.config
        n_views = len(scene.cameras)
        obs_view, obs_point, obs_uv = [], [], []
        for v in range(n_views):
            ids = sfm.point_ids[v]
            ok = ids >= 0
            obs_view.append(np.full(int(ok.sum()), v))
            obs_point.append(ids[ok])
            obs_uv.append(sfm.keypoints[v][ok])
        samp_view, samp_plane, samp_x = (samples["samp_view"], samples["samp_plane"],
                                         samples["samp_x"])
        pp_point, pp_plane, pp_depth = on_planes
        return AdjustmentProblem(
            K=np.stack([c.K for c in scene.cameras]), R=np.stack([c.R for c in scene.cameras]),
            t=np.stack([c.t for c in scene.cameras]), points=sfm.points.copy(),
            obs_view=np.concatenate(obs_view).astype(np.int64),
            obs_point=np.concatenate(obs_point).astype(np.int64),
            obs_uv=np.concatenate(obs_uv).reshape(-1, 2),
            planes=scene.planes[refined].copy(),
            samp_view=np.concatenate(samp_view or [np.zeros(0)]).astype(np.int64),
            samp_plane=np.concatenate(samp_plane or [np.zeros(0)]).astype(np.int64),
            samp_x=np.concatenate(samp_x or [np.zeros((0, 3))]).reshape(-1, 3),
            norm_view=np.array(samples["norm_view"], dtype=np.int64),
            norm_plane=np.array(samples["norm_plane"], dtype=np.int64),
            norm_m=np.array(samples["norm_m"], dtype=np.float64).reshape(-1, 3),
            pp_point=pp_point, pp_plane=pp_plane, pp_depth=pp_depth,
            sigma_px=cfg.sigma_px, sigma_rel=cfg.sigma_rel,
            sigma_normal_deg=cfg.sigma_normal_deg, sigma_point=max(cfg.sigma_point, 1e-9),
            prior_rot_deg=cfg.prior_rot_deg,
            prior_t=self._prior_t(samp_view, samp_x, n_views),
        )

    @staticmethod
    def _apply(scene: Scene, sfm: SfmResult, res: AdjustmentResult,
               members: dict[int, list[tuple[int, int]]],
               row: dict[int, int], refined: list[int]) -> tuple[Scene, SfmResult]:
        """The scene and SfM result an accepted solve gives: new poses, depth scales (views'
        depth and plane offsets), refined planes, and the planes left out of the solve moved
        with their views."""
        n_views = len(scene.cameras)
        cameras = [replace(c, R=res.R[v], t=res.t[v]) for v, c in enumerate(scene.cameras)]
        views = []
        for v, rec in enumerate(scene.views):
            s = float(res.scales[v])
            frame = rec.frame.with_(depth=(rec.frame.depth * s).astype(np.float32))
            params = rec.planes.copy()
            params[:, 3] *= s
            views.append(replace(rec, frame=frame, planes=params))
        planes = scene.planes.copy()
        planes[refined] = res.planes
        for g, mem in members.items():
            if g in row:
                continue
            # Planes left out of the solve follow their views' new poses and scales.
            world = np.array([plane_to_world(views[v].planes[local - 1], cameras[v].R,
                                             cameras[v].t).reshape(4) for v, local in mem])
            planes[g] = fuse_planes(world)
        for g in range(planes.shape[0]):
            first = cameras[members[g][0][0]] if g in members else cameras[0]
            if plane_to_camera(planes[g], first.R, first.t).reshape(4)[3] < 0:
                planes[g] = -planes[g]
        scales = list(scene.scales) if scene.scales else [1.0] * n_views
        scales = [float(a * b) for a, b in zip(scales, res.scales, strict=True)]
        new_scene = replace(scene, cameras=cameras, views=views, planes=planes, scales=scales,
                            points=res.points)
        new_sfm = replace(sfm, cameras=[replace(c, R=res.R[v], t=res.t[v])
                                        for v, c in enumerate(sfm.cameras)],
                          points=res.points)
        return new_scene, new_sfm

    @staticmethod
    def _points_on_planes(scene: Scene, sfm: SfmResult, row: dict[int, int]
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """SfM points that lie on a refined global plane, by the masks they are seen in.

        A point counts when every view that sees it places its keypoint well inside (a 5x5
        window of one label) a view plane linked to the same refined global plane; points near
        plane borders or with disagreeing views are left out.

        Returns
        -------
        (numpy.ndarray, numpy.ndarray, numpy.ndarray)
            (Q,) point index, (Q,) row of the global plane in the solve, (Q,) mean depth of
            the point in its views.
        """
        plane_of: dict[int, int] = {}
        depths: dict[int, list[float]] = {}
        for v, (rec, cam) in enumerate(zip(scene.views, scene.cameras, strict=True)):
            ids = sfm.point_ids[v]
            ok = ids >= 0
            if not np.any(ok):
                continue
            h, w = rec.labels.shape
            uv = np.rint(sfm.keypoints[v][ok]).astype(np.int64)
            x = np.clip(uv[:, 0], 2, w - 3)
            y = np.clip(uv[:, 1], 2, h - 3)
            lab = rec.labels[y, x]
            uniform = np.ones(len(lab), dtype=bool)
            for dy in (-2, 0, 2):
                for dx in (-2, 0, 2):
                    uniform &= rec.labels[y + dy, x + dx] == lab
            lut = np.full(int(rec.labels.max()) + 1, -1)
            for local, glob in scene.links[v].items():
                lut[local] = row.get(glob, -1)
            g = np.where(uniform, lut[lab], -1)
            pts = ids[ok]
            z = (sfm.points[pts] @ cam.R.T + cam.t)[:, 2]
            for p, gp, zp in zip(pts.tolist(), g.tolist(), z.tolist(), strict=True):
                if plane_of.get(p, gp) != gp:
                    gp = -1
                plane_of[p] = gp
                depths.setdefault(p, []).append(zp)
        keep = [(p, g) for p, g in plane_of.items() if g >= 0]
        z = np.array([np.mean(depths[p]) for p, _ in keep], dtype=np.float64)
        good = z > 0
        return (np.array([p for p, _ in keep], dtype=np.int64)[good],
                np.array([g for _, g in keep], dtype=np.int64)[good], z[good])

    def _prior_t(self, samp_view: list[np.ndarray], samp_x: list[np.ndarray],
                 n_views: int) -> np.ndarray:
        """(V,) translation prior sigma: ``prior_t_rel`` times each view's median plane depth."""
        views = np.concatenate(samp_view or [np.zeros(0)]).astype(np.int64)
        z = np.concatenate(samp_x or [np.zeros((0, 3))]).reshape(-1, 3)[:, 2]
        overall = float(np.median(z)) if len(z) else 1.0
        out = np.full(n_views, overall)
        for v in range(n_views):
            if np.any(views == v):
                out[v] = float(np.median(z[views == v]))
        return self.config.prior_t_rel * np.maximum(out, 1e-9)


@hookimpl
def monoplane_register_adjusters() -> list[type[Stage]]:
    """Register the built-in adjusters."""
    return [NoAdjuster, PlaneBundleAdjuster]
