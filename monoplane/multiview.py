"""Sparse-view planar reconstruction (paper §III-C): SfM, scale alignment, per-view planes, fusion.

Python API::

    from monoplane.pipeline import Pipeline
    from monoplane.multiview import reconstruct_multiview, save_scene
    pipe = Pipeline.from_preset("monoplane")
    result = reconstruct_multiview([frame_a, frame_b], pipe, progress=True)
    save_scene(result, "out/")

Steps:

1. the configured matcher (``[matcher]``, default ``colmap``) gives cameras, sparse points and
   keypoint matches;
2. the cue provider fills each view's depth and normals (at the view's native resolution, with
   the SfM intrinsics);
3. each view's depth is scaled onto the SfM points (:func:`~monoplane.geometry.alignment.
   align_scale`); when every view's depth is metric the SfM world is then rescaled to the views'
   median metric scale, so outputs keep the depth's units;
4. the single-view pipeline segments each view;
5. the configured fuser (``[fuser]``, default ``average``) matches and fuses planes into a
   :class:`~monoplane.types.Scene`.

Frames: cameras are world-to-camera ``x_cam = R x_world + t`` with OpenCV axes (x right, y down,
z forward).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.geometry.alignment import ScaleAlignment, align_scale
from monoplane.geometry.polygons import PlaneMesh, points_plane_mesh
from monoplane.stages.base import Fuser, Matcher
from monoplane.types import (
    Camera,
    Frame,
    Reconstruction,
    Scene,
    SfmResult,
    plane_to_camera,
    ray_plane_depth,
)

if TYPE_CHECKING:
    from monoplane.pipeline import Pipeline


@dataclass
class MultiviewResult:
    """Everything the sparse-view driver produced.

    Attributes
    ----------
    scene : Scene
        Cameras, per-view reconstructions and fused global planes (world frame).
    sfm : SfmResult
        The matcher's output, in the scene's units.
    alignments : list of ScaleAlignment
        Per-view scale alignment of the monocular depth onto the SfM points.
    plane_matches : list
        Plane correspondences the fuser accepted (objects with ``view_i``, ``plane_i``,
        ``view_j``, ``plane_j``, ``criterion``), when the fuser exposes them.
    units : str
        Unit of the scene's coordinates: the depths' unit when all views had metric depth,
        otherwise ``"sfm"`` (the SfM model's arbitrary scale).
    timings : dict
        Seconds per step: ``matcher``, ``cues``, ``alignment``, ``single_view``, ``fuser``,
        ``total``.
    config : dict
        The resolved pipeline config.
    """

    scene: Scene
    sfm: SfmResult
    alignments: list[ScaleAlignment]
    plane_matches: list[Any] = field(default_factory=list)
    units: str = "sfm"
    timings: dict[str, float] = field(default_factory=dict)
    config: dict[str, Any] = field(default_factory=dict)


def scale_sfm(sfm: SfmResult, factor: float) -> SfmResult:
    """The same SfM model with world coordinates multiplied by ``factor`` (> 0).

    Rotations and intrinsics are unchanged; translations and points scale.
    """
    if not factor > 0:
        raise InvalidInput(f"SfM scale factor must be positive, got {factor}")
    cameras = [replace(c, t=c.t * factor) for c in sfm.cameras]
    return replace(sfm, cameras=cameras, points=sfm.points * factor)


def reconstruct_multiview(frames: list[Frame], pipe: Pipeline, progress: bool = False,
                          sfm: SfmResult | None = None) -> MultiviewResult:
    """Planes of a scene seen in a few views.

    Parameters
    ----------
    frames : list of Frame
        Two or more colour frames, optionally with depth/normals (then the ``given`` cue
        provider uses them). ``K`` is fixed in SfM only when the config sets
        ``matcher.fixed_intrinsics``; otherwise it is the initial guess.
    pipe : Pipeline
        Configured pipeline; its ``matcher``, ``cues``, RANSAC stages, ``refiner`` and ``fuser``
        are used.
    progress : bool
        Show tqdm progress bars on stderr.
    sfm : SfmResult, optional
        Skip the matcher and use this SfM result (e.g. known poses).

    Returns
    -------
    MultiviewResult
        The fused scene and diagnostics.

    Raises
    ------
    monoplane.errors.StageError
        When a stage fails (the message names the stage and says why, e.g. no initial pair).
    InvalidInput
        When a view cannot be scale-aligned (too few SfM points on valid depth).
    """
    from tqdm import tqdm

    if len(frames) < 2:
        raise InvalidInput(f"multi-view reconstruction needs at least 2 images, got {len(frames)}")
    timings: dict[str, float] = {}
    start = time.perf_counter()
    if sfm is None:
        matcher = pipe.stage("matcher", Matcher)
        sfm = pipe.call("matcher", matcher.name, lambda: matcher.match(frames), "multiview",
                        timings)
    elif sfm.num_views != len(frames):
        raise InvalidInput(f"{len(frames)} frames but the SfM result has {sfm.num_views} views")

    prepared: list[Frame] = []
    for v, frame in enumerate(tqdm(frames, desc="cues", disable=not progress, leave=False)):
        cam = sfm.cameras[v]
        if (cam.height, cam.width) != frame.shape:
            raise InvalidInput(f"{frame.name}: SfM camera size differs from the image size")
        f = frame.with_(K=cam.K) if not np.allclose(cam.K, frame.K) else frame
        t0 = time.perf_counter()
        prepared.append(pipe.prepare(f))
        timings["cues"] = timings.get("cues", 0.0) + time.perf_counter() - t0

    t0 = time.perf_counter()
    alignments = []
    for v, frame in enumerate(prepared):
        pixels, depth = sfm.sparse_depth(v)
        try:
            alignments.append(align_scale(frame.depth, pixels, depth))
        except InvalidInput as exc:
            raise InvalidInput(f"{frame.name}: {exc}") from None
    metric = all(f.depth_kind == "metric" for f in prepared)
    units = prepared[0].depth_units if metric and len(
        {f.depth_units for f in prepared}) == 1 else "sfm"
    world_factor = 1.0
    if units != "sfm":
        # Depth is metric: express the SfM world in the depth's unit instead of the reverse.
        world_factor = float(np.median([1.0 / a.scale for a in alignments]))
        sfm = scale_sfm(sfm, world_factor)
    alignments = [replace(a, scale=a.scale * world_factor, residual=a.residual * world_factor)
                  for a in alignments]
    scales = [a.scale for a in alignments]
    aligned = [
        f.with_(depth=(f.depth * s).astype(np.float32), depth_units=units,
                notes=[*f.notes, f"depth scaled by {s:.6g} onto the SfM points "
                       f"({a.num_inliers}/{a.num_points} inliers)"])
        for f, s, a in zip(prepared, scales, alignments, strict=True)
    ]
    timings["alignment"] = time.perf_counter() - t0

    views: list[Reconstruction] = []
    t0 = time.perf_counter()
    for f in tqdm(aligned, desc="single-view planes", disable=not progress, leave=False):
        views.append(pipe.segment(f))
    timings["single_view"] = time.perf_counter() - t0

    fuser = pipe.stage("fuser", Fuser)
    # Fusers that can report their plane correspondences do so through fuse_with_matches.
    with_matches = getattr(fuser, "fuse_with_matches", None)
    plane_matches: list[Any] = []
    if with_matches is not None:
        scene, plane_matches = pipe.call("fuser", fuser.name, lambda: with_matches(views, sfm),
                                         "multiview", timings)
    else:
        scene = pipe.call("fuser", fuser.name, lambda: fuser.fuse(views, sfm), "multiview",
                          timings)
    scene.scales = scales
    timings["total"] = time.perf_counter() - start
    return MultiviewResult(scene=scene, sfm=sfm, alignments=alignments,
                           plane_matches=plane_matches, units=units, timings=timings,
                           config=pipe.config.to_dict())


# --------------------------------------------------------------------------------------------
# Writers


def cameras_document(cameras: list[Camera]) -> dict:
    """``cameras.json`` content: ``{"cameras": [{"image", "K", "R", "t", "width", "height"}]}``.

    Poses are world-to-camera, ``x_cam = R x_world + t``, OpenCV axes.
    """
    return {
        "cameras": [{
            "image": c.name,
            "K": np.asarray(c.K).tolist(),
            "R": np.asarray(c.R).tolist(),
            "t": np.asarray(c.t).tolist(),
            "width": int(c.width),
            "height": int(c.height),
        } for c in cameras],
        "convention": "world-to-camera: x_cam = R x_world + t; camera axes x right, y down, "
                      "z forward (OpenCV); pixel centres at integer coordinates",
    }


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
    from monoplane.io import atomic_output_dir

    with atomic_output_dir(out_dir, overwrite) as tmp:
        doc = cameras_document(sfm.cameras)
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
    from monoplane.types import pixel_rays

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
    cams = cameras_document(scene.cameras)["cameras"]
    for v, cam in enumerate(cams):
        a = result.alignments[v]
        cam["view_folder"] = f"view_{v:03d}"
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
        "notes": list(result.sfm.notes),
        "timings_s": {k: round(float(v), 4) for k, v in result.timings.items()},
        "config": result.config,
    }


def save_scene(result: MultiviewResult, out_dir: str | Path, overwrite: bool = False,
               report: bool = False) -> Path:
    """Write a multi-view result atomically into ``out_dir``.

    Layout: ``view_000/`` ... (the single-view outputs of each view), ``scene.json``,
    ``scene.ply`` (each global plane's coloured surface, triangulated with holes open),
    ``cameras.json`` and ``points.ply`` (sparse SfM points); with ``report``, ``report.html``
    and its figures.
    """
    from monoplane.io import atomic_output_dir, write_plane_mesh_ply, write_reconstruction_files

    scene = result.scene
    with atomic_output_dir(out_dir, overwrite) as tmp:
        for v, rec in enumerate(scene.views):
            folder = tmp / f"view_{v:03d}"
            folder.mkdir()
            write_reconstruction_files(rec, folder)
        (tmp / "scene.json").write_text(json.dumps(scene_document(result), indent=2) + "\n")
        colors = scene_plane_colors(scene)
        write_plane_mesh_ply(tmp / "scene.ply", scene_mesh(scene), colors, first_id=0)
        cams = cameras_document(scene.cameras)
        (tmp / "cameras.json").write_text(json.dumps(cams, indent=2) + "\n")
        write_points_ply(tmp / "points.ply", result.sfm.points, result.sfm.colors)
        if report:
            from monoplane.report import write_scene_report
            write_scene_report(scene, tmp)
    return Path(out_dir)
