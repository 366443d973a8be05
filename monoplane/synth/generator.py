"""Seeded synthetic indoor scenes with exact plane ground truth: :func:`generate`.

Randomness is split into independent streams derived from the seed: the layout and view 0's
camera, the extra cameras, the sensor noise of each view and the cue corruption of each
(level, view). Hence

* the same ``(seed, level, width, height, n_views)`` gives byte-identical arrays;
* the room, the cameras and the RGB images do not depend on ``level``;
* the room does not depend on ``n_views`` or on the image size (view 0 of a two-view scene is
  the single-view scene of the same seed, at any resolution).

Ground-truth planes: every planar face (room, boxes, panels, table tops) covering at least
:data:`MIN_PLANE_FRACTION` of a view's pixels gets a label in that view, one id per face
(coplanar faces of different objects are different instances, as in ScanNet-style annotations).
Curved objects, and planar faces below the area threshold, are label 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from monoplane.datamodel import Frame, intrinsics_matrix
from monoplane.errors import InvalidInput
from monoplane.geometry.camera import look_at
from monoplane.synth.corrupt import corrupt
from monoplane.synth.render import make_raycaster, render_view, world_planes
from monoplane.synth.scene import WORLD_UP, Layout, build_layout, extra_camera

LEVELS: tuple[str, ...] = ("clean", "mild", "strong")
#: A planar face needs at least this fraction of the image's pixels to get a plane id.
MIN_PLANE_FRACTION = 0.002

_STREAM_LAYOUT, _STREAM_CAMERAS, _STREAM_SENSOR, _STREAM_CUES = 0, 1, 2, 3


@dataclass
class SynthView:
    """One rendered view with corrupted cues and exact ground truth.

    Attributes
    ----------
    frame : Frame
        What an algorithm sees: ``rgb`` (H, W, 3) uint8; corrupted ``depth`` (H, W) float32
        (``depth_kind`` "relative" and unknown scale for "mild"/"strong", "metric" metres for
        "clean"); corrupted ``normals`` (H, W, 3) float32 unit, camera frame, facing the camera;
        ``K`` (3, 3).
    gt_depth : numpy.ndarray
        (H, W) float32 exact z-depth in metres.
    gt_normals : numpy.ndarray
        (H, W, 3) float32 exact unit normals, camera frame (x right, y down, z forward), facing
        the camera.
    gt_labels : numpy.ndarray
        (H, W) int32: 0 = non-planar (curved objects, planar faces too small to count), 1..P =
        plane id.
    gt_params : numpy.ndarray
        (P, 4) float64 camera-frame planes ``n · X + d = 0`` in metres, ``|n| = 1``, ``d > 0``
        (normal facing the camera); row ``i - 1`` is label ``i``.
    gt_faces : numpy.ndarray
        (H, W) int32 exact surface truth: every visible planar face has an id, however small
        (``gt_faces == gt_labels`` wherever ``gt_labels > 0``; faces below the area threshold
        get the ids after P), 0 on curved surfaces.
    gt_curved : numpy.ndarray
        (H, W) bool: the pixel lies on a curved surface (sphere, dome, cylinder, torus).
    R, t : numpy.ndarray
        (3, 3) and (3,) world-to-camera pose, ``x_cam = R x_world + t``.
    scale : float
        Global factor the corruption applied to the depth (1 for "clean"); for diagnostics and
        evaluation only, an algorithm must not use it.
    """

    frame: Frame
    gt_depth: np.ndarray
    gt_normals: np.ndarray
    gt_labels: np.ndarray
    gt_params: np.ndarray
    gt_faces: np.ndarray
    gt_curved: np.ndarray
    R: np.ndarray
    t: np.ndarray
    scale: float = 1.0


@dataclass
class SynthScene:
    """A synthetic room seen from one or more views.

    Attributes
    ----------
    views : list of SynthView
    seed : int
    level : str
        Corruption level, one of :data:`LEVELS`.
    gt_planes_world : numpy.ndarray
        (G, 4) float64 world planes ``n · x + d = 0`` (metres, unit ``n`` towards the side the
        surface is seen from) of every plane labelled in at least one view.
    view_to_global : list of dict
        ``view_to_global[v][local_label] = global_index`` (row of ``gt_planes_world``).
    """

    views: list[SynthView]
    seed: int
    level: str
    gt_planes_world: np.ndarray
    view_to_global: list[dict[int, int]]


def generate(seed: int, level: str = "mild", width: int = 256, height: int = 192,
             n_views: int = 1, objects: int | None = None) -> SynthScene:
    """Generate a synthetic indoor scene with exact plane ground truth.

    Parameters
    ----------
    seed : int
        Non-negative seed; the output is a pure function of all arguments.
    level : {"clean", "mild", "strong"}
        Cue corruption level (see :mod:`monoplane.synth.corrupt`).
    width, height : int
        Image size in pixels (at least 16 each).
    n_views : int
        Number of views. Views after the first move 0.3-0.8 m from view 0 and turn 10-30
        degrees relative to it, looking at the same part of the room.
    objects : int, optional
        ``None``: the usual furnishing (about 7-16 objects). A number: exactly that many
        objects, all in view 0's field of view, in the same room seen from the same camera
        (see :func:`monoplane.synth.scene.build_layout`); a scene-complexity knob.

    Returns
    -------
    SynthScene

    Raises
    ------
    InvalidInput
        On an unknown level or out-of-range argument.
    """
    check_arguments(seed, level, width, height, n_views)
    if objects is not None and (int(objects) != objects or objects < 0):
        raise InvalidInput(f"objects must be a non-negative integer, got {objects!r}")
    seed = int(seed)

    layout = build_layout(np.random.default_rng([seed, _STREAM_LAYOUT]),
                          None if objects is None else int(objects))
    poses = [look_at(layout.camera_center, layout.camera_target, WORLD_UP)]
    cam_rng = np.random.default_rng([seed, _STREAM_CAMERAS])
    poses += [extra_camera(layout, cam_rng) for _ in range(n_views - 1)]
    return render_scene(layout, poses, seed, level, width, height)


def check_arguments(seed: int, level: str, width: int, height: int, n_views: int) -> None:
    """Raise :class:`InvalidInput` on an unknown level or out-of-range argument."""
    if level not in LEVELS:
        raise InvalidInput(f"unknown synth level {level!r}; choose one of {', '.join(LEVELS)}")
    if int(seed) != seed or seed < 0:
        raise InvalidInput(f"seed must be a non-negative integer, got {seed!r}")
    if width < 16 or height < 16:
        raise InvalidInput(f"image size must be at least 16x16, got {width}x{height}")
    if n_views < 1:
        raise InvalidInput(f"n_views must be at least 1, got {n_views}")


def render_scene(layout: Layout, poses: list[tuple[np.ndarray, np.ndarray]], seed: int,
                 level: str, width: int, height: int) -> SynthScene:
    """Render ``layout`` from the given world-to-camera ``poses`` with corrupted cues.

    Parameters
    ----------
    layout : Layout
        The furnished room.
    poses : list of (R, t)
        (3, 3) and (3,) world-to-camera pose of each view.
    seed : int
        Seed of the sensor-noise and cue-corruption streams.
    level : str
        Corruption level.
    width, height : int
        Image size in pixels.

    Returns
    -------
    SynthScene
    """
    f = 0.5 * width / math.tan(math.radians(layout.hfov_deg) / 2)
    K = intrinsics_matrix(f, f, (width - 1) / 2.0, (height - 1) / 2.0)

    raycaster = make_raycaster(layout)
    renders = [
        render_view(raycaster, layout, K, R, t, width, height,
                    np.random.default_rng([seed, _STREAM_SENSOR, v]))
        for v, (R, t) in enumerate(poses)
    ]

    planes_w = world_planes(layout)
    planar = np.isfinite(planes_w[:, 0])
    min_area = math.ceil(MIN_PLANE_FRACTION * width * height)
    kept = []
    for r in renders:
        area = np.bincount(r.surface.ravel(), minlength=len(layout.surfaces))
        kept.append(np.flatnonzero(planar & (area >= min_area)))
    global_sids = np.unique(np.concatenate(kept))
    global_index = {int(s): g for g, s in enumerate(global_sids)}

    views: list[SynthView] = []
    links: list[dict[int, int]] = []
    level_idx = LEVELS.index(level)
    for v, (r, (R, t), sids) in enumerate(zip(renders, poses, kept, strict=True)):
        lut = np.zeros(len(layout.surfaces), dtype=np.int32)
        lut[sids] = np.arange(1, len(sids) + 1, dtype=np.int32)
        labels = lut[r.surface]
        # Faces below the area threshold: ids after the labelled ones, in surface order.
        small = np.setdiff1d(np.flatnonzero(planar & (np.bincount(
            r.surface.ravel(), minlength=len(layout.surfaces)) > 0)), sids)
        lut[small] = np.arange(len(sids) + 1, len(sids) + 1 + len(small), dtype=np.int32)
        faces = lut[r.surface]
        params = r.planes_cam[sids].copy()
        cues = corrupt(r.depth, r.normals, K, level,
                       np.random.default_rng([seed, _STREAM_CUES, level_idx, v]))
        frame = Frame(
            rgb=r.rgb, K=K, depth=cues.depth, normals=cues.normals,
            depth_kind="metric" if level == "clean" else "relative",
            depth_units="m" if level == "clean" else "relative",
            name=f"synth_{seed:04d}_v{v}",
            notes=[f"synthetic scene seed={seed} level={level} view={v}"],
        )
        views.append(SynthView(frame=frame, gt_depth=r.depth, gt_normals=r.normals,
                               gt_labels=labels, gt_params=params, gt_faces=faces,
                               gt_curved=~planar[r.surface], R=R.copy(), t=t.copy(),
                               scale=cues.scale))
        links.append({i + 1: global_index[int(s)] for i, s in enumerate(sids)})

    return SynthScene(views=views, seed=seed, level=level,
                      gt_planes_world=planes_w[global_sids].copy(), view_to_global=links)
