"""The sparse-view driver: matcher, per-view stages, scale alignment, registrar, fusion.

Frames: cameras are world-to-camera ``x_cam = R x_world + t`` with OpenCV axes (x right, y down,
z forward).
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from monoplane.host.pool import default_workers
from monoplane.host.view_pool import VIEW_STAGES, ViewPool, process_view
from monoplane.datamodel import Frame, Scene, SfmResult
from monoplane.errors import InvalidInput, StageError
from monoplane.geometry.alignment import ScaleAlignment
from monoplane.multiview.fusion import fuse_and_adjust
from monoplane.multiview.registration import (
    align_to_sfm,
    feature_correspondences,
    match_views,
    matcher_keeps_intrinsics,
    origin_sfm,
    rescale_reconstruction,
    scale_sfm,
    subset_sfm,
)
from monoplane.stages.base import Registrar

if TYPE_CHECKING:
    from monoplane.host.pipeline import Pipeline


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
        the registrar, the scale of its pose hypothesis and the dense check's counts).
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
        Per scene view, how its pose was found and the evidence: ``method`` ``"sfm"``,
        ``"origin"`` (SfM built no model; this view's camera is the world frame) or the
        registrar's (see :func:`~monoplane.multiview.writers.cameras_document`).
    unregistered : list of str
        Names of the input frames left out (no pose).
    unregistered_reasons : dict
        Why each of them was left out (the registrar's last word), by name.
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
    unregistered_reasons: dict[str, str] = field(default_factory=dict)
    adjustment: dict[str, Any] = field(default_factory=dict)
    fused: Scene | None = None


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
        Fail when any view can be placed neither by the matcher nor by the registrar,
        instead of reconstructing the others.
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
        correspondences = feature_correspondences(pipe, frames)
        if sfm is None:
            try:
                sfm = match_views(pipe, frames, correspondences, "multiview", timings)
            except StageError as exc:
                if exc.kind != "matcher":
                    raise
                # No model at all: view 0 becomes the world frame and the registrar places
                # the other views.
                sfm_failure = str(exc)
                print(f"monoplane: warning: {exc}; placing the views with the registrar",
                      file=sys.stderr)
                sfm = replace(origin_sfm(frames, sfm_failure), correspondences=correspondences)
        elif sfm.num_views != len(frames):
            raise InvalidInput(f"{len(frames)} frames but the SfM result has {sfm.num_views} views")
        registration = [dict(r) for r in sfm.registration] or [{"method": "sfm"} for _ in frames]
        for v, r in enumerate(registration):
            if r["method"] == "sfm":
                # Evidence of an SfM placement: the view's keypoints that observe model points.
                r.setdefault("observations", int((sfm.point_ids[v] >= 0).sum()))
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
        found = align_to_sfm(prepared, sfm, registration, strict)
        if not any(r["method"] != "none" for r in registration):
            # SfM placed views but none could be scale-aligned (too few model points on valid
            # depth): as if it had built no model, view 0 sets the world and the registrar
            # places the rest.
            reasons = "; ".join(r.get("reason", "") for r in registration if r.get("reason"))
            sfm_failure = f"no registered view could be scale-aligned ({reasons})"
            sfm = replace(origin_sfm(prepared, sfm_failure), correspondences=correspondences)
            registration = [dict(r) for r in sfm.registration]
            found = align_to_sfm(prepared, sfm, registration, strict)
        timings["alignment"] = time.perf_counter() - t0
        sfm = replace(sfm, registration=registration)
        # The registrar places the views SfM left out, and checks the weakly supported ones.
        registrar = pipe.stage("registrar", Registrar)
        sfm, found = pipe.call("registrar", registrar.name,
                               lambda: registrar.register(segmented, sfm, found), "multiview",
                               timings)
        registration = [dict(r) for r in sfm.registration]
        if progress:
            placed = sum(r["method"] not in ("none", "sfm", "origin") for r in registration)
            print(f"monoplane: the registrar placed {placed} view(s)", file=sys.stderr)
        t0 = time.perf_counter()
        keep = [v for v, r in enumerate(registration) if r["method"] != "none"]
        unregistered = [frames[v].name for v, r in enumerate(registration) if r["method"] == "none"]
        if strict and unregistered:
            why = f" (structure from motion: {sfm_failure})" if sfm_failure else ""
            raise InvalidInput(f"could not register {len(unregistered)} of {len(frames)} images: "
                               f"{', '.join(unregistered)}; no method placed them{why} (drop "
                               "--strict to reconstruct the registered views)")
        if len(keep) < 2:
            why = f"; {sfm_failure}" if sfm_failure else ""
            raise InvalidInput(f"only {len(keep)} of {len(frames)} images could be registered "
                               f"({', '.join(unregistered)} could not){why}; a scene needs two")
        reasons = {frames[v].name: registration[v].get("reason", "not placed")
                   for v, r in enumerate(registration) if r["method"] == "none"}
        if unregistered:
            print(f"monoplane: warning: {len(unregistered)} of {len(frames)} images could not be "
                  f"registered and are left out: "
                  f"{'; '.join(f'{n} ({why})' for n, why in reasons.items())}", file=sys.stderr)
        sfm = subset_sfm(sfm, keep)
        prepared = [prepared[v] for v in keep]
        aligns = [found[v] for v in keep]

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
        timings["alignment"] += time.perf_counter() - t0
        views = [rescale_reconstruction(segmented[v], frame, s)
                 for v, frame, s in zip(keep, aligned, scales, strict=True)]

        scene, fused, sfm, plane_matches, adjustment = fuse_and_adjust(pipe, views, sfm, scales,
                                                                       timings)
    timings["total"] = time.perf_counter() - start
    return MultiviewResult(scene=scene, sfm=sfm, alignments=aligns,
                           plane_matches=plane_matches, units=units, timings=timings,
                           config=config, frame_indices=keep,
                           registration=[registration[v] for v in keep],
                           unregistered=unregistered, unregistered_reasons=reasons,
                           adjustment=adjustment, fused=fused)
