"""Rerun recordings of monoplane results: :func:`log_rerun` and the commands' ``--rerun FILE.rrd``.

Rerun (``rerun-sdk``) is an optional extra: ``pip install 'monoplane[rerun]'``. Open a recording
with ``rerun FILE.rrd``. As the ``rerun`` output format (off by default: ``save(...,
formats=[..., "rerun"])``) it writes ``recording.rrd`` into the output folder.

Entities
--------
One view (``monoplane run``, every frame of ``monoplane batch``):

==============================  ============================================================
``world``                       view coordinates RDF (the camera frame: x right, y down,
                                z forward) and the annotation context: class 0
                                ``non-planar``, class ``p`` ``plane_<p>`` in the plane
                                palette (the colours of the report's label maps)
``world/camera``                pinhole camera (K, image size) at the origin
``world/camera/image``          the RGB image
``world/camera/depth``          the depth cue, in the frame's depth units (``meter`` = 1)
``world/camera/labels``         the label map (``labels.png``) as a segmentation image
``world/points``                the depth's points, in image colours, class id = plane id
``world/planes/plane_<p>``      plane ``p``'s mesh (the triangles of ``planes.glb``)
==============================  ============================================================

Several views (``monoplane multiview``), in the SfM world frame (also logged as RDF: it is the
frame of the first cameras); class ``g + 1`` is global plane ``g``, named ``plane_<g>``:
``world/sfm_points`` (sparse points), ``world/view_<iii>`` (camera pose and pinhole),
``world/view_<iii>/image``, ``…/depth`` (scaled onto the SfM model), ``…/labels`` (global plane
id + 1, as ``labels_global.png``), ``world/points/view_<iii>`` (that view's depth points in the
world) and ``world/planes/plane_<g>`` (the triangles of ``scene.glb``).

A point cloud (``monoplane cloud``), in its own frame: ``world/points`` (input colours, or the
plane palette by class id when the cloud has none) and ``world/planes/plane_<p>``.

Point clouds are thinned on a regular pixel grid to at most :data:`MAX_POINTS` points per view,
which keeps a batch recording's size in check.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np

from monoplane.contracts.exporter import Exporter
from monoplane.datamodel import CloudResult, Reconstruction, Scene, global_label_map
from monoplane.errors import InvalidInput, MonoplaneError
from monoplane.export.shared import SharedWork
from monoplane.geometry.cloud_mesh import cloud_mesh
from monoplane.geometry.mesh import scene_mesh
from monoplane.geometry.polygons import PlaneMesh, reconstruction_mesh
from monoplane.hookspecs import hookimpl
from monoplane.palette import NON_PLANAR, plane_palette

#: Most points logged per view (depth pixels are taken on a regular grid to stay below it).
MAX_POINTS = 200_000
#: Application id of monoplane's recordings.
APPLICATION_ID = "monoplane"


class MissingExtra(MonoplaneError):
    """An optional dependency that a requested feature needs is not installed."""


def require_rerun() -> ModuleType:
    """Import the Rerun SDK, or raise a one-line error naming the extra that provides it."""
    try:
        import rerun
    except ImportError:
        raise MissingExtra("--rerun needs the Rerun SDK: pip install 'monoplane[rerun]'") from None
    return rerun


def check_recording_path(path: str | Path) -> Path:
    """Check a ``--rerun`` target before any work: a ``.rrd`` file name in a writable place.

    Raises
    ------
    InvalidInput
        One line: wrong suffix, an existing folder, or a parent that is a file.
    MissingExtra
        The Rerun SDK is not installed.
    """
    p = Path(path)
    if p.suffix != ".rrd":
        raise InvalidInput(f"--rerun {p}: a Rerun recording needs the suffix .rrd")
    if p.is_dir():
        raise InvalidInput(f"--rerun {p} is a folder; give a file name ending in .rrd")
    parent = next((q for q in p.parents if q.exists()), Path("."))
    if not parent.is_dir():
        raise InvalidInput(f"cannot write {p}: {parent} is a file, not a folder")
    require_rerun()
    return p


@contextlib.contextmanager
def recording_file(path: str | Path) -> Iterator[Any]:
    """Yield a new recording that is saved to ``path`` only if the block succeeds.

    The stream writes into a temporary sibling file, which is renamed over ``path`` once the
    block has returned and everything is flushed: a failed or interrupted run leaves no
    half-written ``.rrd``. Missing parent folders are created.

    Yields
    ------
    rerun.RecordingStream
    """
    rr = require_rerun()
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".partial", dir=target.parent)
    os.close(fd)
    stream = rr.RecordingStream(APPLICATION_ID)
    try:
        stream.save(tmp)
        yield stream
        stream.flush()
        stream.disconnect()
        os.chmod(tmp, 0o644)  # mkstemp makes it private; a recording is meant to be shared
        os.replace(tmp, target)
    except BaseException:
        stream.disconnect()
        Path(tmp).unlink(missing_ok=True)
        raise


def log_rerun(result: Any, path: str | Path | None = None, *, recording: Any = None,
              entity: str = "world") -> Any:
    """Log a monoplane result to Rerun.

    Parameters
    ----------
    result : Reconstruction, MultiviewResult, Scene or CloudResult
        What ``monoplane run``/``batch``, ``multiview`` or ``cloud`` computed (see the module
        notes for the entities of each).
    path : str or Path, optional
        Write a ``.rrd`` file (atomically: complete or not at all).
    recording : rerun.RecordingStream, optional
        Log into this stream instead (for example one you have ``spawn()``-ed or ``serve``-d,
        or one that a loop logs many frames into under ``set_time``).
    entity : str
        Root entity path.

    Returns
    -------
    rerun.RecordingStream
        The stream logged into. With neither ``path`` nor ``recording`` it is a new stream
        that holds the data until you give it a sink (``.save(path)``, ``.spawn()``).

    Raises
    ------
    MissingExtra
        The Rerun SDK is not installed.
    InvalidInput
        ``result`` is none of the types above.
    """
    rr = require_rerun()
    if recording is not None:
        _log_any(rr, recording, result, entity)
        return recording
    if path is not None:
        with recording_file(path) as stream:
            _log_any(rr, stream, result, entity)
        return stream
    stream = rr.RecordingStream(APPLICATION_ID)
    _log_any(rr, stream, result, entity)
    return stream


def _log_any(rr: ModuleType, stream: Any, result: Any, entity: str) -> None:
    """Log ``result`` by what its ``result_kind`` says it is."""
    kind = getattr(result, "result_kind", "")
    if kind == "frame":
        log_reconstruction(rr, stream, result, entity)
    elif kind == "scene":
        log_scene(rr, stream, result, None, entity)
    elif kind == "multiview":
        log_scene(rr, stream, result.scene, result.sfm.colors, entity)
    elif kind == "cloud":
        log_cloud(rr, stream, result, entity)
    else:
        raise InvalidInput(f"log_rerun: cannot log a {type(result).__name__}; give a "
                           "Reconstruction, MultiviewResult, Scene or CloudResult")


def annotation_context(rr: ModuleType, num_planes: int, first_id: int = 1) -> Any:
    """The plane palette as an annotation context.

    Class 0 is ``non-planar``; palette row ``i`` is class ``i + 1``, named
    ``plane_<i + first_id>`` (``first_id`` 1 for label values, 0 for a scene's global planes,
    whose label maps hold global id + 1).
    """
    classes = [rr.AnnotationInfo(id=0, label="non-planar", color=NON_PLANAR.tolist())]
    classes += [rr.AnnotationInfo(id=i + 1, label=f"plane_{i + first_id}", color=rgb.tolist())
                for i, rgb in enumerate(plane_palette(num_planes))]
    return rr.AnnotationContext(classes)


def _grid_step(height: int, width: int) -> int:
    """Pixel stride that keeps one view's points under :data:`MAX_POINTS`."""
    return max(1, int(np.ceil(np.sqrt(height * width / MAX_POINTS))))


def log_plane_meshes(rr: ModuleType, stream: Any, mesh: PlaneMesh, planes: np.ndarray,
                     first_id: int, entity: str) -> None:
    """Log ``entity/planes/plane_<id>``, one mesh per plane in its palette colour, after
    clearing ``entity/planes`` (so that a frame logged after another keeps none of its
    planes)."""
    palette = plane_palette(len(planes))
    stream.log(f"{entity}/planes", rr.Clear(recursive=True))
    for row, plane in enumerate(planes):
        pid = row + first_id
        tris = mesh.triangles[mesh.plane_ids == pid]
        if not len(tris):
            continue
        used, inverse = np.unique(tris, return_inverse=True)
        normal = plane[:3] / np.linalg.norm(plane[:3])
        stream.log(f"{entity}/planes/plane_{pid}", rr.Mesh3D(
            vertex_positions=mesh.vertices[used].astype(np.float32),
            triangle_indices=inverse.reshape(-1, 3).astype(np.uint32),
            vertex_normals=np.tile(normal.astype(np.float32), (len(used), 1)),
            vertex_colors=np.tile(palette[row], (len(used), 1))))


def _log_view_images(rr: ModuleType, stream: Any, rec: Reconstruction, labels: np.ndarray,
                     path: str) -> None:
    """Pinhole, image, depth and label map of one view under ``path``."""
    frame = rec.frame
    stream.log(path, rr.Pinhole(image_from_camera=frame.K, resolution=[frame.width,
                                                                       frame.height],
                                camera_xyz=rr.ViewCoordinates.RDF))
    if frame.rgb is not None:
        stream.log(f"{path}/image", rr.Image(frame.rgb))
    if frame.depth is not None:
        stream.log(f"{path}/depth", rr.DepthImage(frame.depth.astype(np.float32), meter=1.0))
    stream.log(f"{path}/labels", rr.SegmentationImage(labels.astype(np.uint16)))


def _view_points(rec: Reconstruction, labels: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Camera-frame points of a view's valid depth on a thinning grid, with their colours and
    class ids: (N, 3) float32, (N, 3) uint8 or None, (N,) uint16."""
    frame = rec.frame
    if frame.depth is None:
        return np.zeros((0, 3), np.float32), None, np.zeros(0, np.uint16)
    s = _grid_step(*frame.shape)
    valid = frame.depth[::s, ::s] > 0
    points = frame.points()[::s, ::s][valid].astype(np.float32)
    colors = None if frame.rgb is None else frame.rgb[::s, ::s][valid]
    return points, colors, labels[::s, ::s][valid].astype(np.uint16)


def log_reconstruction(rr: ModuleType, stream: Any, rec: Reconstruction,
                       entity: str = "world", mesh: PlaneMesh | None = None) -> None:
    """Log one view (see the module notes); ``mesh`` is ``reconstruction_mesh(rec)`` when the
    caller has it."""
    stream.log(entity, rr.ViewCoordinates.RDF, static=True)
    stream.log(entity, annotation_context(rr, rec.num_planes))
    _log_view_images(rr, stream, rec, rec.labels, f"{entity}/camera")
    points, colors, classes = _view_points(rec, rec.labels)
    stream.log(f"{entity}/points", rr.Points3D(points, colors=colors, class_ids=classes))
    log_plane_meshes(rr, stream, reconstruction_mesh(rec) if mesh is None else mesh,
                     rec.planes, 1, entity)


def log_scene(rr: ModuleType, stream: Any, scene: Scene, sfm_colors: np.ndarray | None,
              entity: str = "world") -> None:
    """Log a multi-view scene (see the module notes); ``sfm_colors`` are the (M, 3) uint8
    colours of ``scene.points``, if known."""
    G = scene.planes.shape[0]
    stream.log(entity, rr.ViewCoordinates.RDF, static=True)
    stream.log(entity, annotation_context(rr, G, first_id=0))
    stream.log(f"{entity}/sfm_points", rr.Points3D(np.asarray(scene.points, np.float32),
                                                   colors=sfm_colors))
    for v, (cam, rec, links) in enumerate(zip(scene.cameras, scene.views, scene.links,
                                              strict=True)):
        path = f"{entity}/view_{v:03d}"
        stream.log(path, rr.Transform3D(translation=cam.center, mat3x3=cam.R.T))
        labels = global_label_map(rec.labels, links)
        _log_view_images(rr, stream, rec, labels, path)
        points, colors, classes = _view_points(rec, labels)
        stream.log(f"{entity}/points/view_{v:03d}", rr.Points3D(
            (points - cam.t) @ cam.R, colors=colors, class_ids=classes))
    log_plane_meshes(rr, stream, scene_mesh(scene), scene.planes, 0, entity)


def log_cloud(rr: ModuleType, stream: Any, result: CloudResult, entity: str = "world") -> None:
    """Log a point cloud's planes (see the module notes); ``result`` is a CloudResult."""
    stream.log(entity, annotation_context(rr, result.num_planes))
    finite = np.isfinite(result.points).all(axis=1)
    colors = None
    if result.colors is not None:
        colors = np.clip(np.round(result.colors[finite] * 255), 0, 255).astype(np.uint8)
    stream.log(f"{entity}/points", rr.Points3D(result.points[finite].astype(np.float32),
                                               colors=colors,
                                               class_ids=result.labels[finite].astype(np.uint16)))
    log_plane_meshes(rr, stream, cloud_mesh(result), result.planes, 1, entity)


def _write(result: Any, folder: Path, shared: SharedWork) -> None:
    log_rerun(result, folder / "recording.rrd")


EXPORTER = Exporter(
    name="rerun",
    files={"frame": ("recording.rrd",), "cloud": ("recording.rrd",),
           "multiview": ("recording.rrd",)},
    write=_write,
    default=False,  # an optional extra, and a viewer's file rather than a result
    summary="a Rerun recording, recording.rrd (needs the 'rerun' extra)",
)


@hookimpl
def monoplane_register_exporters() -> list[Exporter]:
    return [EXPORTER]
