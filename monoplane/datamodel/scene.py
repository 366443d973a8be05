"""Several views: planes fused across them (:class:`Scene`) and the structure from motion
that relates them (:class:`SfmResult`).

Conventions: see :mod:`monoplane.datamodel`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from monoplane.datamodel.pinhole import Camera
from monoplane.datamodel.planeset import PlaneSet
from monoplane.datamodel.reconstruction import Reconstruction
from monoplane.errors import InvalidInput


@dataclass
class Scene(PlaneSet):
    """Planes fused across several views.

    Attributes
    ----------
    cameras : list of Camera
        One per view, world-to-camera poses in the SfM world frame (scale of the SfM model).
    views : list of Reconstruction
        Per-view planes after scale alignment, in each camera's frame.
    planes : numpy.ndarray
        (G, 4) global planes ``n · x_world + d = 0`` (unit normals); their ``ids`` are the
        global ids 0..G-1 and their ``support`` the pixels of their view regions.
    links : list of dict
        ``links[v][local_id] = global_id`` for view ``v``; local ids are 1-based like labels,
        global ids 0-based rows of ``planes``.
    scales : list of float
        Scale applied to each view's monocular depth to align it with the SfM model.
    points : numpy.ndarray
        (M, 3) sparse SfM points in world coordinates.
    """

    result_kind: ClassVar[str] = "scene"
    first_id: ClassVar[int] = 0

    cameras: list[Camera]
    views: list[Reconstruction]
    planes: np.ndarray
    links: list[dict[int, int]]
    scales: list[float] = field(default_factory=list)
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def __post_init__(self) -> None:
        if len(self.cameras) != len(self.views) or len(self.links) != len(self.views):
            raise InvalidInput("a scene needs one camera, one view and one link table per view")
        self.planes = np.asarray(self.planes, dtype=np.float64).reshape(-1, 4)
        g = self.planes.shape[0]
        for v, table in enumerate(self.links):
            for local, glob in table.items():
                if not 1 <= local <= self.views[v].num_planes or not 0 <= glob < g:
                    raise InvalidInput(f"view {v}: bad link {local} -> {glob}")

    @property
    def support(self) -> np.ndarray:  # type: ignore[override]
        """(G,) int64 pixels of each global plane, summed over the view regions linked to it."""
        out = np.zeros(self.planes.shape[0], dtype=np.int64)
        for rec, table in zip(self.views, self.links, strict=True):
            area = rec.area_px
            for local, glob in table.items():
                out[glob] += area[local - 1]
        return out


@dataclass
class SfmResult:
    """Structure from motion over several views: what a matcher hands to the fuser.

    All pixel coordinates follow this module's convention (pixel centres at integers) and refer
    to the frames' native resolution, whatever resolution the matcher worked at internally.

    Attributes
    ----------
    cameras : list of Camera
        One per input frame, in input order; world-to-camera poses ``x_cam = R x_world + t``
        (OpenCV axes) in the SfM model's frame and (arbitrary) scale.
    points : numpy.ndarray
        (M, 3) float64 sparse 3D points in world coordinates.
    keypoints : list of numpy.ndarray
        ``keypoints[i]`` is (k_i, 2) float64 pixel coordinates ``(u, v)`` of view ``i``'s
        keypoints.
    point_ids : list of numpy.ndarray
        ``point_ids[i]`` is (k_i,) int64: the row of ``points`` each keypoint observes, or -1.
    matches : dict
        ``matches[(i, j)]`` with ``i < j`` is (m, 2) int64 pairs of keypoint indices
        ``(index in view i, index in view j)`` of geometrically verified matches.
    colors : numpy.ndarray or None
        (M, 3) uint8 RGB colour of each point.
    notes : list of str
        Provenance remarks (e.g. whether intrinsics were fixed or estimated).
    registration : list of dict
        How each camera's pose was obtained, one dict per camera with at least ``"method"``:
        ``"sfm"`` (the matcher's model), ``"origin"`` (the world frame of a run whose matcher
        built no model), a registrar's method (``"features"``, ``"planes"``, ...; then also
        ``"reference"``, the view it was placed against, and its evidence) or ``"none"`` (not
        registered: the camera is a placeholder and must not be used). Empty means every
        camera came from the matcher's model.
    correspondences : monoplane.features.Correspondences or None
        The ``[features]`` stage's keypoints and (unverified) matches of every pair of these
        views, computed on demand, for the registrar; None when the views were subset or the
        result came from elsewhere.
    """

    cameras: list[Camera]
    points: np.ndarray
    keypoints: list[np.ndarray]
    point_ids: list[np.ndarray]
    matches: dict[tuple[int, int], np.ndarray] = field(default_factory=dict)
    colors: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    registration: list[dict] = field(default_factory=list)
    correspondences: Any = None

    @property
    def registered(self) -> list[bool]:
        """Per camera, whether its pose is usable (``method`` other than ``"none"``)."""
        if not self.registration:
            return [True] * len(self.cameras)
        return [r.get("method") != "none" for r in self.registration]

    def __post_init__(self) -> None:
        n = len(self.cameras)
        if len(self.keypoints) != n or len(self.point_ids) != n:
            raise InvalidInput(
                f"SfM result: {n} cameras but {len(self.keypoints)} keypoint sets and "
                f"{len(self.point_ids)} point-id sets"
            )
        self.points = np.asarray(self.points, dtype=np.float64).reshape(-1, 3)
        if not np.all(np.isfinite(self.points)):
            raise InvalidInput("SfM result: points contain NaN or inf")
        m = self.points.shape[0]
        if self.colors is not None:
            self.colors = np.asarray(self.colors, dtype=np.uint8).reshape(-1, 3)
            if self.colors.shape[0] != m:
                raise InvalidInput(f"SfM result: {m} points but {self.colors.shape[0]} colours")
        kps, ids = [], []
        for i, (kp, pid) in enumerate(zip(self.keypoints, self.point_ids, strict=True)):
            kp = np.asarray(kp, dtype=np.float64).reshape(-1, 2)
            pid = np.asarray(pid, dtype=np.int64).reshape(-1)
            if pid.shape[0] != kp.shape[0]:
                raise InvalidInput(
                    f"SfM result: view {i} has {kp.shape[0]} keypoints but {pid.shape[0]} ids"
                )
            if not np.all(np.isfinite(kp)):
                raise InvalidInput(f"SfM result: view {i} keypoints contain NaN or inf")
            if pid.size and (pid.min() < -1 or pid.max() >= m):
                raise InvalidInput(f"SfM result: view {i} point ids must lie in -1..{m - 1}")
            kps.append(kp)
            ids.append(pid)
        self.keypoints, self.point_ids = kps, ids
        checked: dict[tuple[int, int], np.ndarray] = {}
        for key, pairs in self.matches.items():
            i, j = (int(key[0]), int(key[1]))
            if not 0 <= i < j < n:
                raise InvalidInput(f"SfM result: match key {key} must be (i, j) with i < j < {n}")
            pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
            if pairs.size and (
                pairs.min() < 0
                or pairs[:, 0].max() >= len(kps[i])
                or pairs[:, 1].max() >= len(kps[j])
            ):
                raise InvalidInput(f"SfM result: matches {key} index missing keypoints")
            checked[(i, j)] = pairs
        self.matches = checked
        if self.registration and len(self.registration) != n:
            raise InvalidInput(f"SfM result: {n} cameras but {len(self.registration)} "
                               "registration records")

    @property
    def num_views(self) -> int:
        """Number of views N."""
        return len(self.cameras)

    def sparse_depth(self, view: int) -> tuple[np.ndarray, np.ndarray]:
        """Depths of the 3D points observed by one view, at their keypoints.

        Parameters
        ----------
        view : int
            View index.

        Returns
        -------
        pixels : numpy.ndarray
            (k, 2) float64 keypoint coordinates ``(u, v)`` of the observations.
        depth : numpy.ndarray
            (k,) float64 z-depth of the observed points in that camera, in SfM units; only
            observations in front of the camera are returned.
        """
        cam = self.cameras[view]
        has = self.point_ids[view] >= 0
        pix = self.keypoints[view][has]
        x_cam = self.points[self.point_ids[view][has]] @ cam.R.T + cam.t
        front = x_cam[:, 2] > 0
        return pix[front], x_cam[front, 2]


def scene_plane_colors(scene: Scene) -> np.ndarray:
    """(G, 3) uint8 area-weighted mean colour of each global plane over its views."""
    g = scene.planes.shape[0]
    sums = np.zeros((g, 3))
    weights = np.zeros(g)
    for v, table in enumerate(scene.links):
        colors, area = scene.views[v].colors, scene.views[v].area_px
        for local, glob in table.items():
            sums[glob] += area[local - 1] * colors[local - 1]
            weights[glob] += area[local - 1]
    out = np.full((g, 3), 128, np.uint8)
    ok = weights > 0
    out[ok] = np.clip(sums[ok] / weights[ok, None], 0, 255).astype(np.uint8)
    return out


def global_label_map(labels: np.ndarray, links: dict[int, int]) -> np.ndarray:
    """(H, W) uint16 map of global plane ids + 1 (0 = non-planar) from a view's local labels."""
    lut = np.zeros(int(labels.max()) + 1, dtype=np.uint16)
    for local, glob in links.items():
        if local < len(lut):
            lut[local] = glob + 1
    return lut[labels]
