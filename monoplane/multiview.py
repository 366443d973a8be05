"""Sparse-view planar reconstruction (paper §III-C): SfM, scale alignment, per-view planes, fusion.

Python API::

    from monoplane.pipeline import Pipeline
    from monoplane.multiview import reconstruct_multiview, save_scene
    pipe = Pipeline.from_preset("monoplane")
    result = reconstruct_multiview([frame_a, frame_b], pipe, progress=True)
    save_scene(result, "out/")

Steps:

1. the configured matcher (``[matcher]``) gives cameras, sparse points and
   keypoint matches;
2. the cue provider fills each view's depth and normals (at the view's native resolution, with
   the SfM intrinsics) and the single-view pipeline segments each view. Both ignore the
   depth's scale, so when the matcher keeps every ``K`` as given they run while SfM does
   (in the view pool's workers), on the unscaled depth;
3. each view's depth is scaled onto the SfM points (:func:`~monoplane.geometry.alignment.
   align_scale`), and its planes with it (:func:`rescale_reconstruction`); when every view's
   depth is metric the SfM world is then rescaled to the views' median metric scale, so
   outputs keep the depth's units;
4. the configured fuser (``[fuser]``) matches and fuses planes into a
   :class:`~monoplane.datamodel.Scene`, and the adjuster (``[adjuster]``) refines it.

Frames: cameras are world-to-camera ``x_cam = R x_world + t`` with OpenCV axes (x right, y down,
z forward).
"""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np

from monoplane.datamodel import (
    Camera,
    Frame,
    Reconstruction,
    Scene,
    SfmResult,
    plane_to_camera,
    ray_plane_depth,
)
from monoplane.errors import InvalidInput, StageError
from monoplane.geometry.alignment import ScaleAlignment, align_scale
from monoplane.geometry.polygons import PlaneMesh, points_plane_mesh
from monoplane.stages.base import Fuser, Matcher

if TYPE_CHECKING:
    from monoplane.pipeline import Pipeline


@dataclass
class MultiviewResult:
    """Everything the sparse-view driver produced.

    Attributes
    ----------
    scene : Scene
        Cameras, per-view reconstructions and fused global planes (world frame), over the
        registered views only (in input order).
    sfm : SfmResult
        The matcher's output restricted to the registered views, in the scene's units.
    alignments : list of ScaleAlignment
        Per registered view, the scale alignment of its monocular depth (for a view placed by
        the fallback pose, the scale comes from the fallback's triangulated points).
    plane_matches : list
        Plane correspondences the fuser kept (objects with ``view_i``, ``plane_i``,
        ``view_j``, ``plane_j``, ``criterion``), view indices into ``scene.views``.
    units : str
        Unit of the scene's coordinates: the depths' unit when all views had metric depth,
        otherwise ``"sfm"`` (the SfM model's arbitrary scale).
    timings : dict
        Wall seconds per step: ``matcher``, ``single_view`` (waiting for the per-view cues,
        RANSAC and refiner after SfM: the part SfM did not hide), ``alignment``, ``fuser``,
        ``adjuster``, ``total``; and ``per_view``, the mean seconds one view's stages took
        (where they ran).
    config : dict
        The resolved pipeline config.
    frame_indices : list of int
        Input index of each scene view.
    registration : list of dict
        Per scene view, how its pose was found: ``method`` ``"sfm"``, ``"fallback"`` (with
        ``reference`` and ``inliers``) or ``"origin"`` (SfM built no model; this view's camera
        is the world frame and the others were placed by fallback poses).
    unregistered : list of str
        Names of the input frames left out (no pose).
    adjustment : dict
        The adjuster's report (``before``/``after`` residuals), empty when none ran.
    fused : Scene or None
        The scene as fused, before the adjuster (for evaluation).
    """

    scene: Scene
    sfm: SfmResult
    alignments: list[ScaleAlignment]
    plane_matches: list[Any] = field(default_factory=list)
    units: str = "sfm"
    timings: dict[str, float] = field(default_factory=dict)
    config: dict[str, Any] = field(default_factory=dict)
    frame_indices: list[int] = field(default_factory=list)
    registration: list[dict[str, Any]] = field(default_factory=list)
    unregistered: list[str] = field(default_factory=list)
    adjustment: dict[str, Any] = field(default_factory=dict)
    fused: Scene | None = None


def scale_sfm(sfm: SfmResult, factor: float) -> SfmResult:
    """The same SfM model with world coordinates multiplied by ``factor`` (> 0).

    Rotations and intrinsics are unchanged; translations and points scale.
    """
    if not factor > 0:
        raise InvalidInput(f"SfM scale factor must be positive, got {factor}")
    cameras = [replace(c, t=c.t * factor) for c in sfm.cameras]
    return replace(sfm, cameras=cameras, points=sfm.points * factor)


def subset_sfm(sfm: SfmResult, views: list[int]) -> SfmResult:
    """The SfM result restricted to ``views`` (indices, increasing), matches re-keyed."""
    pos = {v: k for k, v in enumerate(views)}
    matches = {(pos[i], pos[j]): m for (i, j), m in sfm.matches.items()
               if i in pos and j in pos}
    registration = [sfm.registration[v] for v in views] if sfm.registration else []
    return replace(sfm, cameras=[sfm.cameras[v] for v in views],
                   keypoints=[sfm.keypoints[v] for v in views],
                   point_ids=[sfm.point_ids[v] for v in views], matches=matches,
                   registration=registration)


def origin_sfm(frames: list[Frame], reason: str) -> SfmResult:
    """A point-less SfM result whose world frame is view 0's camera; other views unplaced.

    Used when the matcher builds no model at all, so that the fallback pose can still place
    the views (each frame's ``K`` is taken as is).
    """
    n = len(frames)
    cameras = [Camera(K=f.K, R=np.eye(3), t=np.zeros(3), width=f.width, height=f.height,
                      name=f.name) for f in frames]
    return SfmResult(cameras=cameras, points=np.zeros((0, 3)),
                     keypoints=[np.zeros((0, 2)) for _ in frames],
                     point_ids=[np.zeros(0, np.int64) for _ in frames],
                     registration=[{"method": "origin"}] + [{"method": "none"}] * (n - 1),
                     notes=[f"structure from motion failed: {reason}"])


def hold_intrinsics_fixed(pipe: Pipeline) -> bool:
    """Make the pipeline's matcher keep every frame's ``K`` fixed, if it can.

    Asks the configured matcher class (:meth:`Matcher.fixed_intrinsics_config`); returns False
    when it cannot, in which case the given intrinsics are only its starting guess.
    """
    name, cfg = pipe.config.stages["matcher"]
    fixed = pipe.registry.get("matcher", name).cls.fixed_intrinsics_config(cfg)
    if fixed is None:
        return False
    pipe.config.stages["matcher"] = (name, fixed)
    pipe._stages.pop("matcher", None)  # rebuilt from the new config on next use
    return True


def matcher_keeps_intrinsics(pipe: Pipeline) -> bool:
    """True when the pipeline's matcher returns every frame's ``K`` unchanged.

    That is when its config already is what :meth:`Matcher.fixed_intrinsics_config` would make
    of it (e.g. after :func:`hold_intrinsics_fixed`).
    """
    name, cfg = pipe.config.stages["matcher"]
    fixed = pipe.registry.get("matcher", name).cls.fixed_intrinsics_config(cfg)
    return fixed is not None and fixed == cfg


#: How the fallback placed a view, as written to cameras.json.
FALLBACK_ESTIMATORS = {
    "essential": "essential matrix (OpenCV USAC MAGSAC++), baseline from the reference "
                 "view's depth",
    "pnp": "PnP RANSAC on the reference view's depth-lifted keypoints",
}

# Per-view work (cues, RANSAC, refiner) runs in the worker pool of monoplane.batch: each
# worker builds the pipeline once from the config (initializer), then takes one view per task.
_PIPE: Pipeline | None = None

#: Per-view stages whose seconds make up a view's time (``timings["per_view"]``).
VIEW_STAGES = ("cues", "ransac", "refiner")


def _init_view_worker(config: dict[str, Any]) -> None:
    """Worker initializer: build this worker's pipeline from the resolved config."""
    from monoplane.pipeline import Pipeline

    global _PIPE
    _PIPE = Pipeline.from_config(config)


def process_view(frame: Frame) -> Reconstruction:
    """Cues, RANSAC and refiner on one frame with the pool's pipeline (picklable view task).

    ``rec.frame`` is the frame with its cues; ``rec.timings`` holds each stage's seconds.
    """
    assert _PIPE is not None, "process_view runs in a ViewPool"
    timings: dict[str, float] = {}
    return _PIPE.segment(_PIPE.prepare(frame, timings), timings)


def rescale_reconstruction(rec: Reconstruction, frame: Frame, scale: float) -> Reconstruction:
    """A reconstruction of ``rec.frame`` expressed for ``frame``, its depth times ``scale``.

    The single-view stages are free of the depth's scale: the cloud is normalised into the
    unit sphere and every tolerance is a fraction of the scene radius, so segmenting depth
    ``s·D`` gives the labels of ``D`` and planes whose offsets (and RMS errors) are ``s``
    times larger (to float rounding; ``tests/multiview/test_overlap.py`` checks the labels
    are identical). That lets the views be segmented before SfM has fixed their scale.

    Parameters
    ----------
    rec : Reconstruction
        Segmentation of a frame with depth ``D``.
    frame : Frame
        The same frame with depth ``scale·D`` (and the units and notes that go with it).
    scale : float
        Positive depth factor.

    Returns
    -------
    Reconstruction
        Same labels and normals; offsets ``d`` and ``rmse`` multiplied by ``scale``; ``frame``
        as given.
    """
    params = rec.params.copy()
    params[:, 3] *= scale
    return replace(rec, frame=frame, params=params, rmse=rec.rmse * scale)


@contextlib.contextmanager
def _thread_budget(threads: int | None) -> Iterator[None]:
    """Within the block, this process's kernels use ``threads`` threads, like a worker's
    (:func:`monoplane.jit.thread_budget` reads ``OMP_NUM_THREADS``); None or a value the user
    set leaves it alone."""
    import os

    if threads is None or "OMP_NUM_THREADS" in os.environ:
        yield
        return
    os.environ["OMP_NUM_THREADS"] = str(threads)
    try:
        yield
    finally:
        os.environ.pop("OMP_NUM_THREADS", None)


class ViewTasks:
    """Per-view tasks under way in a :class:`ViewPool`; :meth:`result` collects them.

    The pool's workers take the views one at a time, driven from a background thread (which
    only waits on the workers' pipes), so this process is free meanwhile, e.g. to run SfM.
    Views no worker has taken when :meth:`result` is called are run in this process, so the
    host's core helps finish the batch instead of idling.
    """

    def __init__(self, views: ViewPool, fn: Callable[[Frame], Any], frames: list[Frame]) -> None:
        import threading

        self._views, self._fn, self._frames = views, fn, list(frames)
        self._lock = threading.Lock()
        self._next = 0  # first view nobody has taken
        self._values: dict[int, Any] = {}
        self._errors: dict[int, BaseException] = {}
        self._pool_failure: BaseException | None = None
        self._thread = None
        if views.pool is not None:
            self._thread = threading.Thread(target=self._drive, args=(views.pool,), daemon=True,
                                            name="monoplane-view-pool")
            self._thread.start()

    def _take(self) -> int | None:
        with self._lock:
            if self._next >= len(self._frames):
                return None
            self._next += 1
            return self._next - 1

    def stop(self) -> None:
        """Hand out no further views; return once the workers' running views have finished."""
        with self._lock:
            self._next = len(self._frames)
        if self._thread is not None:
            self._thread.join()

    def _drive(self, pool: Any) -> None:
        taken: list[int] = []  # view of each item handed to the pool, in hand-out order

        def hand_out():  # pulled by the pool whenever a worker is idle
            while (v := self._take()) is not None:
                taken.append(v)
                yield self._frames[v]

        try:
            for outcome in pool.imap_unordered(self._fn, hand_out()):
                v = taken[outcome.index]
                if outcome.error is None:
                    self._values[v] = outcome.value
                else:
                    self._errors[v] = outcome.error
        except BaseException as exc:  # e.g. WorkerInitError: result() runs the rest here
            self._pool_failure = exc

    def result(self) -> list[Any]:
        """Every view's result, in input order, once all are done.

        Raises
        ------
        Exception
            The error of the first failing view (by input position), after all views ran.
        """
        global _PIPE
        previous, _PIPE = _PIPE, self._views.pipe
        try:
            with _thread_budget(self._views.threads):
                while (v := self._take()) is not None:
                    self._run_here(v)
            if self._thread is not None:
                self._thread.join()
                self._thread = None
                if self._pool_failure is not None:
                    self._views.pool_failed(self._pool_failure)
                    # Views the pool took but never finished run here.
                    for v in range(len(self._frames)):
                        if v not in self._values and v not in self._errors:
                            self._run_here(v)
        finally:
            _PIPE = previous
        for v in sorted(self._errors):
            raise self._errors[v]
        return [self._values[v] for v in range(len(self._frames))]

    def _run_here(self, v: int) -> None:
        try:
            self._values[v] = self._fn(self._frames[v])
        except Exception as exc:
            self._errors[v] = exc


class ViewPool:
    """Runs per-view tasks in ``workers`` processes: this one and ``workers - 1`` workers.

    Opened before structure from motion so that the workers start (and import) while the
    matcher runs; this process joins in once it waits for the results
    (:meth:`ViewTasks.result`). A worker costs its start-up (a fresh interpreter importing
    NumPy, SciPy, OpenCV and the project, and loading the compiled kernels: over a second of
    CPU), so with ``workers`` 2 one worker and this process share the views rather than two
    workers while this one waits. In-process, the tasks use ``pipe`` itself.

    Parameters
    ----------
    pipe : Pipeline
        The pipeline whose config the workers rebuild.
    workers : int
        Processes that run views, this one included (1: this process alone).
    n_views : int
        Number of views (no more workers than views are started).
    """

    def __init__(self, pipe: Pipeline, workers: int, n_views: int) -> None:
        self.pipe = pipe
        self.pool = None
        self._tasks: list[ViewTasks] = []
        #: Threads each view may use (the thread budget of the workers and of this process
        #: while it runs views), so that the processes together fill the cores once.
        self.threads: int | None = None
        size = min(workers, n_views) - 1
        if size >= 1:
            from monoplane.batch import WorkerPool, default_workers

            self.threads = max(1, default_workers() // (size + 1))
            self.pool = WorkerPool(size, _init_view_worker, (pipe.config.to_dict(),),
                                   threads_per_worker=self.threads)

    def __enter__(self) -> ViewPool:
        if self.pool is not None:
            self.pool.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        # Tasks nobody collected (the host failed meanwhile): let their running views finish,
        # so the driver thread is done with the workers before they are stopped.
        for tasks in self._tasks:
            tasks.stop()
        if self.pool is not None:
            self.pool.__exit__(*exc)

    def submit(self, fn: Callable[[Frame], Any], frames: list[Frame]) -> ViewTasks:
        """Start ``fn`` on every frame in the workers; :meth:`ViewTasks.result` collects."""
        tasks = ViewTasks(self, fn, frames)
        self._tasks.append(tasks)
        return tasks

    def map(self, fn: Callable[[Frame], Any], frames: list[Frame]) -> list[Any]:
        """``[fn(f) for f in frames]`` in input order; the first failure propagates."""
        return self.submit(fn, frames).result()

    def pool_failed(self, exc: BaseException) -> None:
        """Stop using the workers after ``exc``; later views run in this process."""
        import sys

        from monoplane.batch import WorkerInitError

        if not isinstance(exc, WorkerInitError):
            raise exc
        # E.g. a script without an ``if __name__ == "__main__":`` guard, which spawned
        # workers cannot import: run the views here instead.
        print(f"monoplane: warning: per-view workers could not start ({exc}); "
              "running the views in this process", file=sys.stderr)
        if self.pool is not None:
            self.pool.__exit__(None, None, None)
            self.pool = None
            self.threads = None  # this process alone: all its cores


def default_workers() -> int:
    """Worker processes for per-view stages: the CPUs this process may use."""
    from monoplane.batch import default_workers as batch_default

    return batch_default()


def reconstruct_multiview(frames: list[Frame], pipe: Pipeline, progress: bool = False,
                          sfm: SfmResult | None = None, strict: bool = False,
                          workers: int | None = None) -> MultiviewResult:
    """Planes of a scene seen in a few views.

    Parameters
    ----------
    frames : list of Frame
        Two or more colour frames, optionally with depth/normals (then the cue
        provider uses them). ``K`` is held fixed in SfM only after
        :func:`hold_intrinsics_fixed`; otherwise it is the initial guess.
    pipe : Pipeline
        Configured pipeline; its ``matcher``, ``cues``, RANSAC stages, ``refiner``, ``fuser``
        and ``adjuster`` are used.
    progress : bool
        Show progress messages on stderr.
    sfm : SfmResult, optional
        Skip the matcher and use this SfM result (e.g. known poses).
    strict : bool
        Fail when any view cannot be registered, instead of reconstructing the others.
    workers : int, optional
        Processes for the per-view stages (cues, RANSAC, refiner); default: the CPUs
        available. 1 runs everything in this process.

    Returns
    -------
    MultiviewResult
        The fused scene and diagnostics.

    Raises
    ------
    monoplane.errors.StageError
        When a stage fails (the message names the stage and says why, e.g. no initial pair).
    InvalidInput
        When fewer than two views register, or (``strict``) when any view does not; when a
        view cannot be scale-aligned (too few SfM points on valid depth).
    """
    import sys

    from threadpoolctl import threadpool_limits

    from monoplane.geometry.relative_pose import fallback_relative_pose
    from monoplane.stages.base import Adjuster

    if len(frames) < 2:
        raise InvalidInput(f"multi-view reconstruction needs at least 2 images, got {len(frames)}")
    workers = default_workers() if workers is None else max(1, int(workers))
    with ViewPool(pipe, workers, len(frames)) as views_pool, contextlib.ExitStack() as blas_limit:
        timings: dict[str, float] = {}
        start = time.perf_counter()
        sfm_failure = ""
        # The single-view stages do not depend on the depth's scale (see
        # rescale_reconstruction), only on K. When the matcher keeps every K as given, the
        # views are segmented while SfM runs, and only scaled once it is done.
        early = (views_pool.submit(process_view, frames)
                 if sfm is None and matcher_keeps_intrinsics(pipe) else None)
        if sfm is None:
            matcher = pipe.stage("matcher", Matcher)
            try:
                sfm = pipe.call("matcher", matcher.name, lambda: matcher.match(frames), "multiview",
                                timings)
            except StageError as exc:
                if strict:
                    raise
                # No model at all: view 0 becomes the world frame and every other view is
                # tried with the two-view fallback pose below.
                sfm_failure = str(exc)
                print(f"monoplane: warning: {exc}; placing the views by two-view fallback poses",
                      file=sys.stderr)
                sfm = origin_sfm(frames, sfm_failure)
        elif sfm.num_views != len(frames):
            raise InvalidInput(f"{len(frames)} frames but the SfM result has {sfm.num_views} views")
        registration = [dict(r) for r in sfm.registration] or [{"method": "sfm"} for _ in frames]
        if strict and any(r["method"] == "none" for r in registration):
            missing = [f.name for f, r in zip(frames, registration, strict=True)
                       if r["method"] == "none"]
            raise InvalidInput(f"could not register {len(missing)} of {len(frames)} images: "
                               f"{', '.join(missing)}; they overlap too little with the others "
                               "(drop --strict to reconstruct the registered views)")
        if progress:
            print(f"monoplane: SfM registered {sum(r['method'] != 'none' for r in registration)} "
                  f"of {len(frames)} views", file=sys.stderr)

        config = pipe.config.to_dict()
        # Everything below runs small dense products ((N, 3) @ (3, k)), where OpenBLAS's
        # threads cost far more than they give: 10x slower on a 2-core machine with one core
        # busy (measured: 23 ms against 2.5 ms for a 76 800 x 3 product). One BLAS thread.
        blas_limit.enter_context(threadpool_limits(1, user_api="blas"))
        with_k = []
        for v, frame in enumerate(frames):
            cam = sfm.cameras[v]
            if (cam.height, cam.width) != frame.shape:
                raise InvalidInput(f"{frame.name}: SfM camera size differs from the image size")
            with_k.append(frame.with_(K=cam.K) if not np.allclose(cam.K, frame.K) else frame)
        t0 = time.perf_counter()
        if early is None:
            segmented = views_pool.map(process_view, with_k)
        else:
            segmented = early.result()
            # A view whose K SfM changed after all (a matcher that did not hold it) is redone.
            redo = [v for v in range(len(frames)) if with_k[v] is not frames[v]]
            if redo:
                for v, rec in zip(redo, views_pool.map(process_view, [with_k[v] for v in redo]),
                                  strict=True):
                    segmented[v] = rec
        prepared = [rec.frame for rec in segmented]
        timings["single_view"] = time.perf_counter() - t0
        timings["per_view"] = float(np.mean([sum(rec.timings.get(k, 0.0) for k in VIEW_STAGES)
                                             for rec in segmented]))

        t0 = time.perf_counter()
        alignments: dict[int, ScaleAlignment] = {}
        for v, frame in enumerate(prepared):
            if registration[v]["method"] == "none":
                continue
            if registration[v]["method"] == "origin":
                # The world frame's own depth sets the units.
                alignments[v] = ScaleAlignment(scale=1.0, num_points=0, num_inliers=0,
                                               residual=float("nan"),
                                               relative_residual=float("nan"))
                continue
            pixels, depth = sfm.sparse_depth(v)
            try:
                alignments[v] = align_scale(frame.depth, pixels, depth)
            except InvalidInput as exc:
                if strict:
                    raise InvalidInput(f"{frame.name}: {exc}") from None
                registration[v] = {"method": "none", "reason": str(exc)}
        if sum(r["method"] != "none" for r in registration) == 0:
            raise InvalidInput("no view could be registered and scale-aligned")
        # Fallback: place each left-over view against the registered view it matches best.
        cameras = list(sfm.cameras)
        for v in [v for v, r in enumerate(registration) if r["method"] == "none"]:
            best = None
            for ref in [u for u, r in enumerate(registration) if r["method"] != "none"]:
                depth_ref = prepared[ref].depth * alignments[ref].scale
                found = fallback_relative_pose(prepared[ref].rgb, cameras[ref].K, depth_ref,
                                               prepared[v].rgb, cameras[v].K, prepared[v].depth)
                if found is not None and (best is None or found.inliers > best[1].inliers):
                    best = (ref, found)
            if best is None:
                continue
            ref, fb = best
            cam_ref = cameras[ref]
            cameras[v] = replace(cameras[v], R=fb.R @ cam_ref.R, t=fb.R @ cam_ref.t + fb.t)
            alignments[v] = ScaleAlignment(scale=fb.depth_scale_j, num_points=fb.matches,
                                           num_inliers=fb.inliers, residual=float("nan"),
                                           relative_residual=float("nan"))
            registration[v] = {"method": "fallback", "reference": frames[ref].name,
                               "inliers": fb.inliers, "matches": fb.matches,
                               "estimator": FALLBACK_ESTIMATORS[fb.estimator]}
        sfm = replace(sfm, cameras=cameras, registration=registration)
        keep = [v for v, r in enumerate(registration) if r["method"] != "none"]
        unregistered = [frames[v].name for v, r in enumerate(registration) if r["method"] == "none"]
        if len(keep) < 2:
            why = f"; {sfm_failure}" if sfm_failure else ""
            raise InvalidInput(f"only {len(keep)} of {len(frames)} images could be registered "
                               f"({', '.join(unregistered)} could not){why}; a scene needs two")
        if unregistered:
            print(f"monoplane: warning: {len(unregistered)} of {len(frames)} images could not be "
                  f"registered and are left out: {', '.join(unregistered)}", file=sys.stderr)
        sfm = subset_sfm(sfm, keep)
        prepared = [prepared[v] for v in keep]
        aligns = [alignments[v] for v in keep]

        metric = all(f.depth_kind == "metric" for f in prepared)
        units = prepared[0].depth_units if metric and len(
            {f.depth_units for f in prepared}) == 1 else "sfm"
        world_factor = 1.0
        if units != "sfm":
            # Depth is metric: express the SfM world in the depth's unit instead of the reverse.
            world_factor = float(np.median([1.0 / a.scale for a in aligns]))
            sfm = scale_sfm(sfm, world_factor)
        aligns = [replace(a, scale=a.scale * world_factor, residual=a.residual * world_factor)
                  for a in aligns]
        scales = [a.scale for a in aligns]
        aligned = [
            f.with_(depth=(f.depth * s).astype(np.float32), depth_units=units,
                    notes=[*f.notes, f"depth scaled by {s:.6g} onto the SfM points "
                           f"({a.num_inliers}/{a.num_points} inliers)"])
            for f, s, a in zip(prepared, scales, aligns, strict=True)
        ]
        timings["alignment"] = time.perf_counter() - t0
        views = [rescale_reconstruction(segmented[v], frame, s)
                 for v, frame, s in zip(keep, aligned, scales, strict=True)]

        fuser = pipe.stage("fuser", Fuser)
        scene, plane_matches = pipe.call("fuser", fuser.name,
                                         lambda: fuser.fuse_with_matches(views, sfm), "multiview",
                                         timings)
        scene.scales = scales
        fused = scene
        adjuster = pipe.stage("adjuster", Adjuster)
        scene, sfm, adjustment = pipe.call("adjuster", adjuster.name,
                                           lambda: adjuster.adjust(scene, sfm), "multiview",
                                           timings)
    timings["total"] = time.perf_counter() - start
    return MultiviewResult(scene=scene, sfm=sfm, alignments=aligns,
                           plane_matches=plane_matches, units=units, timings=timings,
                           config=config, frame_indices=keep,
                           registration=[registration[v] for v in keep],
                           unregistered=unregistered, adjustment=adjustment, fused=fused)


# --------------------------------------------------------------------------------------------
# Writers


def cameras_document(cameras: list[Camera], registration: list[dict] | None = None,
                     unregistered: list[str] | None = None) -> dict:
    """``cameras.json`` content: ``{"cameras": [{"image", "K", "R", "t", "width", "height",
    "registration"}], "unregistered": [...]}``.

    Poses are world-to-camera, ``x_cam = R x_world + t``, OpenCV axes. ``registration`` says
    how each pose was found: ``{"method": "sfm"}`` or ``{"method": "fallback", "reference",
    "inliers", ...}``.
    """
    doc = {
        "cameras": [{
            "image": c.name,
            "K": np.asarray(c.K).tolist(),
            "R": np.asarray(c.R).tolist(),
            "t": np.asarray(c.t).tolist(),
            "width": int(c.width),
            "height": int(c.height),
            "registration": dict(registration[k]) if registration else {"method": "sfm"},
        } for k, c in enumerate(cameras)],
        "unregistered": list(unregistered or []),
        "convention": "world-to-camera: x_cam = R x_world + t; camera axes x right, y down, "
                      "z forward (OpenCV); pixel centres at integer coordinates",
    }
    return doc


def write_points_ply(path: Path, points: np.ndarray, colors: np.ndarray | None = None) -> None:
    """Write a coloured point cloud as an ASCII PLY.

    Parameters
    ----------
    path : Path
        Output file.
    points : numpy.ndarray
        (M, 3) points.
    colors : numpy.ndarray, optional
        (M, 3) uint8 RGB; grey when omitted.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    col = (np.full((len(pts), 3), 200, np.uint8) if colors is None
           else np.asarray(colors, dtype=np.uint8).reshape(-1, 3))
    header = ["ply", "format ascii 1.0", f"element vertex {len(pts)}",
              "property float x", "property float y", "property float z",
              "property uchar red", "property uchar green", "property uchar blue", "end_header"]
    rows = [f"{x:.6g} {y:.6g} {z:.6g} {r} {g} {b}"
            for (x, y, z), (r, g, b) in zip(pts.tolist(), col.tolist(), strict=True)]
    path.write_text("\n".join(header + rows) + "\n")


def save_sfm(sfm: SfmResult, out_dir: str | Path, overwrite: bool = False) -> Path:
    """Write ``cameras.json`` and ``points.ply`` of an SfM result atomically into ``out_dir``."""
    from monoplane.fileio import atomic_output_dir

    with atomic_output_dir(out_dir, overwrite) as tmp:
        keep = [v for v, ok in enumerate(sfm.registered) if ok]
        doc = cameras_document([sfm.cameras[v] for v in keep],
                               [sfm.registration[v] for v in keep] if sfm.registration else None,
                               [c.name for c, ok in zip(sfm.cameras, sfm.registered,
                                                        strict=True) if not ok])
        doc["num_points"] = int(len(sfm.points))
        doc["matches"] = [{"images": [sfm.cameras[i].name, sfm.cameras[j].name],
                           "verified_matches": int(len(m))}
                          for (i, j), m in sorted(sfm.matches.items())]
        doc["notes"] = list(sfm.notes)
        (tmp / "cameras.json").write_text(json.dumps(doc, indent=2) + "\n")
        write_points_ply(tmp / "points.ply", sfm.points, sfm.colors)
    return Path(out_dir)


def scene_mesh(scene: Scene, step: int = 2, max_cells: int = 512) -> PlaneMesh:
    """Every global plane's surface: the union of its views' masks on the fused plane.

    Every ``step``-th mask pixel of each linked view plane is lifted along its ray onto the
    fused plane (pixels whose lifted depth disagrees with the view's own plane by more than a
    factor 2 are dropped, which removes grazing-angle slivers). The union is triangulated by
    :func:`~monoplane.geometry.polygons.points_plane_mesh` at about the pixel footprint, holes
    left open.

    Parameters
    ----------
    scene : Scene
        Fused scene.
    step : int
        Pixel stride used when lifting masks.
    max_cells : int
        Cap on the raster size per side.

    Returns
    -------
    PlaneMesh
        World-frame triangles; ``plane_ids`` are global plane ids (0-based, as in scene.json).
    """
    from monoplane.datamodel import pixel_rays

    members: dict[int, list[tuple[int, int]]] = {}
    for v, table in enumerate(scene.links):
        for local, glob in table.items():
            members.setdefault(glob, []).append((v, local))
    rays_cache: dict[int, np.ndarray] = {}
    parts = []
    for g, plane in enumerate(scene.planes):
        points, footprints = [], []
        for v, local in members.get(g, []):
            rec, cam = scene.views[v], scene.cameras[v]
            if v not in rays_cache:
                rays_cache[v] = pixel_rays(cam.K, cam.height, cam.width)[::step, ::step]
            mask = rec.labels[::step, ::step] == local
            rays = rays_cache[v][mask]
            z = ray_plane_depth(rays, plane_to_camera(plane, cam.R, cam.t)[0])
            z_own = ray_plane_depth(rays, rec.params[local - 1])
            ok = (z > 0) & (z_own > 0) & (z < 2 * z_own) & (z_own < 2 * z)
            if not np.any(ok):
                continue
            x_cam = rays[ok] * z[ok, None]
            points.append((x_cam - cam.t) @ cam.R)
            footprints.append(np.median(z[ok]) * step / cam.K[0, 0])
        if points:
            verts, tris = points_plane_mesh(np.concatenate(points), plane,
                                            float(np.median(footprints)), max_cells=max_cells)
            parts.append((g, verts, tris))
    return PlaneMesh.concatenate(parts)


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


def scene_document(result: MultiviewResult) -> dict:
    """``scene.json`` content."""
    scene = result.scene
    colors = scene_plane_colors(scene)
    cams = cameras_document(scene.cameras, result.registration)["cameras"]
    for v, cam in enumerate(cams):
        a = result.alignments[v]
        cam["view_folder"] = f"view_{v:03d}"
        if result.frame_indices:
            cam["input_index"] = int(result.frame_indices[v])
        cam["depth_scale"] = float(scene.scales[v]) if scene.scales else None
        cam["alignment"] = {"num_points": a.num_points, "num_inliers": a.num_inliers,
                            "residual": a.residual, "relative_residual": a.relative_residual}
    planes = []
    for g, plane in enumerate(scene.planes):
        views = [{"view": v, "image": scene.cameras[v].name, "local_id": int(local)}
                 for v, table in enumerate(scene.links) for local, glob in table.items()
                 if glob == g]
        area = sum(int(scene.views[m["view"]].area_px[m["local_id"] - 1]) for m in views)
        planes.append({"id": g, "normal": [float(x) for x in plane[:3]],
                       "offset": float(plane[3]), "color": [int(c) for c in colors[g]],
                       "area_px": area, "views": views})
    return {
        "cameras": cams,
        "planes": planes,
        "plane_matches": [{"view_i": m.view_i, "plane_i": m.plane_i, "view_j": m.view_j,
                           "plane_j": m.plane_j, "criterion": m.criterion}
                          for m in result.plane_matches],
        "num_points": int(len(result.sfm.points)),
        "units": result.units,
        "convention": "world frame of the SfM model; planes satisfy normal . x_world + offset "
                      "= 0, each normal facing the first camera that sees the plane; "
                      "x_cam = R x_world + t with OpenCV camera axes; local_id is the view's "
                      "labels.png value",
        "unregistered": list(result.unregistered),
        "adjustment": result.adjustment,
        "notes": list(result.sfm.notes),
        "timings_s": {k: round(float(v), 4) for k, v in result.timings.items()},
        "config": result.config,
    }


def global_label_map(labels: np.ndarray, links: dict[int, int]) -> np.ndarray:
    """(H, W) uint16 map of global plane ids + 1 (0 = non-planar) from a view's local labels."""
    lut = np.zeros(int(labels.max()) + 1, dtype=np.uint16)
    for local, glob in links.items():
        if local < len(lut):
            lut[local] = glob + 1
    return lut[labels]


def write_global_labels(path: Path, labels: np.ndarray, links: dict[int, int]) -> None:
    """Write ``labels_global.png``: 16-bit PNG, value = global plane id + 1, 0 = non-planar."""
    cv2.imwrite(str(path), global_label_map(labels, links))


def save_scene(result: MultiviewResult, out_dir: str | Path, overwrite: bool = False,
               report: bool = False) -> Path:
    """Write a multi-view result atomically into ``out_dir``.

    Layout: ``view_000/`` ... (the single-view outputs of each registered view, plus
    ``labels_global.png``: global plane id + 1 per pixel, 16-bit), ``scene.json``,
    ``scene.ply`` (each global plane's coloured surface, triangulated with holes open),
    ``cameras.json`` and ``points.ply`` (sparse SfM points); with ``report``, ``report.html``
    and its figures.
    """
    from monoplane.fileio import atomic_output_dir, write_plane_mesh_ply, write_reconstruction_files

    scene = result.scene
    with atomic_output_dir(out_dir, overwrite) as tmp:
        for v, rec in enumerate(scene.views):
            folder = tmp / f"view_{v:03d}"
            folder.mkdir()
            write_reconstruction_files(rec, folder)
            write_global_labels(folder / "labels_global.png", rec.labels, scene.links[v])
        (tmp / "scene.json").write_text(json.dumps(scene_document(result), indent=2) + "\n")
        colors = scene_plane_colors(scene)
        write_plane_mesh_ply(tmp / "scene.ply", scene_mesh(scene), colors, first_id=0)
        cams = cameras_document(scene.cameras, result.registration, result.unregistered)
        (tmp / "cameras.json").write_text(json.dumps(cams, indent=2) + "\n")
        write_points_ply(tmp / "points.ply", result.sfm.points, result.sfm.colors)
        if report:
            from monoplane.report import write_scene_report
            write_scene_report(scene, tmp)
    return Path(out_dir)
