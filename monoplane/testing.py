"""Test helpers for monoplane and for third-party stage plugins.

Installed as a pytest plugin (entry point ``pytest11``), so these fixtures are available in any
test suite once monoplane is installed:

* ``synthetic_view``: a small seeded synthetic view (mild monocular-style noise) with exact
  ground truth;
* ``plugin_manager``: a fresh plugin manager with built-ins only (no entry-point autoload),
  plus whatever the test registers on it.

:func:`plane_scene` (its shorthands :func:`box_frame`, :func:`room_cues`) and
:func:`two_view_room` build exactly known views of planes; :func:`stage_plugin` registers
stage classes in a test; :func:`check_stage_contract`, which a plugin's own tests call on each
of its stage classes, :func:`check_work_ahead` for a refiner's background work, and
:func:`check_baseline_contract` for ``monoplane eval`` baselines::

    from monoplane.testing import check_stage_contract

    def test_contract(synthetic_view):
        check_stage_contract(MyCueProvider, synthetic_view.frame)
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

if TYPE_CHECKING:
    import pluggy

    from monoplane.contracts import Stage
    from monoplane.datamodel import Frame, Reconstruction, SfmResult
    from monoplane.geometry.cloud import PlaneCloud
    from monoplane.synth import SynthView


#: Helpers defined elsewhere that a plugin's tests need, so that they import only this module
#: and :mod:`monoplane.plugin`: the segmentation metrics (to assert accuracy) and tiny ONNX
#: stand-in networks (to run a cue provider end to end). Loaded on first use, because every
#: pytest session that has monoplane installed loads this module.
_ELSEWHERE: dict[str, str] = {
    "segmentation_scores": "monoplane.evaluation.segmentation",
    "tiny_depth_model": "monoplane.cues.tiny_models",
}


def __getattr__(name: str) -> Any:
    module = _ELSEWHERE.get(name)
    if module is None:
        raise AttributeError(f"module 'monoplane.testing' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)


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
                R: np.ndarray | None = None, t: np.ndarray | None = None,
                bounds: np.ndarray | None = None, colors: np.ndarray | None = None,
                color_noise: float = 0.0, texture: bool = False, seed: int = 0,
                name: str = "frame") -> PlaneScene:
    """Ray-cast planes (optionally bounded rectangles) seen by a pinhole camera.

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
    R, t : numpy.ndarray, optional
        (3, 3) rotation and (3,) translation of the world-to-camera pose
        ``x_cam = R x_world + t``; identity and zero by default.
    bounds : numpy.ndarray, optional
        (P, 2, 3) lower and upper world corners of each plane's rectangle; unbounded if omitted.
    colors : numpy.ndarray, optional
        (P, 3) RGB per plane; the frame has no RGB without it.
    color_noise : float
        Standard deviation of Gaussian noise added to the colours (seeded by ``seed``).
    texture : bool
        Modulate the colours by a blurred random texture fixed to each plane in the world (2 cm
        texels, seeded by ``seed``), so that views from different poses share features.
    name : str
        Frame name.
    """
    from monoplane.datamodel import Frame, pixel_rays, plane_to_camera, ray_plane_depth

    planes = np.asarray(planes, dtype=np.float64)
    R = np.eye(3) if R is None else np.asarray(R, dtype=np.float64)
    t = np.zeros(3) if t is None else np.asarray(t, dtype=np.float64)
    cam_planes = plane_to_camera(planes, R, t)
    rays = pixel_rays(K, height, width)
    z = ray_plane_depth(rays[..., None, :], cam_planes)  # (H, W, P)
    if bounds is not None:
        world = (rays[..., None, :] * z[..., None] - t) @ R
        lo, hi = np.asarray(bounds)[:, 0] - 1e-9, np.asarray(bounds)[:, 1] + 1e-9
        z[~np.all((world >= lo) & (world <= hi), axis=-1)] = 0.0
    z[z <= 0] = np.inf
    nearest = np.argmin(z, axis=-1)
    depth = np.min(z, axis=-1)
    hit = np.isfinite(depth)
    labels = np.where(hit, nearest + 1, 0).astype(np.int32)
    normals = np.where(hit[..., None], cam_planes[nearest, :3], 0.0)
    rgb = None
    if colors is not None:
        rng = np.random.default_rng(seed)
        base = np.where(hit[..., None], np.asarray(colors, np.float64)[nearest], 0.0)
        if texture:
            base *= _world_texture(planes, nearest, (rays * np.where(hit, depth, 0.0)[..., None]
                                                     - t) @ R, rng)[..., None]
        rgb = np.clip(base + rng.normal(0.0, color_noise, (height, width, 3)), 0, 255)
        rgb = rgb.astype(np.uint8)
    frame = Frame(rgb=rgb, K=K, depth=np.where(hit, depth, 0.0).astype(np.float32),
                  normals=normals.astype(np.float32), name=name)
    return PlaneScene(frame=frame, labels=labels, planes=cam_planes)


def _world_texture(planes: np.ndarray, nearest: np.ndarray, world: np.ndarray,
                   rng: np.random.Generator, texel: float = 0.02, size: int = 128) -> np.ndarray:
    """(H, W) brightness factors in [0.4, 1.6] from a texture fixed on each world plane."""
    import cv2

    from monoplane.geometry.polygons import plane_basis

    out = np.ones(nearest.shape)
    for p, plane in enumerate(planes):
        tex = cv2.GaussianBlur(rng.uniform(0.0, 1.0, (size, size)), (0, 0), 1.5)
        tex = 0.4 + 1.2 * (tex - tex.min()) / max(float(np.ptp(tex)), 1e-12)
        e1, e2 = plane_basis(plane[:3] / np.linalg.norm(plane[:3]))
        mine = nearest == p
        a = np.floor(world[mine] @ e1 / texel).astype(np.int64) % size
        b = np.floor(world[mine] @ e2 / texel).astype(np.int64) % size
        out[mine] = tex[b, a]
    return out


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
    from monoplane.datamodel import intrinsics_matrix

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
    from monoplane.datamodel import default_intrinsics

    K = default_intrinsics(width, height, 70.0)
    s = plane_scene(ROOM, K, width, height, colors=ROOM_COLORS, color_noise=noise, seed=seed)
    return s.frame.rgb, s.frame.depth, s.frame.normals, s.labels, K  # type: ignore[return-value]


@dataclasses.dataclass
class PosedView:
    """One view of :func:`two_view_room`: a cue-filled frame, its true pose and ground truth.

    Attributes
    ----------
    frame : Frame
        Textured RGB, exact depth and normals.
    R, t : numpy.ndarray
        World-to-camera pose ``x_cam = R x_world + t`` (OpenCV axes, metres).
    gt_depth, gt_labels : numpy.ndarray
        (H, W) exact depth and labels (row ``i - 1`` of ``planes``).
    planes : numpy.ndarray
        (P, 4) the room's planes in this camera's frame.
    """

    frame: Frame
    R: np.ndarray
    t: np.ndarray
    gt_depth: np.ndarray
    gt_labels: np.ndarray
    planes: np.ndarray


@dataclasses.dataclass
class TwoViewRoom:
    """Two posed views of the textured :data:`ROOM` (world frame = view 0's camera frame)."""

    views: list[PosedView]

    def reconstructions(self) -> list[Reconstruction]:
        """Each view's exact planes and labels, as a refiner would hand them to a fuser."""
        from monoplane.datamodel import Reconstruction

        return [Reconstruction(frame=v.frame, labels=v.gt_labels, planes=v.planes)
                for v in self.views]

    def sfm(self, num_points: int = 300) -> SfmResult:
        """An exact SfM result: true cameras, points on view 0 seen by view 1, their matches."""
        from monoplane.evaluation.twoview import ground_truth_sfm

        return ground_truth_sfm(self, num_points=num_points)  # type: ignore[arg-type]


def two_view_room(width: int = 160, height: int = 120, seed: int = 0) -> TwoViewRoom:
    """The :data:`ROOM` from two poses 0.4 m apart, turned 8° towards each other.

    Colours are :data:`ROOM_COLORS` times a world-fixed texture, so a feature matcher finds
    correspondences; everything else is exact.
    """
    from monoplane.datamodel import default_intrinsics

    K = default_intrinsics(width, height, 70.0)
    yaw = np.deg2rad(-8.0)
    R1 = np.array([[np.cos(yaw), 0.0, -np.sin(yaw)], [0.0, 1.0, 0.0],
                   [np.sin(yaw), 0.0, np.cos(yaw)]])
    poses = [(np.eye(3), np.zeros(3)), (R1, -R1 @ np.array([0.4, 0.0, 0.0]))]
    views = []
    for i, (R, t) in enumerate(poses):
        s = plane_scene(ROOM, K, width, height, R=R, t=t, colors=ROOM_COLORS, color_noise=2.0,
                        texture=True, seed=seed, name=f"view{i}")
        # The texture must be the same in both views: it is drawn from ``seed`` alone.
        views.append(PosedView(frame=s.frame, R=R, t=t, gt_depth=s.frame.depth,  # type: ignore[arg-type]
                               gt_labels=s.labels, planes=s.planes))
    return TwoViewRoom(views=views)


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
    from monoplane.host.registry import get_plugin_manager

    return get_plugin_manager(autoload=False)


def stage_plugin(**hooks: list[type]) -> object:
    """A plugin whose registration hooks return the given classes, for
    ``get_plugin_manager(extra_plugins=(...,))``::

        pm = get_plugin_manager(autoload=False,
                                extra_plugins=(stage_plugin(monoplane_register_samplers=[S]),))

    Parameters
    ----------
    **hooks : list of type
        Registration hook name (``monoplane_register_samplers``, ...) and the classes it
        returns; any hook may be named, so a test can register a class under the wrong kind.

    Returns
    -------
    object
        The plugin: one instance of a class with one hook implementation per keyword.
    """
    from monoplane.hookspecs import hookimpl

    def implementation(classes: list[type]) -> Callable[[object], list[type]]:
        # One function per hook: each returns its own list (a closure over a loop variable
        # would give every hook the last one).
        @hookimpl
        def register(self: object) -> list[type]:
            return list(classes)

        return register

    impls = {hook: implementation(classes) for hook, classes in hooks.items()}
    return type("StagePlugin", (), impls)()


def _check_config(cls: type[Stage]) -> Any:
    from monoplane.contracts import KINDS, Stage  # noqa: F811 (runtime import)

    assert isinstance(cls, type) and issubclass(cls, Stage), f"{cls} is not a Stage"
    assert cls.kind in KINDS, f"{cls.__name__}.kind {cls.kind!r} not in {tuple(KINDS)}"
    assert issubclass(cls, KINDS[cls.kind].base), \
        f"{cls.__name__} must subclass {KINDS[cls.kind].base.__name__}"
    assert cls.name and cls.name == cls.name.strip(), f"{cls.__name__} needs a name"
    assert dataclasses.is_dataclass(cls.Config), f"{cls.__name__}.Config must be a dataclass"
    for f in dataclasses.fields(cls.Config):
        assert f.metadata.get("doc"), f"{cls.__name__}.Config.{f.name} has no doc (use param())"
    return cls(cls.Config())


def check_stage_contract(cls: type[Stage], frame: Frame | None = None, seed: int = 0,
                         run: bool | None = None) -> None:
    """Assert that a stage class honours its kind's contract.

    Static checks (all kinds): subclass of the right base, a name, a dataclass ``Config`` whose
    every field has a doc, and instantiation with defaults. With ``run`` (default: whether a
    ``frame`` is given) the stage is also run once and its output checked against the shapes,
    dtypes and value ranges stated in :mod:`monoplane.contracts`:

    * cues, sampler, scorer, labeler, refiner: on ``frame`` (a frame with depth and normals);
    * matcher: on the two textured views of :func:`two_view_room` (``frame`` is not used);
    * fuser: on the exact planes of those two views with their exact SfM result, and every
      link it makes must join planes that agree in the world frame.
    """
    from monoplane.contracts import Labeling, RansacParams
    from monoplane.datamodel import Frame, Reconstruction
    from monoplane.geometry.cloud import PlaneCloud
    from monoplane.geometry.graph import NeighbourGraph

    stage = _check_config(cls)
    if not (frame is not None if run is None else run):
        return
    if cls.kind in ("matcher", "fuser"):
        _check_multiview_stage(stage, _two_view_room_cached())
        return
    if frame is None:
        raise ValueError(f"check_stage_contract: running a {cls.kind} needs a frame")
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

        rec = Reconstruction(frame=frame, labels=labels, planes=fit_plane(pts)[0][None])
        out = stage.refine(rec, params)
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


@functools.lru_cache(maxsize=1)
def _two_view_room_cached() -> TwoViewRoom:
    return two_view_room()


def _check_multiview_stage(stage: Stage, room: TwoViewRoom) -> None:
    from monoplane.datamodel import Scene, SfmResult, plane_to_world

    frames = [v.frame for v in room.views]
    if stage.kind == "matcher":
        sfm = stage.match(frames)  # type: ignore[attr-defined]
        assert isinstance(sfm, SfmResult), f"{stage.name}.match must return an SfmResult"
        assert len(sfm.cameras) == len(frames), "one camera per input frame, in input order"
        for cam, f in zip(sfm.cameras, frames, strict=True):
            assert (cam.width, cam.height) == (f.width, f.height), "camera size != frame size"
            np.testing.assert_allclose(cam.R @ cam.R.T, np.eye(3), atol=1e-6)
            assert np.isfinite(cam.t).all() and np.isfinite(cam.K).all()
        for kp, f in zip(sfm.keypoints, frames, strict=True):
            assert np.all((kp >= -0.5) & (kp <= [f.width - 0.5, f.height - 0.5])), \
                "keypoints must be pixel coordinates inside their image"
        for (i, j), m in sfm.matches.items():
            assert 0 <= i < j < len(frames), f"match key {(i, j)} must have i < j"
            assert m.ndim == 2 and m.shape[1] == 2 and m.dtype == np.int64
            assert np.all((m >= 0) & (m < [len(sfm.keypoints[i]), len(sfm.keypoints[j])]))
        return
    views = room.reconstructions()
    scene = stage.fuse(views, room.sfm())  # type: ignore[attr-defined]
    assert isinstance(scene, Scene), f"{stage.name}.fuse must return a Scene"
    assert len(scene.views) == len(views) and len(scene.cameras) == len(views)
    assert np.isfinite(scene.planes).all()
    np.testing.assert_allclose(np.linalg.norm(scene.planes[:, :3], axis=1), 1.0, atol=1e-6)
    linked = 0
    for v, table in enumerate(scene.links):
        world = plane_to_world(views[v].planes, room.views[v].R, room.views[v].t)
        for local, glob in table.items():
            cos = abs(float(world[local - 1, :3] @ scene.planes[glob, :3]))
            assert cos > np.cos(np.deg2rad(10.0)), \
                f"view {v} plane {local} is linked to a global plane {glob} it does not match"
            linked += 1
    assert linked >= len(views), "exact views of one room must link some planes"


def check_work_ahead(make_refiner: Callable[[], Any], frame: Frame, other: Frame,
                     rec: Reconstruction, params: Any, monkeypatch: pytest.MonkeyPatch) -> None:
    """Assert that a refiner's background work (:class:`monoplane.contracts.WorkAhead`) changes
    nothing.

    With two threads, the work ``prepare(frame)`` starts is taken by ``refine`` and gives the
    labels and planes of a refiner that did it all inside ``refine``; work prepared for
    ``other`` is neither used nor kept; with one thread ``prepare`` starts nothing.

    Parameters
    ----------
    make_refiner : callable
        Returns a fresh refiner (a ``WorkAhead`` stage with ``prepare`` and ``refine``).
    frame, other : Frame
        The frame ``rec`` was made from, and another one.
    rec : Reconstruction
        A reconstruction of ``frame`` to refine.
    params : RansacParams
        Passed to ``refine``.
    monkeypatch : pytest.MonkeyPatch
        Sets ``OMP_NUM_THREADS`` (2, then 1).
    """
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    expected = make_refiner().refine(rec, params)
    refiner = make_refiner()
    refiner.prepare(frame)
    assert refiner._pending is not None and refiner._pending[0] is frame
    out = refiner.refine(rec, params)
    assert refiner._pending is None  # picked up
    np.testing.assert_array_equal(out.labels, expected.labels)
    np.testing.assert_array_equal(out.planes, expected.planes)
    # Work prepared for another frame is not used (and not kept).
    refiner.prepare(other)
    np.testing.assert_array_equal(refiner.refine(rec, params).labels, expected.labels)
    assert refiner._pending is None
    # With one thread the refiner does all of its work itself, inside refine.
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    refiner.prepare(frame)
    assert refiner._pending is None


def check_baseline_contract(baseline: Callable[..., Reconstruction], seed: int = 0) -> None:
    """Assert that a ``monoplane eval`` baseline honours the baseline contract.

    A baseline is ``baseline(frame, *, seed=0, **options) -> Reconstruction``. It is run on the
    exact :func:`box_frame` (depth and normals, no RGB): the result must cover the frame, label
    with ``0..P``, give ``P`` finite planes with unit normals, and find the back wall, which
    covers most of the image. An unknown keyword option must raise a one-line
    :class:`~monoplane.errors.ConfigError` naming it; a ``config_class`` attribute, when
    present, must be a dataclass whose defaults build.
    """
    from monoplane.datamodel import Reconstruction
    from monoplane.errors import ConfigError
    from monoplane.evaluation.baselines import baseline_config

    frame, _ = box_frame(64, 48)
    rec = baseline(frame, seed=seed)
    name = getattr(baseline, "__name__", repr(baseline))
    assert isinstance(rec, Reconstruction), f"{name} must return a Reconstruction"
    assert rec.labels.shape == frame.shape and rec.frame.shape == frame.shape
    assert rec.labels.min() >= 0 and rec.labels.max() <= rec.num_planes
    assert np.isfinite(rec.planes).all()
    np.testing.assert_allclose(np.linalg.norm(rec.planes[:, :3], axis=1), 1.0, atol=1e-6)
    assert rec.num_planes and np.abs(rec.planes - BOX_PLANES[0]).max(axis=1).min() < 0.02, \
        f"{name} misses the back wall of an exact box"
    try:
        baseline(frame, seed=seed, no_such_option=1)
    except ConfigError as exc:
        message = str(exc)
        assert "no_such_option" in message and "\n" not in message, \
            f"{name}: the error on an unknown option must be one line naming it: {message!r}"
    except TypeError as exc:
        raise AssertionError(f"{name} must take keyword options (baseline(frame, *, seed=0, "
                             f"**options)) and reject unknown ones with a ConfigError: {exc}"
                             ) from None
    else:
        raise AssertionError(f"{name} accepts an unknown option without a ConfigError")
    config_class = getattr(baseline, "config_class", None)
    if config_class is not None:
        assert dataclasses.is_dataclass(config_class), f"{name}.config_class must be a dataclass"
        baseline_config(config_class, {}, name)
