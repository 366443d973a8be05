"""The data model that flows between stages: Frame, Reconstruction, Camera, Scene, SfmResult.

Conventions used everywhere in monoplane
----------------------------------------
* Camera frame is OpenCV's: x right, y down, z forward (into the scene).
* Pixel ``(u, v)`` is column ``u``, row ``v``; pixel centres are at integer coordinates.
* A plane is ``(n, d)`` with ``n · X + d = 0`` for points ``X`` on it, ``|n| = 1`` and ``n``
  facing the camera, i.e. ``n · X < 0`` on the plane, hence ``d > 0`` for planes that do not
  pass through the camera centre.
* Depth is z-depth (distance along the optical axis), not ray length. ``0`` marks an invalid
  pixel. Plane offsets are in the depth's units.

This module imports nothing of the project but :mod:`monoplane.errors` and
:mod:`monoplane.jit` (which loads numba only when a kernel first runs), so every other module
can depend on it. Writing outputs lives in :mod:`monoplane.io.frames`
(``monoplane.save_reconstruction``) and meshes in :mod:`monoplane.geometry.mesh`
(``reconstruction_to_open3d``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.jit import kernel

DepthKind = Literal["metric", "relative"]
DEPTH_KINDS: tuple[str, ...] = ("metric", "relative")


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
class Frame:
    """One image with its geometric cues.

    Attributes
    ----------
    rgb : numpy.ndarray or None
        (H, W, 3) uint8 colour image, RGB order. ``None`` for depth-only input (range images),
        in which case colour terms are dropped downstream.
    K : numpy.ndarray
        (3, 3) float64 pinhole intrinsics in pixels.
    depth : numpy.ndarray or None
        (H, W) float32 z-depth in ``depth_units``; 0 marks invalid pixels. ``None`` until a cue
        provider fills it.
    normals : numpy.ndarray or None
        (H, W, 3) float32 unit surface normals in the camera frame (x right, y down, z forward),
        facing the camera; all-zero rows mark invalid pixels.
    depth_kind : {"metric", "relative"}
        ``"relative"`` means depth is right only up to an unknown scale.
    depth_units : str
        Human-readable unit of ``depth`` (``"m"``, ``"mm"`` or ``"relative"``).
    confidence : numpy.ndarray or None
        (H, W) float32 in [0, 1], optional per-pixel cue confidence.
    name : str
        Identifier used in messages and outputs (usually the image file stem).
    notes : list of str
        Provenance remarks, e.g. that intrinsics were assumed. Written to ``planes.json``.
    normals_from_depth : bool
        True when ``normals`` were estimated from this frame's own ``depth`` (no normal cue of
        their own): they then carry no evidence that the depth does not, and the planarity
        test (:mod:`monoplane.algorithm.planarity`) judges curvature by the depth alone.
    depth_predicted : bool
        True when a network predicted ``depth`` from the image. Even a metric network's depth
        warps by several percent, so registration treats its scale and shape as estimates, as
        it does relative depth, and takes poses from feature matches instead.
    """

    rgb: np.ndarray | None
    K: np.ndarray
    depth: np.ndarray | None = None
    normals: np.ndarray | None = None
    depth_kind: DepthKind = "metric"
    depth_units: str = "m"
    confidence: np.ndarray | None = None
    name: str = "frame"
    notes: list[str] = field(default_factory=list)
    normals_from_depth: bool = False
    depth_predicted: bool = False
    _shape: tuple[int, int] = field(init=False, repr=False, default=(0, 0))

    def __post_init__(self) -> None:
        shape: tuple[int, int] | None = None
        if self.rgb is not None:
            rgb = np.asarray(self.rgb)
            if rgb.ndim != 3 or rgb.shape[2] != 3:
                raise InvalidInput(f"{self.name}: rgb must have shape (H, W, 3), got {rgb.shape}")
            if rgb.dtype != np.uint8:
                raise InvalidInput(f"{self.name}: rgb must be uint8, got {rgb.dtype}")
            self.rgb = np.ascontiguousarray(rgb)
            shape = rgb.shape[:2]
        if self.depth is not None:
            depth = np.asarray(self.depth)
            if depth.ndim != 2:
                raise InvalidInput(f"{self.name}: depth must have shape (H, W), got {depth.shape}")
            if shape is not None and depth.shape != shape:
                raise InvalidInput(
                    f"{self.name}: depth size {depth.shape[1]}x{depth.shape[0]} differs from "
                    f"image size {shape[1]}x{shape[0]}"
                )
            depth = np.ascontiguousarray(depth, dtype=np.float32)
            nonfinite, negative, positive = _depth_counts(depth)
            if nonfinite:
                raise InvalidInput(
                    f"{self.name}: depth contains NaN or inf; mark invalid pixels with 0"
                )
            if negative:
                raise InvalidInput(f"{self.name}: depth has negative values")
            if not positive:
                raise InvalidInput(f"{self.name}: depth has no valid (positive) pixel")
            self.depth = depth
            shape = shape or depth.shape
        if self.normals is not None:
            normals = np.asarray(self.normals)
            if normals.ndim != 3 or normals.shape[2] != 3:
                raise InvalidInput(
                    f"{self.name}: normals must have shape (H, W, 3), got {normals.shape}"
                )
            if shape is not None and normals.shape[:2] != shape:
                raise InvalidInput(
                    f"{self.name}: normals size {normals.shape[1]}x{normals.shape[0]} differs "
                    f"from image size {shape[1]}x{shape[0]}"
                )
            normals = np.ascontiguousarray(normals, dtype=np.float32)
            nonfinite, bad = _normal_counts(normals)
            if nonfinite:
                raise InvalidInput(f"{self.name}: normals contain NaN or inf")
            if bad:
                raise InvalidInput(
                    f"{self.name}: normals must be unit length (or all-zero where invalid); "
                    f"{bad} pixels are not"
                )
            self.normals = normals
            shape = shape or normals.shape[:2]
        if self.confidence is not None:
            conf = np.asarray(self.confidence, dtype=np.float32)
            if shape is not None and conf.shape != shape:
                raise InvalidInput(f"{self.name}: confidence must have shape {shape}")
            self.confidence = conf
        if shape is None:
            raise InvalidInput(f"{self.name}: a frame needs at least an image or a depth map")
        self._shape = (int(shape[0]), int(shape[1]))
        self.K = _check_K(self.K, f"{self.name}: K")
        if self.depth_kind not in DEPTH_KINDS:
            raise InvalidInput(
                f"{self.name}: depth_kind must be one of {', '.join(DEPTH_KINDS)}, "
                f"got {self.depth_kind!r}"
            )

    @property
    def height(self) -> int:
        """Image height H in pixels."""
        return self._shape[0]

    @property
    def width(self) -> int:
        """Image width W in pixels."""
        return self._shape[1]

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self._shape

    @property
    def has_color(self) -> bool:
        """True when the frame has an RGB image that is not grey (all channels equal)."""
        if self.rgb is None:
            return False
        rgb = self.rgb
        return bool(np.any(rgb[..., 0] != rgb[..., 1]) or np.any(rgb[..., 1] != rgb[..., 2]))

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool mask of pixels with a valid depth (and normal, when normals exist)."""
        if self.depth is None:
            raise InvalidInput(f"{self.name}: frame has no depth yet")
        mask = self.depth > 0
        if self.normals is not None:
            mask &= np.any(self.normals != 0, axis=-1)
        return mask

    def points(self) -> np.ndarray:
        """Unproject the depth map.

        Returns
        -------
        numpy.ndarray
            (H, W, 3) float64 camera-frame points (OpenCV axes) in depth units; invalid pixels
            are at the origin.
        """
        if self.depth is None:
            raise InvalidInput(f"{self.name}: frame has no depth yet")
        return pixel_rays(self.K, *self.shape) * self.depth[..., None].astype(np.float64)

    def with_(self, **changes: object) -> Frame:
        """Return a validated copy with some fields replaced."""
        return replace(self, **changes)  # type: ignore[arg-type]


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


@dataclass
class Reconstruction:
    """Planes recovered from one frame.

    Attributes
    ----------
    frame : Frame
        The frame (with cues) the planes were recovered from.
    labels : numpy.ndarray
        (H, W) int32 label map: 0 = non-planar, ``i`` in 1..P = plane ``params[i - 1]``.
    params : numpy.ndarray
        (P, 4) float64 planes ``(nx, ny, nz, d)``, ``n · X + d = 0`` in the camera frame
        (OpenCV axes) and the frame's depth units, normal facing the camera.
    rmse : numpy.ndarray
        (P,) float64 RMS point-to-plane distance of each plane's pixels, in depth units.
    support : numpy.ndarray
        (P,) int64 number of 3D points that voted for the plane in the fit.
    config : dict
        The resolved pipeline config that produced this result (for reproducibility).
    timings : dict
        Seconds spent per stage.
    """

    frame: Frame
    labels: np.ndarray
    params: np.ndarray
    rmse: np.ndarray | None = None
    support: np.ndarray | None = None
    config: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        labels = np.asarray(self.labels)
        if labels.shape != self.frame.shape:
            raise InvalidInput(
                f"labels must have the frame's shape {self.frame.shape}, got {labels.shape}"
            )
        if not np.issubdtype(labels.dtype, np.integer):
            raise InvalidInput(f"labels must be integers, got {labels.dtype}")
        self.labels = labels.astype(np.int32)
        params = np.asarray(self.params, dtype=np.float64).reshape(-1, 4)
        if not np.all(np.isfinite(params)):
            raise InvalidInput("plane parameters contain NaN or inf")
        if params.shape[0]:
            self.params = orient_towards_camera(params)
        else:
            self.params = params
        n = self.params.shape[0]
        if self.labels.size and (self.labels.min() < 0 or self.labels.max() > n):
            raise InvalidInput(f"labels must lie in 0..{n} for {n} planes")
        self.rmse = (
            np.zeros(n) if self.rmse is None else np.asarray(self.rmse, dtype=np.float64)
        )
        self.support = (
            self.area_px.copy() if self.support is None
            else np.asarray(self.support, dtype=np.int64)
        )
        if self.rmse.shape != (n,) or self.support.shape != (n,):
            raise InvalidInput(f"rmse and support must have shape ({n},)")

    @property
    def num_planes(self) -> int:
        """Number of planes P."""
        return int(self.params.shape[0])

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
        out[mask] = ray_plane_depth(rays[mask], self.params[self.labels[mask] - 1])
        return out


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


@dataclass
class Scene:
    """Planes fused across several views.

    Attributes
    ----------
    cameras : list of Camera
        One per view, world-to-camera poses in the SfM world frame (scale of the SfM model).
    views : list of Reconstruction
        Per-view planes after scale alignment, in each camera's frame.
    planes : numpy.ndarray
        (G, 4) global planes ``n · x_world + d = 0`` (unit normals).
    links : list of dict
        ``links[v][local_id] = global_id`` for view ``v``; local ids are 1-based like labels,
        global ids 0-based rows of ``planes``.
    scales : list of float
        Scale applied to each view's monocular depth to align it with the SfM model.
    points : numpy.ndarray
        (M, 3) sparse SfM points in world coordinates.
    """

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


# Frame validation runs on every frame (and every ``with_``); one compiled pass per array
# replaces the half-dozen numpy passes of the checks (6 ms at 640x480).


@kernel
def _depth_counts(depth: np.ndarray) -> tuple[int, int, int]:
    """(non-finite, negative, positive) pixel counts of a (H, W) float32 depth map."""
    nonfinite = negative = positive = 0
    for d in depth.ravel():
        if not np.isfinite(d):
            nonfinite += 1
        elif d < 0:
            negative += 1
        elif d > 0:
            positive += 1
    return nonfinite, negative, positive


@kernel
def _normal_counts(normals: np.ndarray) -> tuple[int, int]:
    """(H, W, 3) float32 normals: pixels with a non-finite component, and non-zero normals
    whose length differs from 1 by more than 1e-2 (computed in float32, as numpy's norm is)."""
    flat = normals.reshape(-1, 3)
    nonfinite = bad = 0
    tol = np.float32(1e-2)
    for i in range(flat.shape[0]):
        x, y, z = flat[i, 0], flat[i, 1], flat[i, 2]
        if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(z)):
            nonfinite += 1
            continue
        norm = np.sqrt(x * x + y * y + z * z)
        if norm > 0 and abs(norm - np.float32(1.0)) > tol:
            bad += 1
    return nonfinite, bad
