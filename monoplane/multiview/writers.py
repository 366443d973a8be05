"""What a multi-view run writes: ``cameras.json``, ``points.ply``, ``scene.json``, ``scene.ply``,
``scene.glb`` and each view's folder, always atomically (a failed write leaves no folder behind).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from monoplane.datamodel import Camera, SfmResult
from monoplane.export.gltf import scene_glb
from monoplane.geometry.mesh import scene_mesh
from monoplane.io.frames import (
    atomic_output_dir,
    write_plane_mesh_ply,
    write_points_ply,
    write_reconstruction_files,
)
from monoplane.multiview.global_planes import global_label_map, scene_plane_colors

if TYPE_CHECKING:
    from monoplane.multiview.driver import MultiviewResult


def cameras_document(cameras: list[Camera], registration: list[dict] | None = None,
                     unregistered: list[str] | None = None) -> dict:
    """``cameras.json`` content: ``{"cameras": [{"image", "K", "R", "t", "width", "height",
    "registration"}], "unregistered": [...]}``.

    Poses are world-to-camera, ``x_cam = R x_world + t``, OpenCV axes. ``registration`` says
    how each pose was found, with its evidence: ``{"method": "sfm", "observations"}``,
    ``{"method": "origin"}`` (SfM built no model; this camera is the world frame) or what the
    registrar placed it by (``"features"``, ``"essential"``, ``"planes"``,
    ``"planes+features"``, ``"fpfh"``; with ``reference``, ``matches``, ``support``,
    ``verified_overlap``, ``colour_correlation``, ``violations``, ``icp``, ``depth_scale``).
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


def save_sfm(sfm: SfmResult, out_dir: str | Path, overwrite: bool = False) -> Path:
    """Write ``cameras.json`` and ``points.ply`` of an SfM result atomically into ``out_dir``."""
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
        "unregistered_reasons": dict(result.unregistered_reasons),
        "adjustment": result.adjustment,
        "notes": list(result.sfm.notes),
        "timings_s": {k: round(float(v), 4) for k, v in result.timings.items()},
        "config": result.config,
    }


def write_global_labels(path: Path, labels: np.ndarray, links: dict[int, int]) -> None:
    """Write ``labels_global.png``: 16-bit PNG, value = global plane id + 1, 0 = non-planar."""
    cv2.imwrite(str(path), global_label_map(labels, links))


def save_scene(result: MultiviewResult, out_dir: str | Path, overwrite: bool = False,
               report: bool = False) -> Path:
    """Write a multi-view result atomically into ``out_dir``.

    Layout: ``view_000/`` ... (the single-view outputs of each registered view, plus
    ``labels_global.png``: global plane id + 1 per pixel, 16-bit), ``scene.json``,
    ``scene.ply`` (each global plane's coloured surface, triangulated with holes open),
    ``scene.glb`` (the same surfaces, one glTF mesh node per global plane, and the cameras; see
    :mod:`monoplane.export.gltf`), ``cameras.json`` and ``points.ply`` (sparse SfM points);
    with ``report``, ``report.html`` and its figures.
    """
    scene = result.scene
    with atomic_output_dir(out_dir, overwrite) as tmp:
        for v, rec in enumerate(scene.views):
            folder = tmp / f"view_{v:03d}"
            folder.mkdir()
            write_reconstruction_files(rec, folder)
            write_global_labels(folder / "labels_global.png", rec.labels, scene.links[v])
        (tmp / "scene.json").write_text(json.dumps(scene_document(result), indent=2) + "\n")
        colors = scene_plane_colors(scene)
        mesh = scene_mesh(scene)
        write_plane_mesh_ply(tmp / "scene.ply", mesh, colors, first_id=0)
        (tmp / "scene.glb").write_bytes(scene_glb(scene, mesh))
        cams = cameras_document(scene.cameras, result.registration, result.unregistered)
        (tmp / "cameras.json").write_text(json.dumps(cams, indent=2) + "\n")
        write_points_ply(tmp / "points.ply", result.sfm.points, result.sfm.colors)
        if report:
            from monoplane.report import write_scene_report
            write_scene_report(scene, tmp)
    return Path(out_dir)
