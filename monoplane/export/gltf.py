"""The ``gltf`` output format: plane meshes as glTF 2.0 binary scenes (``.glb``), one mesh node
per plane: ``planes.glb`` of a frame or a point cloud, ``scene.glb`` of a multi-view result.

What a monoplane ``.glb`` holds
-------------------------------
* One scene with one root node, ``monoplane``, which carries the frame conversion below.
* Under it, one node per plane, ``plane_<id>``, with the id of ``planes.json`` and
  ``labels.png`` (the 0-based global id of ``scene.json`` for a multi-view scene). Its mesh,
  also ``plane_<id>``, is one indexed triangle primitive: ``POSITION``, ``NORMAL`` (the plane's
  normal) and ``COLOR_0`` (the plane's palette colour, the colour of the report's label maps,
  stored linear as glTF requires). The node's ``extras`` hold ``plane_id``, ``normal`` and
  ``offset`` (``normal · X + offset = 0`` in the source frame). A plane too small to outline
  gets its node but no mesh.
* With cameras (multi-view): a node ``camera_<i>`` per view ``i`` (the ``view_<iii>`` folder)
  holding a glTF perspective camera placed at that view's pose, its ``extras`` naming the image,
  and a line mesh ``frustum_<i>`` that draws the camera's viewing pyramid (view 0 red, the
  others dark grey), since viewers do not draw glTF cameras.
* One material for all planes (white, fully rough, not metallic) that the vertex colours tint.
  Planes are one-sided where their normals face the cameras (``run``, ``batch``,
  ``multiview``): seen from outside a room, its walls then hide themselves like a doll's
  house. Point-cloud planes are two-sided, as a cloud has no camera.

Frames
------
Vertices are stored exactly in the frame of the accompanying JSON (the camera frame of
``planes.json``: x right, y down, z forward, depth units; the SfM world of ``scene.json``; a
point cloud's own frame). glTF's frame is y up, with a camera looking down -z. The root node's
rotation, the quaternion (x, y, z, w) = (1, 0, 0, 0), a half turn about x, turns one into the
other: ``(x, y, z) -> (x, -y, -z)``. A viewer that opens the file therefore shows an image's
planes upright, seen from where the input camera stood, and a script that reads the accessors
directly gets ``planes.json`` coordinates back.

Why a writer of our own: a ``.glb`` is a 12-byte header, a JSON chunk and a binary chunk;
writing them takes less code than adapting our meshes to a library's scene objects, and adds
no dependency. The tests read the files back with two independent readers, trimesh and
pygltflib.
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from monoplane.contracts.exporter import Exporter
from monoplane.datamodel import Camera, CloudResult, Reconstruction, Scene
from monoplane.export.shared import SharedWork
from monoplane.geometry.camera import frustum
from monoplane.geometry.cloud_mesh import cloud_mesh
from monoplane.geometry.mesh import scene_mesh
from monoplane.geometry.polygons import PlaneMesh, reconstruction_mesh
from monoplane.hookspecs import hookimpl
from monoplane.palette import plane_palette
from monoplane.version import __version__

#: Name of the root node that carries the frame conversion.
ROOT_NODE = "monoplane"
#: Rotation of the root node, quaternion (x, y, z, w): a half turn about x,
#: ``(x, y, z) -> (x, -y, -z)``, from OpenCV camera axes to glTF's y-up frame.
SOURCE_TO_GLTF_ROTATION = (1.0, 0.0, 0.0, 0.0)
#: The same rotation as a matrix.
SOURCE_TO_GLTF = np.diag([1.0, -1.0, -1.0])

_FLOAT, _UINT32 = 5126, 5125  # accessor component types
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963  # buffer view targets
_LINES, _TRIANGLES = 1, 4  # primitive modes
_GLB_MAGIC, _GLB_VERSION = 0x46546C67, 2  # "glTF"
_JSON_CHUNK, _BIN_CHUNK = 0x4E4F534A, 0x004E4942  # "JSON", "BIN\0"
_FIRST_CAMERA_RGB = (217, 26, 26)  # the scene report's colours: view 1 red, the others dark
_OTHER_CAMERA_RGB = (26, 26, 26)


def srgb_to_linear(rgb: np.ndarray) -> np.ndarray:
    """Convert 8-bit sRGB colours to the linear values glTF stores.

    Parameters
    ----------
    rgb : numpy.ndarray
        (..., 3) uint8 sRGB.

    Returns
    -------
    numpy.ndarray
        (..., 3) float32 linear RGB in [0, 1] (the sRGB transfer function undone).
    """
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


class _Document:
    """A glTF document and its one binary buffer, filled in build order."""

    def __init__(self) -> None:
        self.json: dict[str, Any] = {
            "asset": {"version": "2.0", "generator": f"monoplane {__version__}"},
            "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [], "meshes": [],
            "materials": [], "accessors": [], "bufferViews": [], "buffers": [],
        }
        self.bin = bytearray()

    def add(self, kind: str, item: dict[str, Any]) -> int:
        """Append ``item`` to the top-level array ``kind``; returns its index."""
        self.json.setdefault(kind, []).append(item)
        return len(self.json[kind]) - 1

    def accessor(self, data: np.ndarray, target: int) -> int:
        """Store ``data`` in the buffer and describe it.

        ``data`` is (N, 3) float32 (a VEC3 attribute, with its bounds, which glTF requires for
        positions) or (M,) uint32 (indices).
        """
        data = np.ascontiguousarray(data)
        self.bin += bytes(-len(self.bin) % 4)  # every view starts 4-byte aligned
        view = self.add("bufferViews", {"buffer": 0, "byteOffset": len(self.bin),
                                        "byteLength": data.nbytes, "target": target})
        self.bin += data.astype(data.dtype.newbyteorder("<")).tobytes()
        item: dict[str, Any] = {"bufferView": view, "count": int(len(data))}
        if data.ndim == 2:
            item.update(componentType=_FLOAT, type="VEC3", min=data.min(0).tolist(),
                        max=data.max(0).tolist())
        else:
            item.update(componentType=_UINT32, type="SCALAR")
        return self.add("accessors", item)

    def glb(self) -> bytes:
        """The binary file: header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
        doc = {k: v for k, v in self.json.items() if v != []}  # glTF forbids empty arrays
        if self.bin:
            doc["buffers"] = [{"byteLength": len(self.bin)}]
        text = json.dumps(doc, separators=(",", ":")).encode()
        text += b" " * (-len(text) % 4)
        chunks = struct.pack("<II", len(text), _JSON_CHUNK) + text
        if self.bin:
            data = bytes(self.bin) + bytes(-len(self.bin) % 4)
            chunks += struct.pack("<II", len(data), _BIN_CHUNK) + data
        return struct.pack("<III", _GLB_MAGIC, _GLB_VERSION, 12 + len(chunks)) + chunks


def _frustum_depth(vertices: np.ndarray, cameras: Sequence[Camera]) -> float:
    """Depth of the drawn camera pyramids: a fifth of the scene's radius (as the report's)."""
    pts = vertices if len(vertices) else np.array([c.center for c in cameras])
    radius = float(np.percentile(np.linalg.norm(pts - np.median(pts, 0), axis=1), 90))
    return 0.2 * radius if radius > 0 else 1.0


def planes_glb(mesh: PlaneMesh, planes: np.ndarray, colors: np.ndarray, first_id: int = 1, *,
               cameras: Sequence[Camera] = (), double_sided: bool = False) -> bytes:
    """Build a ``.glb`` with one mesh node per plane (and the cameras, if any).

    Parameters
    ----------
    mesh : PlaneMesh
        Triangles tagged with plane ids, in the source frame (see the module notes); each
        triangle's right-hand normal is its plane's normal.
    planes : numpy.ndarray
        (P, 4) ``n · X + d = 0`` of plane id ``first_id + i`` at row ``i``, source frame.
    colors : numpy.ndarray
        (P, 3) uint8 sRGB colour of each plane, rows as ``planes``.
    first_id : int
        Id of the first plane: 1 for label values, 0 for a scene's global planes.
    cameras : sequence of Camera
        World-to-camera poses (``x_cam = R x_world + t``, OpenCV axes) to add as cameras and
        frusta; the source frame is then that world.
    double_sided : bool
        Draw planes from both sides (for point clouds, whose normals face no camera).

    Returns
    -------
    bytes
        The ``.glb`` file.
    """
    planes = np.asarray(planes, dtype=np.float64).reshape(-1, 4)
    linear = srgb_to_linear(np.asarray(colors, dtype=np.uint8).reshape(-1, 3))
    doc = _Document()
    root: dict[str, Any] = {
        "name": ROOT_NODE, "rotation": list(SOURCE_TO_GLTF_ROTATION), "children": [],
        "extras": {"frame": "children are in the frame of the accompanying JSON (camera: x "
                            "right, y down, z forward); this node's half turn about x maps "
                            "(x, y, z) to glTF's y-up (x, -y, -z)"}}
    doc.add("nodes", root)
    material = doc.add("materials", {
        "name": "planes", "doubleSided": double_sided,
        "pbrMetallicRoughness": {"baseColorFactor": [1.0, 1.0, 1.0, 1.0],
                                 "metallicFactor": 0.0, "roughnessFactor": 1.0}})
    for row, plane in enumerate(planes):
        pid = row + first_id
        node: dict[str, Any] = {"name": f"plane_{pid}", "extras": {
            "plane_id": pid, "normal": plane[:3].tolist(), "offset": float(plane[3])}}
        tris = mesh.triangles[mesh.plane_ids == pid]
        if len(tris):
            used, inverse = np.unique(tris, return_inverse=True)
            n = len(used)
            normal = (plane[:3] / np.linalg.norm(plane[:3])).astype(np.float32)
            attributes = {
                "POSITION": doc.accessor(mesh.vertices[used].astype(np.float32), _ARRAY_BUFFER),
                "NORMAL": doc.accessor(np.tile(normal, (n, 1)), _ARRAY_BUFFER),
                "COLOR_0": doc.accessor(np.tile(linear[row], (n, 1)), _ARRAY_BUFFER),
            }
            indices = doc.accessor(inverse.reshape(-1).astype(np.uint32), _ELEMENT_ARRAY_BUFFER)
            node["mesh"] = doc.add("meshes", {"name": f"plane_{pid}", "primitives": [{
                "attributes": attributes, "indices": indices, "material": material,
                "mode": _TRIANGLES}]})
        root["children"].append(doc.add("nodes", node))
    if cameras:
        _add_cameras(doc, root, cameras, _frustum_depth(mesh.vertices, cameras))
    if not root["children"]:
        del root["children"]  # glTF forbids empty arrays
    return doc.glb()


def _add_cameras(doc: _Document, root: dict[str, Any], cameras: Sequence[Camera],
                 depth: float) -> None:
    """Add a glTF camera node and a frustum line mesh per camera under ``root``."""
    first = doc.add("materials", {"name": "camera_first", "pbrMetallicRoughness": {
        "baseColorFactor": [*srgb_to_linear(np.array(_FIRST_CAMERA_RGB)).tolist(), 1.0]}})
    other = doc.add("materials", {"name": "camera", "pbrMetallicRoughness": {
        "baseColorFactor": [*srgb_to_linear(np.array(_OTHER_CAMERA_RGB)).tolist(), 1.0]}})
    for i, cam in enumerate(cameras):
        fx, fy = cam.K[0, 0], cam.K[1, 1]
        lens = doc.add("cameras", {"type": "perspective", "name": f"camera_{i}", "perspective": {
            "yfov": 2.0 * math.atan(cam.height / (2.0 * fy)),
            "aspectRatio": (cam.width * fy) / (cam.height * fx),
            "znear": depth / 100.0}})
        # A glTF camera looks down its -z with y up; SOURCE_TO_GLTF turns those axes into
        # OpenCV's, and R^T then into the world: camera-to-world = [R^T F | centre].
        pose = np.eye(4)
        pose[:3, :3] = cam.R.T @ SOURCE_TO_GLTF
        pose[:3, 3] = cam.center
        root["children"].append(doc.add("nodes", {
            "name": f"camera_{i}", "camera": lens, "matrix": pose.T.reshape(-1).tolist(),
            "extras": {"image": cam.name, "width": int(cam.width), "height": int(cam.height),
                       "K": np.asarray(cam.K).tolist()}}))
        points, edges = frustum(cam.K, cam.R, cam.t, cam.width, cam.height, depth)
        lines = doc.add("meshes", {"name": f"frustum_{i}", "primitives": [{
            "attributes": {"POSITION": doc.accessor(points.astype(np.float32), _ARRAY_BUFFER)},
            "indices": doc.accessor(edges.reshape(-1).astype(np.uint32),
                                    _ELEMENT_ARRAY_BUFFER),
            "material": first if i == 0 else other, "mode": _LINES}]})
        root["children"].append(doc.add("nodes", {"name": f"frustum_{i}", "mesh": lines}))


def reconstruction_glb(rec: Reconstruction, mesh: PlaneMesh | None = None) -> bytes:
    """``planes.glb`` of one view: its plane regions in the camera frame, palette colours.

    Parameters
    ----------
    rec : Reconstruction
        Labels and planes of one frame (camera frame, depth units).
    mesh : PlaneMesh, optional
        :func:`~monoplane.geometry.polygons.reconstruction_mesh` of ``rec``, when the caller
        already has it (it is also what ``planes.ply`` holds).

    Returns
    -------
    bytes
        The ``.glb`` file; plane ids are the label values 1..P.
    """
    if mesh is None:
        mesh = reconstruction_mesh(rec)
    return planes_glb(mesh, rec.planes, plane_palette(rec.num_planes))


def scene_glb(scene: Scene, mesh: PlaneMesh | None = None) -> bytes:
    """``scene.glb`` of a multi-view scene: fused planes and cameras in the world frame.

    Parameters
    ----------
    scene : Scene
        Fused scene: global planes in the SfM world frame, world-to-camera poses.
    mesh : PlaneMesh, optional
        :func:`~monoplane.geometry.mesh.scene_mesh` of ``scene``, when the caller already
        has it (it is also what ``scene.ply`` holds).

    Returns
    -------
    bytes
        The ``.glb`` file; plane ids are the 0-based global ids of ``scene.json``.
    """
    if mesh is None:
        mesh = scene_mesh(scene)
    return planes_glb(mesh, scene.planes, plane_palette(scene.planes.shape[0]), first_id=0,
                      cameras=scene.cameras)


def cloud_glb(result: CloudResult, mesh: PlaneMesh | None = None) -> bytes:
    """``planes.glb`` of a point cloud: two-sided planes in the cloud's frame, palette colours.

    ``mesh`` is :func:`~monoplane.geometry.cloud_mesh.cloud_mesh` of the result when the caller
    already has it.
    """
    if mesh is None:
        mesh = cloud_mesh(result)
    return planes_glb(mesh, result.planes, plane_palette(result.num_planes), double_sided=True)


def _write(result: Any, folder: Path, shared: SharedWork) -> None:
    kind = result.result_kind
    mesh = shared.mesh(result)
    if kind == "frame":
        (folder / "planes.glb").write_bytes(reconstruction_glb(result, mesh))
    elif kind == "cloud":
        (folder / "planes.glb").write_bytes(cloud_glb(result, mesh))
    else:
        (folder / "scene.glb").write_bytes(scene_glb(result.scene, mesh))


EXPORTER = Exporter(
    name="gltf",
    files={"frame": ("planes.glb",), "cloud": ("planes.glb",), "multiview": ("scene.glb",)},
    write=_write,
    summary="plane meshes as glTF binary (one node per plane; a scene's cameras too)",
)


@hookimpl
def monoplane_register_exporters() -> list[Exporter]:
    return [EXPORTER]
