"""planar_mesh: vertices on their planes, triangles within one label, camera-facing winding."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.datamodel import Frame, Reconstruction, intrinsics_matrix
from monoplane.geometry.mesh import planar_mesh, reconstruction_to_open3d

H, W = 12, 16
K = intrinsics_matrix(20.0, 20.0, (W - 1) / 2, (H - 1) / 2)


def _rec(labels: np.ndarray, params: np.ndarray, depth: float | None = 2.0) -> Reconstruction:
    rgb = np.random.default_rng(1).integers(0, 255, (H, W, 3), dtype=np.uint8)
    d = None if depth is None else np.full((H, W), depth, np.float32)
    return Reconstruction(frame=Frame(rgb=rgb, K=K, depth=d), labels=labels, planes=params)


def test_fronto_parallel_plane_full_grid() -> None:
    rec = _rec(np.ones((H, W), np.int32), np.array([[0.0, 0.0, -1.0, 2.0]]))
    v, t, c, ids = planar_mesh(rec, step=1)
    assert v.shape == (H * W, 3) and t.shape == (2 * (H - 1) * (W - 1), 3)
    np.testing.assert_allclose(v[:, 2], 2.0)
    # Pixel (u, v) = (W - 1, 0) lifts to x = (u - cx) z / fx.
    np.testing.assert_allclose(v[W - 1, 0], (W - 1 - K[0, 2]) * 2.0 / 20.0)
    np.testing.assert_array_equal(ids, 1)
    np.testing.assert_allclose(c, rec.frame.rgb.reshape(-1, 3) / 255.0)
    # Right-hand normals face the camera, i.e. along the plane normal (0, 0, -1).
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    assert np.all(n[:, 2] < 0) and np.allclose(n[:, :2], 0.0)


def test_triangles_never_span_two_labels_and_vertices_lie_on_planes() -> None:
    labels = np.zeros((H, W), np.int32)
    labels[:, :7] = 1
    labels[:, 7:] = 2
    labels[:3, :] = 0
    params = np.array([[0.3, 0.0, -0.954, 2.0], [-0.2, -0.3, -0.933, 2.5]])
    rec = _rec(labels, params, depth=None)
    v, t, _, ids = planar_mesh(rec, step=1)
    assert len(v) == int((labels > 0).sum())
    assert np.all(ids[t[:, 0]] == ids[t[:, 1]]) and np.all(ids[t[:, 0]] == ids[t[:, 2]])
    # Cells fully inside a region: 2 triangles each; (H-3-1) rows of cells, (7-1) and (9-1) cols.
    assert len(t) == 2 * (H - 4) * (6 + 8)
    p = rec.planes[ids - 1]
    np.testing.assert_allclose(np.einsum("ij,ij->i", v, p[:, :3]) + p[:, 3], 0.0, atol=1e-9)
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    assert np.all(np.einsum("ij,ij->i", n, p[t[:, 0], :3]) > 0)


def test_step_subsamples_and_max_depth_drops_far_vertices() -> None:
    labels = np.ones((H, W), np.int32)
    rec = _rec(labels, np.array([[0.0, 0.0, -1.0, 2.0]]))
    v, t, _, _ = planar_mesh(rec, step=2)
    assert len(v) == (H // 2) * (W // 2) and len(t) == 2 * (H // 2 - 1) * (W // 2 - 1)
    v, t, _, _ = planar_mesh(rec, step=1, max_depth=1.5)
    assert len(v) == 0 and len(t) == 0
    # Default limit is twice the deepest input depth: a plane at 5 with depth 2 is dropped.
    far = _rec(labels, np.array([[0.0, 0.0, -1.0, 5.0]]))
    assert len(planar_mesh(far)[0]) == 0


def test_empty_and_bad_step() -> None:
    rec = _rec(np.zeros((H, W), np.int32), np.zeros((0, 4)))
    v, t, c, ids = planar_mesh(rec)
    assert v.shape == (0, 3) and t.shape == (0, 3) and c.shape == (0, 3) and ids.shape == (0,)
    with pytest.raises(ValueError, match="step"):
        planar_mesh(rec, step=0)


def test_open3d_mesh_matches_planar_mesh() -> None:
    rec = _rec(np.ones((H, W), np.int32), np.array([[0.0, 0.0, -1.0, 2.0]]))
    v, t, c, _ = planar_mesh(rec, step=2)
    mesh = reconstruction_to_open3d(rec, step=2)
    np.testing.assert_allclose(np.asarray(mesh.vertices), v)
    np.testing.assert_array_equal(np.asarray(mesh.triangles), t)
    np.testing.assert_allclose(np.asarray(mesh.vertex_colors), c)
    assert mesh.has_vertex_normals()


def test_scene_mesh_keeps_its_old_path_with_a_warning() -> None:
    from monoplane.geometry.mesh import scene_mesh

    # The old module path warns too (the first time it is imported).
    with pytest.warns(DeprecationWarning) as record:
        from monoplane.multiview.fusion import scene_mesh as old
    assert old is scene_mesh
    assert any("monoplane.geometry.mesh.scene_mesh" in str(w.message) for w in record)
