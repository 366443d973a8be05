"""Test helpers for monoplane and for third-party stage plugins.

Installed as a pytest plugin (entry point ``pytest11``), so these fixtures are available in any
test suite once monoplane is installed:

* ``synthetic_view``: a small seeded synthetic view (mild monocular-style noise) with exact
  ground truth;
* ``plugin_manager``: a fresh plugin manager with built-ins only (no entry-point autoload),
  plus whatever the test registers on it.

:func:`box_frame`, a frame of exact planes with its true labels, and
:func:`check_stage_contract`, which a plugin's own tests call on each of its stage classes::

    from monoplane.testing import check_stage_contract

    def test_contract(synthetic_view):
        check_stage_contract(MyCueProvider, synthetic_view.frame)
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

if TYPE_CHECKING:
    import pluggy

    from monoplane.geometry.cloud import PlaneCloud
    from monoplane.stages.base import Stage
    from monoplane.synth import SynthView
    from monoplane.types import Frame


#: Inside a box, camera frame (OpenCV axes), metres: back wall 4 m ahead, floor 1 m below,
#: left wall 1.5 m to the left; ``n · X + d = 0`` with n facing the camera.
BOX_PLANES = np.array([[0.0, 0.0, -1.0, 4.0], [0.0, -1.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.5]])

#: A room corner: floor 1 m below the camera and two walls meeting 3.75 m ahead.
CORNER_PLANES = np.array([[0.0, -1.0, 0.0, 1.0], [0.6, 0.0, -0.8, 3.0],
                          [-0.6, 0.0, -0.8, 3.0]])

#: A closed box room seen from inside: floor, ceiling, back wall, left and right walls.
ROOM = np.array([[0.0, -1.0, 0.0, 1.5], [0.0, 1.0, 0.0, 1.5], [0.0, 0.0, -1.0, 5.0],
                 [1.0, 0.0, 0.0, 2.0], [-1.0, 0.0, 0.0, 2.5]])
#: One flat RGB colour per :data:`ROOM` surface.
ROOM_COLORS = np.array([[150, 100, 60], [230, 230, 230], [90, 140, 200], [200, 180, 120],
                        [120, 200, 120]])


@dataclasses.dataclass
class PlaneScene:
    """An exactly known view of planes.

    Attributes
    ----------
    frame : Frame
        Depth (0 where no plane is hit), normals (zero there) and, with colours, RGB.
    labels : numpy.ndarray
        (H, W) int32 true labels: ``i`` where plane row ``i - 1`` is the nearest hit, else 0.
    planes : numpy.ndarray
        (P, 4) the planes in the camera frame.
    """

    frame: Frame
    labels: np.ndarray
    planes: np.ndarray


def plane_scene(planes: np.ndarray, K: np.ndarray, width: int, height: int, *,
                R: np.ndarray | None = None, bounds: np.ndarray | None = None,
                colors: np.ndarray | None = None, color_noise: float = 0.0, seed: int = 0,
                name: str = "frame") -> PlaneScene:
    """Ray-cast planes (optionally bounded rectangles) from a camera at the origin.

    The one exact scene builder of the test suites: each pixel sees the nearest plane its ray
    meets in front of the camera (within that plane's bounds, if any).

    Parameters
    ----------
    planes : numpy.ndarray
        (P, 4) ``(n, d)`` in the world frame, facing the camera.
    K : numpy.ndarray
        (3, 3) intrinsics.
    width, height : int
        Image size in pixels.
    R : numpy.ndarray, optional
        (3, 3) world-to-camera rotation (``x_cam = R x_world``); identity by default.
    bounds : numpy.ndarray, optional
        (P, 2, 3) lower and upper world corners of each plane's rectangle; unbounded if omitted.
    colors : numpy.ndarray, optional
        (P, 3) RGB per plane; the frame has no RGB without it.
    color_noise : float
        Standard deviation of Gaussian noise added to the colours (seeded by ``seed``).
    name : str
        Frame name.
    """
    from monoplane.types import Frame, pixel_rays, plane_to_camera, ray_plane_depth

    planes = np.asarray(planes, dtype=np.float64)
    R = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
    rays = pixel_rays(K, height, width) @ R  # world directions, camera-z component 1
    t = ray_plane_depth(rays[..., None, :], planes)  # (H, W, P)
    if bounds is not None:
        hits = rays[..., None, :] * t[..., None]
        lo, hi = np.asarray(bounds)[:, 0] - 1e-9, np.asarray(bounds)[:, 1] + 1e-9
        t[~np.all((hits >= lo) & (hits <= hi), axis=-1)] = 0.0
    t[t <= 0] = np.inf
    nearest = np.argmin(t, axis=-1)
    depth = np.min(t, axis=-1)
    hit = np.isfinite(depth)
    labels = np.where(hit, nearest + 1, 0).astype(np.int32)
    cam_planes = plane_to_camera(planes, R, np.zeros(3)) if bounds is not None or R is not None \
        else planes
    normals = np.where(hit[..., None], cam_planes[nearest, :3], 0.0)
    rgb = None
    if colors is not None:
        noise = np.random.default_rng(seed).normal(0.0, color_noise, (height, width, 3))
        rgb = np.where(hit[..., None], np.asarray(colors, np.float64)[nearest], 0.0) + noise
        rgb = np.clip(rgb, 0, 255).astype(np.uint8)
    frame = Frame(rgb=rgb, K=K, depth=np.where(hit, depth, 0.0).astype(np.float32),
                  normals=normals.astype(np.float32), name=name)
    return PlaneScene(frame=frame, labels=labels, planes=cam_planes)


def box_frame(width: int = 128, height: int = 96, planes: np.ndarray = BOX_PLANES,
              focal: float = 80.0) -> tuple[Frame, np.ndarray]:
    """A depth-only frame of exact planes (:func:`plane_scene`), principal point centred.

    Returns
    -------
    frame : Frame
        Exact depth (metres) and normals, no RGB.
    labels : numpy.ndarray
        (H, W) int32 true labels, ``i`` = row ``i - 1`` of ``planes``.
    """
    from monoplane.types import intrinsics_matrix

    K = intrinsics_matrix(focal, focal, (width - 1) / 2, (height - 1) / 2)
    scene = plane_scene(planes, K, width, height)
    return scene.frame, scene.labels


def room_cues(height: int = 192, width: int = 256, noise: float = 6.0, seed: int = 0
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact cues of the :data:`ROOM` (70° horizontal field of view), as arrays.

    Returns
    -------
    rgb, depth, normals, labels, K
        (H, W, 3) uint8 :data:`ROOM_COLORS` with Gaussian noise of std ``noise``; (H, W) float32
        depth; (H, W, 3) float32 normals; (H, W) int32 labels in 1..5 (row ``i - 1`` of
        :data:`ROOM`); (3, 3) intrinsics.
    """
    from monoplane.types import default_intrinsics

    K = default_intrinsics(width, height, 70.0)
    s = plane_scene(ROOM, K, width, height, colors=ROOM_COLORS, color_noise=noise, seed=seed)
    return s.frame.rgb, s.frame.depth, s.frame.normals, s.labels, K  # type: ignore[return-value]


def cloud_from_arrays(points: np.ndarray, normals: np.ndarray) -> PlaneCloud:
    """A PlaneCloud over given (N, 3) points and normals, taken as already normalised."""
    from monoplane.geometry.cloud import PlaneCloud

    n = len(points)
    pixels = np.arange(n, dtype=np.int64)
    return PlaneCloud(points=points, normals=normals, colors=None, pixels=pixels,
                      center=np.zeros(3), scale=1.0, shape=(1, n), all_points=points,
                      all_pixels=pixels)


@pytest.fixture
def synthetic_view() -> SynthView:
    """A 128x96 synthetic room, seed 0, level ``mild``."""
    from monoplane.synth import generate

    return generate(0, level="mild", width=128, height=96).views[0]


@pytest.fixture
def plugin_manager() -> pluggy.PluginManager:
    """A fresh plugin manager with the built-in stages only."""
    from monoplane.plugin_manager import get_plugin_manager

    return get_plugin_manager(autoload=False)


def _check_config(cls: type[Stage]) -> Any:
    from monoplane.stages.base import STAGE_KINDS, Stage  # noqa: F811 (runtime import)

    assert isinstance(cls, type) and issubclass(cls, Stage), f"{cls} is not a Stage"
    assert cls.kind in STAGE_KINDS, f"{cls.__name__}.kind {cls.kind!r} not in {STAGE_KINDS}"
    assert cls.name and cls.name == cls.name.strip(), f"{cls.__name__} needs a name"
    assert dataclasses.is_dataclass(cls.Config), f"{cls.__name__}.Config must be a dataclass"
    for f in dataclasses.fields(cls.Config):
        assert f.metadata.get("doc"), f"{cls.__name__}.Config.{f.name} has no doc (use param())"
    return cls(cls.Config())


def check_stage_contract(cls: type[Stage], frame: Frame | None = None, seed: int = 0) -> None:
    """Assert that a stage class honours its kind's contract.

    Static checks (all kinds): subclass of the right base, a name, a dataclass ``Config`` whose
    every field has a doc, and instantiation with defaults. With ``frame`` (a frame that has
    depth and normals), the stage is also run once and its output checked: shapes, dtypes and
    value ranges stated in :mod:`monoplane.stages.base`.
    """
    from monoplane.geometry.cloud import PlaneCloud
    from monoplane.geometry.graph import NeighbourGraph
    from monoplane.stages.base import Labeling, RansacParams
    from monoplane.types import Frame, Reconstruction

    stage = _check_config(cls)
    if frame is None:
        return
    rng = np.random.default_rng(seed)
    params = RansacParams()
    if cls.kind == "cues":
        # Every provider must at least complete given depth with normals (RGB-D input).
        out = stage.provide(frame.with_(normals=None))
        assert isinstance(out, Frame) and out.depth is not None and out.normals is not None
        assert out.shape == frame.shape
        return
    if cls.kind == "refiner":
        labels = np.zeros(frame.shape, dtype=np.int32)
        labels[: frame.height // 2] = 1
        pts = frame.points()[labels == 1]
        from monoplane.geometry.planes import fit_plane

        rec = Reconstruction(frame=frame, labels=labels, params=fit_plane(pts)[0][None])
        out = stage.refine(rec)
        assert isinstance(out, Reconstruction) and out.labels.shape == frame.shape
        return
    cloud = PlaneCloud.from_frame(frame, max_points=5000, rng=rng)
    pool = np.arange(len(cloud.points))
    if cls.kind == "sampler":
        samples = stage.sample(cloud, pool, 50, rng, params)
        assert samples.ndim == 2 and samples.shape[1] == 3 and len(samples) <= 50
        assert np.isin(samples, pool).all()
    elif cls.kind in ("scorer", "labeler"):
        idx = rng.choice(pool, size=3, replace=False)
        from monoplane.geometry.planes import planes_from_triplets

        planes, _ = planes_from_triplets(cloud.points[idx][None])
        normal = cloud.normals[idx].mean(0)
        normal /= np.linalg.norm(normal)
        if cls.kind == "scorer":
            costs = stage.score(cloud, pool, planes, normal[None], params)
            assert costs.shape == (1,) and np.isfinite(costs).all()
        else:
            graph = NeighbourGraph.build(cloud.points, k=8)
            lab = stage.label(cloud, graph, pool, planes[0], normal, params)
            assert isinstance(lab, Labeling) and lab.inliers.shape == pool.shape
            assert lab.inliers.dtype == bool and np.isfinite(lab.energy)
