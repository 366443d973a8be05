"""The ``labels`` output format: label maps and the JSON documents beside them.

* a frame: ``labels.png`` (uint16, 0 = non-planar, ``i`` = plane ``i`` of ``planes.json``) and
  ``planes.json``;
* a point cloud: ``labels.npy`` ((N,) int32 in the input order, 0 = no plane) and
  ``planes.json``;
* a multi-view result: ``scene.json``, ``cameras.json`` and in each view folder
  ``labels_global.png`` (uint16, global plane id + 1, 0 = non-planar).

Every document lists its planes the same way (:func:`plane_entries`): ``id`` (the result's
``ids``: label values, or a scene's global ids), ``normal`` and ``offset`` (``normal · X +
offset = 0`` in the result's frame and units), then what that kind of result knows of each
plane. :func:`planes_document` picks the document by the result's ``result_kind``.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from monoplane.contracts.exporter import Exporter
from monoplane.datamodel import (
    Camera,
    CloudResult,
    PlaneSet,
    Reconstruction,
    global_label_map,
    scene_plane_colors,
)
from monoplane.errors import InvalidInput
from monoplane.export.shared import SharedWork
from monoplane.hookspecs import hookimpl
from monoplane.version import __version__


def plane_entries(result: PlaneSet, columns: dict[str, Sequence[Any]]) -> list[dict[str, Any]]:
    """One JSON entry per plane: ``id``, ``normal``, ``offset``, then ``columns``.

    Parameters
    ----------
    result : PlaneSet
        Planes (P, 4) and their ids (P,).
    columns : dict
        Per-plane values by key, each a sequence of P JSON-ready values, in output order.

    Returns
    -------
    list of dict
        P entries, in the order of ``result.planes``.
    """
    return [{"id": int(pid), "normal": [float(v) for v in plane[:3]], "offset": float(plane[3]),
             **{key: values[row] for key, values in columns.items()}}
            for row, (pid, plane) in enumerate(zip(result.ids, result.planes, strict=True))]


def _frame_document(rec: Reconstruction) -> dict[str, Any]:
    """``planes.json`` of one frame."""
    K = rec.frame.K
    return {
        "planes": plane_entries(rec, {
            "area_px": [int(a) for a in rec.area_px],
            "rmse": [float(r) for r in rec.rmse],
            "support": [int(n) for n in rec.support],
            "color": [[int(c) for c in rgb] for rgb in rec.colors],
        }),
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


def _cloud_document(result: CloudResult) -> dict[str, Any]:
    """``planes.json`` of a point cloud (``num_points``: the points of the cloud, and of each
    plane its ``support``)."""
    return {
        **({"source": result.source} if result.source else {}),
        "num_points": int(result.points.shape[0]),
        "num_planes": result.num_planes,
        "planes": plane_entries(result, {
            "num_points": [int(n) for n in result.support],
            "rmse": [float(r) for r in result.rmse],
            "centroid": result.centroids.tolist(),
        }),
        "notes": list(result.notes),
        "config": result.config,
    }


def _multiview_document(result: Any) -> dict[str, Any]:
    """``scene.json`` of a multi-view result (a :class:`monoplane.multiview.MultiviewResult`:
    the scene with its SfM, alignments and plane matches)."""
    scene = result.scene
    cams = cameras_document(scene.cameras, result.registration)["cameras"]
    for v, cam in enumerate(cams):
        a = result.alignments[v]
        cam["view_folder"] = f"view_{v:03d}"
        if result.frame_indices:
            cam["input_index"] = int(result.frame_indices[v])
        cam["depth_scale"] = float(scene.scales[v]) if scene.scales else None
        cam["alignment"] = {"num_points": a.num_points, "num_inliers": a.num_inliers,
                            "residual": a.residual, "relative_residual": a.relative_residual}
    views: list[list[dict[str, Any]]] = [[] for _ in range(scene.num_planes)]
    for v, table in enumerate(scene.links):
        for local, glob in table.items():
            views[glob].append({"view": v, "image": scene.cameras[v].name,
                                "local_id": int(local)})
    return {
        "cameras": cams,
        "planes": plane_entries(scene, {
            "color": [[int(c) for c in rgb] for rgb in scene_plane_colors(scene)],
            "area_px": [int(a) for a in scene.support],
            "views": views,
        }),
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


#: The document of each result kind: ``planes.json`` for a frame or a cloud, ``scene.json``
#: for a multi-view result.
_DOCUMENTS: dict[str, Callable[[Any], dict[str, Any]]] = {
    "frame": _frame_document,
    "cloud": _cloud_document,
    "multiview": _multiview_document,
}


def planes_document(result: Any) -> dict[str, Any]:
    """The JSON document of a result's planes, whatever the kind of result.

    Parameters
    ----------
    result : Reconstruction, CloudResult or MultiviewResult
        Told apart by ``result_kind``.

    Returns
    -------
    dict
        ``planes.json`` (a frame or a cloud) or ``scene.json`` (a multi-view result) content.

    Raises
    ------
    InvalidInput
        A result of another kind (a bare :class:`~monoplane.datamodel.Scene` lacks the SfM
        and alignments ``scene.json`` reports).
    """
    kind = getattr(result, "result_kind", "")
    if kind not in _DOCUMENTS:
        raise InvalidInput(f"no plane document for a {type(result).__name__} (result kind "
                           f"{kind!r}); give a result of kind {', '.join(_DOCUMENTS)}")
    return _DOCUMENTS[kind](result)


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


def scene_document(result: Any) -> dict[str, Any]:
    """``scene.json`` content of a multi-view result (:func:`planes_document` of it)."""
    return _multiview_document(result)


def write_json(path: Path, doc: dict[str, Any]) -> None:
    """Write ``doc`` as indented JSON with a final newline (every JSON file of the outputs)."""
    path.write_text(json.dumps(doc, indent=2) + "\n")


def _write(result: Any, folder: Path, shared: SharedWork) -> None:
    import cv2

    kind = result.result_kind
    if kind == "frame":
        if result.num_planes > np.iinfo(np.uint16).max:
            raise InvalidInput(f"{result.num_planes} planes do not fit in a uint16 labels.png")
        cv2.imwrite(str(folder / "labels.png"), result.labels.astype(np.uint16))
        write_json(folder / "planes.json",
                   {**planes_document(result), "monoplane_version": __version__})
    elif kind == "cloud":
        np.save(folder / "labels.npy", result.labels)
        write_json(folder / "planes.json", planes_document(result))
    else:

        scene = result.scene
        for v, (rec, links) in enumerate(zip(scene.views, scene.links, strict=True)):
            cv2.imwrite(str(folder / f"view_{v:03d}" / "labels_global.png"),
                        global_label_map(rec.labels, links))
        write_json(folder / "scene.json", planes_document(result))
        write_json(folder / "cameras.json", cameras_document(scene.cameras, result.registration,
                                                             result.unregistered))


EXPORTER = Exporter(
    name="labels",
    files={"frame": ("labels.png", "planes.json"), "cloud": ("labels.npy", "planes.json"),
           "multiview": ("scene.json", "cameras.json", "view_*/labels_global.png")},
    write=_write,
    summary="label maps and the planes as JSON (planes.json, scene.json, cameras.json)",
)


@hookimpl
def monoplane_register_exporters() -> list[Exporter]:
    return [EXPORTER]
