"""Label maps and the JSON documents beside them: ``planes.json``, ``scene.json``,
``cameras.json``."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from monoplane.datamodel import Camera, Reconstruction

if TYPE_CHECKING:
    from monoplane.multiview.driver import MultiviewResult


def planes_document(rec: Reconstruction) -> dict:
    """The ``planes.json`` content for a reconstruction."""
    K = rec.frame.K
    colors = rec.colors
    area = rec.area_px
    planes = [{
        "id": i + 1,
        "normal": [float(v) for v in rec.planes[i, :3]],
        "offset": float(rec.planes[i, 3]),
        "area_px": int(area[i]),
        "rmse": float(rec.rmse[i]),  # type: ignore[index]
        "support": int(rec.support[i]),  # type: ignore[index]
        "color": [int(c) for c in colors[i]],
    } for i in range(rec.num_planes)]
    return {
        "planes": planes,
        "convention": "normal . X + offset = 0, X in the camera frame (x right, y down, "
                      "z forward) in depth_units; normal faces the camera",
        "intrinsics": {"fx": float(K[0, 0]), "fy": float(K[1, 1]), "cx": float(K[0, 2]),
                       "cy": float(K[1, 2]), "width": rec.frame.width,
                       "height": rec.frame.height},
        "depth_units": rec.frame.depth_units,
        "depth_kind": rec.frame.depth_kind,
        "notes": list(rec.frame.notes),
        "timings_s": {k: round(float(v), 4) for k, v in rec.timings.items()},
        "config": rec.config,
    }


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


def scene_document(result: MultiviewResult) -> dict:
    """``scene.json`` content."""
    from monoplane.multiview.fusion import scene_plane_colors

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
