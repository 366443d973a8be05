"""``planes.ply``: plane regions with holes, one plane id per face, readable by common readers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from monoplane.datamodel import Frame, Reconstruction, intrinsics_matrix
from monoplane.export import save

_SCALARS = {"char": int, "uchar": int, "short": int, "ushort": int, "int": int, "uint": int,
            "int8": int, "uint8": int, "int16": int, "uint16": int, "int32": int, "uint32": int,
            "float": float, "double": float, "float32": float, "float64": float}


def read_ascii_ply(path: Path) -> dict[str, list[dict[str, object]]]:
    """A small PLY reader written from the format description (as MeshLab and most tools read
    it): the header declares elements, each with scalar or list properties, in order; the body
    lists each element's rows. Returns ``{element: [{property: value}, ...]}``."""
    lines = path.read_text().splitlines()
    assert lines[0] == "ply" and lines[1] == "format ascii 1.0", lines[:2]
    elements: list[tuple[str, int, list[tuple[str, str, str | None]]]] = []
    body_start = None
    for k, line in enumerate(lines[2:], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and words[1] == "list":
            assert words[2] in _SCALARS and words[3] in _SCALARS
            elements[-1][2].append((words[4], words[3], words[2]))
        elif words[0] == "property":
            assert words[1] in _SCALARS, words
            elements[-1][2].append((words[2], words[1], None))
        elif words[0] == "end_header":
            body_start = k + 1
            break
        else:
            raise AssertionError(f"unexpected header line {line!r}")
    assert body_start is not None
    rows = iter(lines[body_start:])
    out: dict[str, list[dict[str, object]]] = {}
    for name, count, props in elements:
        out[name] = []
        for _ in range(count):
            tokens = next(rows).split()
            row: dict[str, object] = {}
            for prop, tp, count_tp in props:
                if count_tp is not None:
                    n = int(tokens.pop(0))
                    row[prop] = [_SCALARS[tp](t) for t in tokens[:n]]
                    del tokens[:n]
                else:
                    row[prop] = _SCALARS[tp](tokens.pop(0))
            assert not tokens, f"{name} row has extra values"
            out[name].append(row)
    assert next(rows, None) is None, "data after the last element"
    return out


@pytest.fixture
def wall_and_box(tmp_path: Path) -> tuple[Path, np.ndarray, np.ndarray]:
    """Outputs of a wall (z = 4) with a box face (z = 2) in front of it, and the box mask."""
    K = intrinsics_matrix(100.0, 100.0, 49.5, 39.5)
    labels = np.ones((80, 100), np.int32)
    box = np.zeros_like(labels, bool)
    box[25:55, 30:70] = True
    labels[box] = 2
    rgb = np.zeros((80, 100, 3), np.uint8)
    rgb[~box] = (200, 50, 50)
    rgb[box] = (20, 20, 220)
    planes = np.array([[0.0, 0.0, -1.0, 4.0], [0.0, 0.0, -1.0, 2.0]])
    rec = Reconstruction(frame=Frame(rgb=rgb, K=K), labels=labels, planes=planes)
    out = save(rec, tmp_path / "out")
    return out, K, box


def test_faces_carry_plane_ids_and_holes_stay_open(wall_and_box) -> None:
    out, K, box = wall_and_box
    ply = read_ascii_ply(out / "planes.ply")
    doc = json.loads((out / "planes.json").read_text())
    planes = {p["id"]: p for p in doc["planes"]}
    vertices = np.array([[v["x"], v["y"], v["z"]] for v in ply["vertex"]])
    assert {f["plane_id"] for f in ply["face"]} == set(planes) == {1, 2}
    for face in ply["face"]:
        idx = face["vertex_indices"]
        assert len(idx) == 3
        plane = planes[face["plane_id"]]
        corners = vertices[idx]
        np.testing.assert_allclose(corners @ plane["normal"] + plane["offset"], 0, atol=1e-5)
        assert [face["red"], face["green"], face["blue"]] == plane["color"]
        # Right-hand normal along the plane normal, i.e. facing the camera.
        assert np.cross(corners[1] - corners[0], corners[2] - corners[0]) @ plane["normal"] > 0
        if face["plane_id"] == 1:  # the wall's triangles never cover the box
            uv = K @ corners.mean(axis=0)
            u, v = np.round(uv[:2] / uv[2]).astype(int)
            assert not box[v, u]


def test_open3d_loads_the_mesh(wall_and_box) -> None:
    import open3d as o3d

    out, _, _ = wall_and_box
    ply = read_ascii_ply(out / "planes.ply")
    mesh = o3d.io.read_triangle_mesh(str(out / "planes.ply"))
    assert len(mesh.triangles) == len(ply["face"]) > 0
    assert len(mesh.vertices) == len(ply["vertex"])
    np.testing.assert_array_equal(np.asarray(mesh.triangles),
                                  [f["vertex_indices"] for f in ply["face"]])
    colors = np.asarray(mesh.vertex_colors)
    assert colors.shape == (len(mesh.vertices), 3)
    assert np.allclose(colors.max(axis=0), [200 / 255, 50 / 255, 220 / 255], atol=1e-6)
