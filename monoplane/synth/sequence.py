"""Synthetic multi-view sequences with ground truth: a walk-through and a star of views.

:func:`generate_sequence` renders the room of :func:`monoplane.synth.generate` (same seed, same
furniture, same view 0) from a camera path:

* ``"walk"``: a walk-through. Each view moves 0.25-0.5 m from the previous one (mostly
  sideways, always in the same general direction) and turns 5-12 degrees relative to it,
  keeping the region around view 0's target in sight. Far-apart views of the walk may overlap
  little or not at all, as in a real walk-through.
* ``"star"``: every view overlaps view 0: 0.3-0.8 m from it and 8-25 degrees turned relative to
  it, but views other than 0 may see each other only through view 0.

The camera draws use their own random streams, so the room, the RGB of view 0 and its cues do
not depend on the path. Poses are world-to-camera ``x_cam = R x_world + t`` (OpenCV axes).
"""

from __future__ import annotations

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.geometry.camera import look_at
from monoplane.synth.generator import (
    _STREAM_LAYOUT,
    SynthScene,
    check_arguments,
    render_scene,
)
from monoplane.synth.scene import MAX_BASELINE, WORLD_UP, Layout, _free, build_layout

#: Camera paths of :func:`generate_sequence`.
PATHS: tuple[str, ...] = ("walk", "star")
#: Random streams of the path draws (distinct from the generator's streams 0-3).
_STREAM_WALK, _STREAM_STAR = 10, 11
#: Neighbour step (m) and relative rotation (deg) of the walk.
WALK_STEP_M = (0.25, 0.5)
WALK_TURN_DEG = (5.0, 12.0)
#: Rotation (deg) of every star view relative to view 0.
STAR_TURN_DEG = (8.0, 25.0)


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle of the relative rotation ``R_b R_aᵀ`` in degrees, for (3, 3) rotations."""
    cos = (np.trace(np.asarray(R_b) @ np.asarray(R_a).T) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def _camera_ok(layout: Layout, center: np.ndarray) -> bool:
    """A camera centre keeps 0.3 m from the walls and from floor-standing objects."""
    inside_height = 0.5 < center[2] < layout.size[2] - 0.3
    return inside_height and _free(center[:2], 0.3, list(layout.footprints), layout.size,
                                   margin=0.3)


def _view0_frame(layout: Layout) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray, np.ndarray]:
    """View 0's pose and the horizontal directions camera paths step along.

    Returns
    -------
    first : (R, t)
        World-to-camera (3, 3) rotation and (3,) translation of view 0.
    fwd, side : (2,) float arrays
        Unit world-xy directions of view 0's gaze and of its left-hand side.
    """
    c0, tgt0 = layout.camera_center, layout.camera_target
    fwd = (tgt0 - c0)[:2] / np.linalg.norm((tgt0 - c0)[:2])
    return look_at(c0, tgt0, WORLD_UP), fwd, np.array([-fwd[1], fwd[0]])


def path_poses(layout: Layout, path: str, n_views: int, seed: int
               ) -> list[tuple[np.ndarray, np.ndarray]]:
    """World-to-camera poses along a camera path that starts at view 0's camera.

    Parameters
    ----------
    layout : Layout
        The room (view 0 is ``look_at(layout.camera_center, layout.camera_target, WORLD_UP)``).
    path : {"walk", "star"}
        Camera path (see the module docstring).
    n_views : int
        Number of views, >= 1.
    seed : int
        Seed of the path's own random stream.

    Returns
    -------
    list of (R, t)
        (3, 3) rotation and (3,) translation per view.
    """
    if path == "walk":
        return _walk_poses(layout, n_views, np.random.default_rng([seed, _STREAM_WALK]))
    return _star_poses(layout, n_views, np.random.default_rng([seed, _STREAM_STAR]))


def _walk_poses(layout: Layout, n_views: int, rng: np.random.Generator
                ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The ``"walk"`` path of :func:`path_poses`: each view steps on from the previous one."""
    c0, tgt0 = layout.camera_center, layout.camera_target
    first, fwd, side = _view0_frame(layout)
    for _attempt in range(100):
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        poses, centers, targets = [first], [c0], [tgt0]
        for _k in range(1, n_views):
            for _try in range(200):
                step = rng.uniform(*WALK_STEP_M)
                ang = rng.uniform(-0.5, 0.5)
                dxy = step * (np.cos(ang) * sign * side + np.sin(ang) * fwd)
                c = centers[-1] + np.array([dxy[0], dxy[1], rng.uniform(-0.05, 0.05)])
                if not _camera_ok(layout, c):
                    continue
                # The gaze drifts along with the walk but keeps view 0's region in sight.
                tgt = targets[-1] + 0.4 * np.array([dxy[0], dxy[1], 0.0]) \
                    + rng.uniform(-0.25, 0.25, size=3) * np.array([1.0, 1.0, 0.3])
                pose = look_at(c, tgt, WORLD_UP, roll_deg=rng.uniform(-3.0, 3.0))
                turn = rotation_angle_deg(poses[-1][0], pose[0])
                if WALK_TURN_DEG[0] <= turn <= WALK_TURN_DEG[1]:
                    poses.append(pose)
                    centers.append(c)
                    targets.append(tgt)
                    break
            else:
                break  # this walk ran into a wall or an object: draw another one
        if len(poses) == n_views:
            return poses
    raise RuntimeError("could not place a walk-through in this room")  # not seen in practice


def _star_poses(layout: Layout, n_views: int, rng: np.random.Generator
                ) -> list[tuple[np.ndarray, np.ndarray]]:
    """The ``"star"`` path of :func:`path_poses`: every view overlaps view 0."""
    c0, tgt0 = layout.camera_center, layout.camera_target
    first, fwd, side = _view0_frame(layout)
    poses = [first]
    for _k in range(1, n_views):
        for _try in range(500):
            base = rng.uniform(0.3, MAX_BASELINE)
            ang = rng.uniform(-0.6, 0.6) + (0.0 if rng.uniform() < 0.5 else np.pi)
            dxy = base * (np.cos(ang) * side + np.sin(ang) * fwd)
            c = c0 + np.array([dxy[0], dxy[1], rng.uniform(-0.15, 0.15)])
            if not _camera_ok(layout, c):
                continue
            tgt = tgt0 + rng.uniform(-0.6, 0.6, size=3) * np.array([1.0, 1.0, 0.4])
            pose = look_at(c, tgt, WORLD_UP, roll_deg=rng.uniform(-5.0, 5.0))
            if STAR_TURN_DEG[0] <= rotation_angle_deg(first[0], pose[0]) <= STAR_TURN_DEG[1]:
                poses.append(pose)
                break
        else:
            raise RuntimeError("could not place a star view in this room")  # not seen
    return poses


def generate_sequence(seed: int, n_views: int = 5, path: str = "walk", level: str = "mild",
                      width: int = 256, height: int = 192) -> SynthScene:
    """A synthetic room seen along a camera path, with exact plane ground truth.

    Parameters
    ----------
    seed : int
        Non-negative seed; the room is the one of ``generate(seed)``.
    n_views : int
        Number of views (>= 2).
    path : {"walk", "star"}
        Camera path (see the module docstring).
    level : {"clean", "mild", "strong"}
        Cue corruption level.
    width, height : int
        Image size in pixels.

    Returns
    -------
    SynthScene
        Views in path order; ``gt_planes_world`` lists every plane labelled in at least one
        view, ``view_to_global`` links view labels to its rows.

    Raises
    ------
    InvalidInput
        On an unknown path or level, or out-of-range arguments.
    """
    check_arguments(seed, level, width, height, n_views)
    if path not in PATHS:
        raise InvalidInput(f"unknown camera path {path!r}; choose one of {', '.join(PATHS)}")
    if n_views < 2:
        raise InvalidInput(f"a sequence needs at least 2 views, got {n_views}")
    seed = int(seed)
    layout = build_layout(np.random.default_rng([seed, _STREAM_LAYOUT]))
    poses = path_poses(layout, path, n_views, seed)
    return render_scene(layout, poses, seed, level, width, height)
