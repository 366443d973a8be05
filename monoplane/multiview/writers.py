"""What a multi-view run writes: ``cameras.json``, ``points.ply``, ``scene.json``, ``scene.ply``,
``scene.glb`` and each view's folder, always atomically (a failed write leaves no folder behind).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from monoplane.datamodel import SfmResult
from monoplane.export.gltf import scene_glb
from monoplane.export.labels import cameras_document, scene_document
from monoplane.io.frames import (
    atomic_output_dir,
    write_plane_mesh_ply,
    write_points_ply,
    write_reconstruction_files,
)
from monoplane.multiview.fusion import global_label_map, scene_mesh, scene_plane_colors

if TYPE_CHECKING:
    from monoplane.multiview.driver import MultiviewResult


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
