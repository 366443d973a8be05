"""The sparse-view driver: matcher, per-view stages, scale alignment, registrar, fusion.

Frames: cameras are world-to-camera ``x_cam = R x_world + t`` with OpenCV axes (x right, y down,
z forward).
"""

from __future__ import annotations

import contextlib
import sys
import time
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from monoplane.contracts import Registrar
from monoplane.datamodel import Frame, Reconstruction, Scene, SfmResult
from monoplane.errors import InvalidInput, StageError
from monoplane.geometry.alignment import ScaleAlignment
from monoplane.host.pool import default_workers
from monoplane.host.view_pool import VIEW_STAGES, ViewPool, process_view
from monoplane.multiview.global_planes import fuse_and_adjust
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

    result_kind: ClassVar[str] = "multiview"  # see monoplane.datamodel.PlaneSet

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
        :func:`hold_intrinsics_fixed`; otherwise it is the initial guess. When two share a
        name, each name gets its input index as a prefix (``000_rgb``).
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
    from threadpoolctl import threadpool_limits

    if len(frames) < 2:
        raise InvalidInput(f"multi-view reconstruction needs at least 2 images, got {len(frames)}")
    frames = _unique_names(frames)
    workers = default_workers() if workers is None else max(1, int(workers))
    with ViewPool(pipe, workers, len(frames)) as views_pool, contextlib.ExitStack() as blas_limit:
        timings: dict[str, float] = {}
        start = time.perf_counter()
        # The single-view stages do not depend on the depth's scale (see
        # rescale_reconstruction), only on K. When the matcher keeps every K as given, the
        # views are segmented while SfM runs, and only scaled once it is done.
        early = (views_pool.submit(process_view, frames)
                 if sfm is None and matcher_keeps_intrinsics(pipe) else None)
        correspondences = feature_correspondences(pipe, frames)
        sfm, sfm_failure = _structure_from_motion(pipe, frames, sfm, correspondences, timings)
        registration = _sfm_registration(sfm, len(frames), progress)

        config = pipe.config.to_dict()
        # Everything below runs small dense products ((N, 3) @ (3, k)), where OpenBLAS's
        # threads cost far more than they give: 10x slower on a 2-core machine with one core
        # busy (measured: 23 ms against 2.5 ms for a 76 800 x 3 product). One BLAS thread.
        blas_limit.enter_context(threadpool_limits(1, user_api="blas"))
        segmented = _segment_views(views_pool, early, frames, sfm, timings)
        prepared = [rec.frame for rec in segmented]

        t0 = time.perf_counter()
        sfm, found, sfm_failure = _align_views(prepared, sfm, registration, strict,
                                               correspondences, sfm_failure)
        timings["alignment"] = time.perf_counter() - t0
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
        keep, unregistered, reasons = _registered_views(frames, registration, strict,
                                                        sfm_failure)
        sfm, units, aligns, aligned = _to_scene_units(subset_sfm(sfm, keep),
                                                      [prepared[v] for v in keep],
                                                      [found[v] for v in keep])
        timings["alignment"] += time.perf_counter() - t0
        scales = [a.scale for a in aligns]
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


def _structure_from_motion(pipe: Pipeline, frames: list[Frame], sfm: SfmResult | None,
                           correspondences: Any, timings: dict[str, float]
                           ) -> tuple[SfmResult, str]:
    """The matcher's SfM result (or ``sfm`` when given), and why SfM failed ("" if it did not).

    When the matcher builds no model at all, view 0 becomes the world frame
    (:func:`~monoplane.multiview.registration.origin_sfm`) and the registrar places the others.
    """
    if sfm is not None:
        if sfm.num_views != len(frames):
            raise InvalidInput(f"{len(frames)} frames but the SfM result has {sfm.num_views} views")
        return sfm, ""
    try:
        return match_views(pipe, frames, correspondences, "multiview", timings), ""
    except StageError as exc:
        if exc.kind != "matcher":
            raise
        # No model at all: view 0 becomes the world frame and the registrar places the other
        # views.
        print(f"monoplane: warning: {exc}; placing the views with the registrar",
              file=sys.stderr)
        return replace(origin_sfm(frames, str(exc)), correspondences=correspondences), str(exc)


def _unique_names(frames: list[Frame]) -> list[Frame]:
    """``frames``, or when two share a name (``view0/rgb.png`` and ``view1/rgb.png``), each
    renamed with its input index as a prefix (``000_rgb``), so the outputs tell them apart."""
    if len({f.name for f in frames}) == len(frames):
        return frames
    return [f.with_(name=f"{i:03d}_{f.name}") for i, f in enumerate(frames)]


def _sfm_registration(sfm: SfmResult, n_views: int, progress: bool) -> list[dict[str, Any]]:
    """Per view, how SfM placed it (``method``; ``"sfm"`` for all when the matcher says
    nothing) and, for an SfM placement, its evidence: the keypoints that observe model points.
    With ``progress``, says how many views SfM placed on stderr."""
    registration = [dict(r) for r in sfm.registration] or [{"method": "sfm"}
                                                           for _ in range(n_views)]
    for v, r in enumerate(registration):
        if r["method"] == "sfm":
            r.setdefault("observations", int((sfm.point_ids[v] >= 0).sum()))
    if progress:
        print(f"monoplane: SfM registered {sum(r['method'] != 'none' for r in registration)} "
              f"of {n_views} views", file=sys.stderr)
    return registration


def _align_views(prepared: list[Frame], sfm: SfmResult, registration: list[dict[str, Any]],
                 strict: bool, correspondences: Any, sfm_failure: str
                 ) -> tuple[SfmResult, list[ScaleAlignment | None], str]:
    """Scale-align each SfM-placed view's depth onto the SfM points
    (:func:`~monoplane.multiview.registration.align_to_sfm`, which updates ``registration``).

    When SfM placed views but none could be scale-aligned (too few model points on valid
    depth), it is as if SfM had built no model: view 0 sets the world and the registrar
    places the rest.

    Returns
    -------
    (SfmResult, list, str)
        The SfM result carrying the registration records, each view's alignment (None where
        there is none) and why SfM failed ("" if it did not).
    """
    found = align_to_sfm(prepared, sfm, registration, strict)
    if not any(r["method"] != "none" for r in registration):
        reasons = "; ".join(r.get("reason", "") for r in registration if r.get("reason"))
        sfm_failure = f"no registered view could be scale-aligned ({reasons})"
        sfm = replace(origin_sfm(prepared, sfm_failure), correspondences=correspondences)
        registration = [dict(r) for r in sfm.registration]
        found = align_to_sfm(prepared, sfm, registration, strict)
    return replace(sfm, registration=registration), found, sfm_failure


def _segment_views(views_pool: ViewPool, early: Any, frames: list[Frame], sfm: SfmResult,
                   timings: dict[str, float]) -> list[Reconstruction]:
    """Each view's single-view result at its SfM camera's intrinsics.

    ``early`` is the pool's pending result for the frames as given (None when none was
    started); a view whose ``K`` SfM changed is redone. Records ``single_view`` (the wait) and
    ``per_view`` (a view's mean stage seconds) in ``timings``.
    """
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
    timings["single_view"] = time.perf_counter() - t0
    timings["per_view"] = float(np.mean([sum(rec.timings.get(k, 0.0) for k in VIEW_STAGES)
                                         for rec in segmented]))
    return segmented


def _registered_views(frames: list[Frame], registration: list[dict[str, Any]], strict: bool,
                      sfm_failure: str) -> tuple[list[int], list[str], dict[str, str]]:
    """The indices of the views with a pose, the names of the others and why each was left
    out (warned about on stderr).

    Raises
    ------
    InvalidInput
        When fewer than two views have a pose, or (``strict``) when any view has none.
    """
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
    return keep, unregistered, reasons


def _to_scene_units(sfm: SfmResult, prepared: list[Frame], aligns: list[ScaleAlignment]
                    ) -> tuple[SfmResult, str, list[ScaleAlignment], list[Frame]]:
    """Express the registered views in one unit: the depth's when every view's depth is
    metric in one unit (the SfM world is scaled onto it), otherwise SfM's (``"sfm"``).

    Returns
    -------
    (SfmResult, str, list of ScaleAlignment, list of Frame)
        The SfM result in scene units, the unit, each view's alignment to it and each frame
        with its depth scaled into it.
    """
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
    aligned = [
        f.with_(depth=(f.depth * a.scale).astype(np.float32), depth_units=units,
                notes=[*f.notes, f"depth scaled by {a.scale:.6g} onto the SfM points "
                       f"({a.num_inliers}/{a.num_points} inliers)"])
        for f, a in zip(prepared, aligns, strict=True)
    ]
    return sfm, units, aligns, aligned
