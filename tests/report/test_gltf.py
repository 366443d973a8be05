"""``planes.glb`` / ``scene.glb``: read back with two independent readers (trimesh, pygltflib),
one mesh per plane with its id, palette colours, and the documented frame, checked numerically."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pygltflib
import pytest
import trimesh
from report_fixtures import make_scene

from monoplane.datamodel import Reconstruction
from monoplane.export import save
from monoplane.export.gltf import SOURCE_TO_GLTF, reconstruction_glb, scene_glb
from monoplane.geometry.polygons import reconstruction_mesh
from monoplane.report.colors import plane_palette


def _accessor(gltf: pygltflib.GLTF2, index: int) -> np.ndarray:
    """The data of a float VEC3 or uint32 SCALAR accessor, read straight from the buffer."""
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    raw = gltf.binary_blob()[view.byteOffset + (acc.byteOffset or 0):][:view.byteLength]
    if acc.componentType == pygltflib.FLOAT:
        return np.frombuffer(raw, "<f4").reshape(acc.count, 3)
    assert acc.componentType == pygltflib.UNSIGNED_INT
    return np.frombuffer(raw, "<u4").reshape(acc.count)


def _linear_to_srgb8(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, dtype=np.float64)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return np.round(s * 255).astype(int)


def _load(path: Path) -> tuple[trimesh.Scene, pygltflib.GLTF2]:
    return trimesh.load(path, file_type="glb", force="scene"), pygltflib.GLTF2().load(str(path))


def test_planes_glb_has_one_mesh_per_plane_in_the_documented_frame(room, tmp_path: Path
                                                                    ) -> None:
    out = save(room, tmp_path / "out")
    path = out / "planes.glb"
    doc = json.loads((out / "planes.json").read_text())
    ids = [p["id"] for p in doc["planes"]]
    scene, gltf = _load(path)

    # One mesh, and one node holding it, per plane of planes.json, named by its id.
    names = [f"plane_{i}" for i in ids]
    assert sorted(scene.geometry) == sorted(names)
    assert [m.name for m in gltf.meshes] == names
    assert sorted(scene.graph.nodes_geometry) == sorted(names)
    assert gltf.nodes[gltf.scenes[0].nodes[0]].rotation == [1.0, 0.0, 0.0, 0.0]

    palette = plane_palette(len(ids))
    mesh = reconstruction_mesh(room)
    for k, plane in enumerate(doc["planes"]):
        pid, n, d = plane["id"], np.array(plane["normal"]), plane["offset"]
        node = next(nd for nd in gltf.nodes if nd.name == f"plane_{pid}")
        assert node.extras["plane_id"] == pid
        prim = gltf.meshes[node.mesh].primitives[0]
        raw = _accessor(gltf, prim.attributes.POSITION).astype(np.float64)
        # Stored in the camera frame of planes.json, on the plane, as the PLY's triangles.
        assert np.abs(raw @ n + d).max() < 1e-5
        assert len(_accessor(gltf, prim.indices)) == 3 * int((mesh.plane_ids == pid).sum())
        # trimesh applies the root node: glTF's y-up frame is (x, -y, -z) of the camera frame.
        transform, geometry = scene.graph[f"plane_{pid}"]
        world = trimesh.transform_points(scene.geometry[geometry].vertices, transform)
        assert np.allclose(world, raw @ SOURCE_TO_GLTF.T, atol=1e-6)
        assert np.all(world[:, 2] < 0)  # in front of a glTF camera at the origin (looks down -z)
        # Palette vertex colours, stored linear.
        colours = _accessor(gltf, prim.attributes.COLOR_0)
        assert np.all(_linear_to_srgb8(colours) == palette[k])
        normals = _accessor(gltf, prim.attributes.NORMAL)
        assert np.allclose(normals, n / np.linalg.norm(n), atol=1e-6)
    # The floor (plane 1, normal towards the camera above it) faces up in glTF.
    floor = np.array(doc["planes"][0]["normal"]) @ SOURCE_TO_GLTF.T
    assert floor[1] > 0.99


def test_glb_layout_is_valid_binary_gltf(room) -> None:
    data = reconstruction_glb(room)
    magic, version, length = struct.unpack_from("<III", data)
    assert (magic, version, length) == (0x46546C67, 2, len(data))
    json_len, json_type = struct.unpack_from("<II", data, 12)
    assert json_type == 0x4E4F534A and json_len % 4 == 0
    bin_len, bin_type = struct.unpack_from("<II", data, 20 + json_len)
    assert bin_type == 0x004E4942 and bin_len % 4 == 0 and 28 + json_len + bin_len == len(data)
    doc = json.loads(data[20:20 + json_len])
    assert doc["asset"]["version"] == "2.0"
    for view in doc["bufferViews"]:
        assert view["byteOffset"] % 4 == 0
        assert view["byteOffset"] + view["byteLength"] <= doc["buffers"][0]["byteLength"]
    assert all(v != [] for v in doc.values())


def test_a_reconstruction_without_planes_gives_a_valid_empty_scene(room, tmp_path: Path) -> None:
    empty = Reconstruction(frame=room.frame, labels=np.zeros(room.frame.shape, np.int32),
                           params=np.zeros((0, 4)))
    (tmp_path / "e.glb").write_bytes(reconstruction_glb(empty))
    scene, gltf = _load(tmp_path / "e.glb")
    assert len(scene.geometry) == 0 and len(gltf.nodes) == 1


def test_scene_glb_holds_global_planes_and_cameras(tmp_path: Path) -> None:
    from monoplane.geometry.mesh import scene_mesh

    sc = make_scene(2)
    mesh = scene_mesh(sc)
    (tmp_path / "scene.glb").write_bytes(scene_glb(sc, mesh))
    scene, gltf = _load(tmp_path / "scene.glb")
    meshed = sorted({int(g) for g in mesh.plane_ids})
    assert sorted(n for n in scene.geometry if n.startswith("plane_")) == sorted(
        f"plane_{g}" for g in meshed)  # 0-based global ids, as scene.json
    assert {f"plane_{g}" for g in range(sc.planes.shape[0])} <= {n.name for n in gltf.nodes}
    assert len(gltf.cameras) == 2
    for i, cam in enumerate(sc.cameras):
        node = next(nd for nd in gltf.nodes if nd.name == f"camera_{i}")
        assert node.extras["image"] == cam.name
        # Camera-to-glTF-world: the root's half turn after the node's own matrix.
        pose = np.array(node.matrix).reshape(4, 4).T
        to_gltf = SOURCE_TO_GLTF @ pose[:3, :3]
        assert np.allclose(SOURCE_TO_GLTF @ pose[:3, 3], SOURCE_TO_GLTF @ cam.center)
        # A glTF camera looks down its -z: that must be the camera's optical axis R^T z.
        assert np.allclose(to_gltf @ [0, 0, -1], SOURCE_TO_GLTF @ cam.R.T @ [0, 0, 1])
        assert np.allclose(to_gltf @ [0, 1, 0], SOURCE_TO_GLTF @ cam.R.T @ [0, -1, 0])
        # The drawn pyramid's apex is the camera centre, in trimesh's reading too.
        transform, geometry = scene.graph[f"frustum_{i}"]
        apex = trimesh.transform_points(scene.geometry[geometry].vertices[:1], transform)[0]
        assert np.allclose(apex, SOURCE_TO_GLTF @ cam.center, atol=1e-5)


@pytest.mark.parametrize("double_sided", [False, True])
def test_planes_are_one_sided_for_cameras_and_two_sided_for_clouds(room, double_sided: bool
                                                                    ) -> None:
    from monoplane.export.gltf import planes_glb

    data = planes_glb(reconstruction_mesh(room), room.params, plane_palette(room.num_planes),
                      double_sided=double_sided)
    gltf = pygltflib.GLTF2.load_from_bytes(data)
    assert gltf.materials[0].doubleSided is double_sided
