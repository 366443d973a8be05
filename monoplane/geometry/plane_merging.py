"""Coplanarity and contact tests between groups of view planes, and their greedy merge.

A global plane in the making is a group of view planes (``(view, local id)`` nodes). Two groups
are one surface when they are coplanar and their footprints touch, or when every view that
holds both explains the gap between them by an occluder (docs/multiview.md, "Fusion that does
not over-split"). The ``average`` fuser (:mod:`monoplane.stages.fusers`) drives these tests;
its settings arrive as ``cfg``, any object with the fields of :class:`MergeSettings` (the
fuser's config).

Frames: world frame of the SfM model; cameras world-to-camera ``x_cam = R x_world + t``
(OpenCV axes); planes ``normal . x + offset = 0``.
"""

from __future__ import annotations

from typing import Protocol

import cv2
import numpy as np

from monoplane.datamodel import (
    Reconstruction,
    pixel_rays,
    plane_to_camera,
    ray_plane_depth,
)
from monoplane.geometry.coplanar import coplanarity_residual, footprint_gap
from monoplane.geometry.plane_matching import fuse_planes


class MergeSettings(Protocol):
    """What the merge tests read (the ``average`` fuser's config has these fields)."""

    merge_max_angle_deg: float
    merge_max_distance: float
    merge_max_gap: float
    merge_max_see_through: float
    merge_samples: int
    see_through_distance: float


def plane_samples(rec: Reconstruction, cam: object,
                   step: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every ``step``-th pixel of each plane lifted by the view's depth into the world.

    The depth, not the plane: whether a view plane's pixels lie on another plane is a question
    about the pixels, which a plane fitted to a small or warped region may misstate.

    Returns
    -------
    list of (numpy.ndarray, numpy.ndarray)
        Per plane (local id ``k + 1`` at index ``k``): (N, 3) world points and their (N,)
        depths in the view's camera; pixels without depth are left out.
    """
    labels = rec.labels[::step, ::step].ravel()
    depth = rec.frame.depth[::step, ::step].ravel().astype(np.float64)
    rays = pixel_rays(cam.K, cam.height, cam.width)[::step, ::step].reshape(-1, 3)
    out = []
    for local in range(1, rec.num_planes + 1):
        mask = (labels == local) & (depth > 0)
        x_cam = rays[mask] * depth[mask, None]
        out.append(((x_cam - cam.t) @ cam.R, depth[mask]))
    return out


class CoplanarMerger:
    """Coplanarity and contact tests between groups of view planes (global planes in the
    making), and the greedy merge of :meth:`monoplane.stages.fusers.AverageFuser.fuse_with_matches`.

    Parameters
    ----------
    nodes : list of (int, int)
        ``(view, local id)`` of each node (view plane).
    planes : numpy.ndarray
        (N, 4) world plane of each node.
    views : list of Reconstruction
        Scale-aligned views (curved planes removed).
    cameras : list of Camera
        Their cameras.
    steps : list of int
        Pixel stride of each view's samples.
    cfg : MergeSettings
        The thresholds (see :class:`monoplane.stages.fusers.AverageConfig`).
    """

    def __init__(self, nodes: list[tuple[int, int]], planes: np.ndarray,
                 views: list[Reconstruction], cameras: list, steps: list[int],
                 cfg: MergeSettings) -> None:
        self.nodes, self.planes, self.cfg = nodes, planes, cfg
        self.views, self.cameras, self.steps = views, cameras, steps
        per_view = [plane_samples(rec, cam, step)
                    for rec, cam, step in zip(views, cameras, steps, strict=True)]
        self.samples = []
        for v, local in nodes:
            x, z = per_view[v][local - 1]
            # Evenly thinned: the tests only need the footprint's shape, not every pixel.
            keep = max(1, int(np.ceil(len(z) / max(cfg.merge_samples, 1))))
            self.samples.append((x[::keep], z[::keep]))

    def fused(self, group: list[int]) -> np.ndarray:
        """(4,) fused world plane of a group of node indices."""
        return fuse_planes(self.planes[group])

    def coplanar(self, group_a: list[int], group_b: list[int]) -> bool:
        """Whether two groups are one plane (:meth:`residual`)."""
        return self.residual(list(group_a), list(group_b)) is not None

    def residual_to(self, group: list[int], plane: np.ndarray) -> float:
        """Coplanarity residual of a group's samples to a given world plane."""
        return coplanarity_residual([self.samples[k][0] for k in group],
                                    [self.samples[k][1] for k in group], plane)

    def residual(self, group_a: list[int], group_b: list[int]) -> float | None:
        """How far two groups are from one plane, or None when they are not one.

        Every member's normal must lie within ``merge_max_angle_deg`` of their union's fused
        normal, and one group's samples within ``merge_max_distance`` of their depth of the
        other group's plane (median per member, the better of the two directions). Measuring
        against the other group's plane, not the union's, keeps two parallel surfaces apart
        (a box top on a table top): the union's plane lies halfway between them.

        Returns
        -------
        float or None
            The residual (relative to depth) when coplanar.
        """
        cos = np.abs(self.planes[group_a + group_b, :3] @ self.fused(group_a + group_b)[:3])
        if np.degrees(np.arccos(np.clip(cos.min(), -1.0, 1.0))) > self.cfg.merge_max_angle_deg:
            return None
        res = min(self.residual_to(group_a, self.fused(group_b)),
                  self.residual_to(group_b, self.fused(group_a)))
        return res if res <= self.cfg.merge_max_distance else None

    def _touch(self, group_a: list[int], group_b: list[int], plane: np.ndarray) -> bool:
        """Whether two coplanar groups are parts of one surface.

        Their footprints on ``plane`` come within ``merge_max_gap`` of their depth, or every
        view that holds planes of both explains the gap between them: within the convex
        hull of their two masks, at most ``merge_max_see_through`` of the other pixels see
        through the plane (depth beyond it by more than ``see_through_distance``); the rest
        lie on it or in front of it (an occluder, e.g. a cabinet before a wall).
        """
        cfg = self.cfg
        xa = np.concatenate([self.samples[k][0] for k in group_a])
        za = np.concatenate([self.samples[k][1] for k in group_a])
        xb = np.concatenate([self.samples[k][0] for k in group_b])
        zb = np.concatenate([self.samples[k][1] for k in group_b])
        if footprint_gap(xa, za, xb, zb, plane) <= cfg.merge_max_gap:
            return True
        shared = ({self.nodes[k][0] for k in group_a} & {self.nodes[k][0] for k in group_b})
        if not shared:
            return False
        for v in shared:
            rec, cam, step = self.views[v], self.cameras[v], self.steps[v]
            labels = rec.labels[::step, ::step]
            mask_a = np.isin(labels, [self.nodes[k][1] for k in group_a if self.nodes[k][0] == v])
            mask_b = np.isin(labels, [self.nodes[k][1] for k in group_b if self.nodes[k][0] == v])
            hull = np.zeros(labels.shape, dtype=np.uint8)
            rows, cols = np.nonzero(mask_a | mask_b)
            cv2.fillConvexPoly(hull, cv2.convexHull(np.stack([cols, rows], 1).astype(np.int32)), 1)
            gap = hull.astype(bool) & ~mask_a & ~mask_b
            if not gap.any():
                continue
            rays = pixel_rays(cam.K, cam.height, cam.width)[::step, ::step][gap]
            z = ray_plane_depth(rays, plane_to_camera(plane, cam.R, cam.t)[0])
            depth = rec.frame.depth[::step, ::step][gap]
            through = (z <= 0) | (depth > z * (1.0 + cfg.see_through_distance))
            if through.mean() > cfg.merge_max_see_through:
                return False
        return True

    def _score(self, group_a: list[int], group_b: list[int]) -> float | None:
        """Coplanarity residual of the union, if coplanar and the footprints touch."""
        res = self.residual(group_a, group_b)
        if res is None or not self._touch(group_a, group_b, self.fused(group_a + group_b)):
            return None
        return res

    def merge(self, groups: list[list[int]]) -> list[list[int]]:
        """Merge coplanar groups that are parts of one surface, the most coplanar pair first.

        Returns
        -------
        list of list of int
            The merged groups, each sorted, ordered by their first node.
        """
        groups = [list(g) for g in groups]
        normals = [self.fused(g)[:3] for g in groups]
        cos_max = np.cos(np.radians(self.cfg.merge_max_angle_deg))
        scores: dict[tuple[int, int], float] = {}

        def consider(a: int, b: int) -> None:
            # The normal test first: most pairs of global planes are far from parallel.
            if abs(normals[a] @ normals[b]) >= cos_max:
                score = self._score(groups[a], groups[b])
                if score is not None:
                    scores[(a, b)] = score

        for a in range(len(groups)):
            for b in range(a + 1, len(groups)):
                consider(a, b)
        alive = set(range(len(groups)))
        while scores:
            a, b = min(scores, key=scores.get)
            groups[a] = sorted(groups[a] + groups[b])
            normals[a] = self.fused(groups[a])[:3]
            alive.discard(b)
            scores = {k: v for k, v in scores.items() if a not in k and b not in k}
            for c in alive - {a}:
                consider(min(a, c), max(a, c))
        return sorted((groups[k] for k in alive), key=lambda g: g[0])
