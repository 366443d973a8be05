"""The sparse-view driver, its outputs and the ``multiview`` / ``match`` subcommands."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from monoplane.datamodel import Reconstruction
from monoplane.evaluation.twoview import ground_truth_sfm, relative_pose_error
from monoplane.export import save
from monoplane.geometry.alignment import ScaleAlignment
from monoplane.multiview import (
    MultiviewResult,
    scale_sfm,
    scene_mesh,
)
from monoplane.stages.fusers import AverageFuser
from monoplane.synth import generate


@pytest.fixture(scope="module")
def synth_pair():
    return generate(3, level="mild", n_views=2)


def _oracle_result(synth) -> MultiviewResult:
    sfm = ground_truth_sfm(synth)
    views = [Reconstruction(frame=v.frame, labels=v.gt_labels, params=v.gt_params)
             for v in synth.views]
    scene, matches = AverageFuser().fuse_with_matches(views, sfm)
    scene.scales = [1.0, 1.0]
    align = ScaleAlignment(scale=1.0, num_points=10, num_inliers=10, residual=0.0,
                           relative_residual=0.0)
    return MultiviewResult(scene=scene, sfm=sfm, alignments=[align, align],
                           plane_matches=matches, units="m")


def test_save_scene_layout_and_contents(synth_pair, tmp_path: Path) -> None:
    result = _oracle_result(synth_pair)
    out = save(result, tmp_path / "scene")
    for v in range(2):
        for name in ("labels.png", "planes.json", "planes.ply", "depth_planar.npy"):
            assert (out / f"view_{v:03d}" / name).is_file()
    doc = json.loads((out / "scene.json").read_text())
    assert len(doc["planes"]) == result.scene.planes.shape[0]
    linked = sum(len(p["views"]) for p in doc["planes"])
    assert linked == sum(v.num_planes for v in result.scene.views)
    assert {m["criterion"] for m in doc["plane_matches"]} <= {"keypoints", "reprojection"}
    cams = json.loads((out / "cameras.json").read_text())["cameras"]
    assert [c["image"] for c in cams] == [v.frame.name for v in synth_pair.views]
    for c, view in zip(cams, synth_pair.views, strict=True):
        np.testing.assert_allclose(c["R"], view.R, atol=1e-12)
        np.testing.assert_allclose(c["t"], view.t, atol=1e-12)
        assert np.shape(c["K"]) == (3, 3)
    header = (out / "scene.ply").read_text().split("end_header")[0]
    assert "element face" in header and "element face 0\n" not in header
    points_header = (out / "points.ply").read_text().split("end_header")[0]
    assert f"element vertex {len(result.sfm.points)}" in points_header


def test_scene_mesh_lies_on_its_fused_planes(synth_pair) -> None:
    scene = _oracle_result(synth_pair).scene
    mesh = scene_mesh(scene)
    assert set(mesh.plane_ids.tolist()) == set(range(scene.planes.shape[0]))
    for g, tri in zip(mesh.plane_ids, mesh.triangles, strict=True):
        dist = mesh.vertices[tri] @ scene.planes[g, :3] + scene.planes[g, 3]
        np.testing.assert_allclose(dist, 0.0, atol=1e-9)


def test_failed_save_leaves_nothing(synth_pair, tmp_path: Path, monkeypatch) -> None:
    import monoplane.export.ply

    result = _oracle_result(synth_pair)

    def boom(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr(monoplane.export.ply, "write_plane_mesh_ply", boom)
    with pytest.raises(RuntimeError):
        save(result, tmp_path / "scene")
    assert list(tmp_path.iterdir()) == []


def test_scale_sfm_keeps_rotations_and_scales_positions(synth_pair) -> None:
    sfm = ground_truth_sfm(synth_pair)
    scaled = scale_sfm(sfm, 2.0)
    for a, b in zip(sfm.cameras, scaled.cameras, strict=True):
        np.testing.assert_allclose(b.R, a.R)
        np.testing.assert_allclose(b.center, 2.0 * a.center)
    np.testing.assert_allclose(scaled.points, 2.0 * sfm.points)


def test_driver_aligns_scales_and_fuses(synth_pair) -> None:
    from monoplane.host.pipeline import Pipeline
    from monoplane.multiview import reconstruct_multiview

    pipe = Pipeline.from_preset("monoplane", overrides=["cues.plugin=given"])
    sfm = ground_truth_sfm(synth_pair)
    # Two frames of one name (view0/rgb.png, view1/rgb.png) come out told apart.
    frames = [v.frame.with_(name="rgb") for v in synth_pair.views]
    result = reconstruct_multiview(frames, pipe, sfm=sfm)
    assert [v.frame.name for v in result.scene.views] == ["000_rgb", "001_rgb"]
    # Mild cues have an unknown per-view scale; alignment must undo it (the warp is smooth).
    for s, view in zip(result.scene.scales, synth_pair.views, strict=True):
        assert s * view.scale == pytest.approx(1.0, rel=0.1)
    assert result.units == "sfm"
    assert result.scene.planes.shape[0] >= 3
    assert sum(len(t) for t in result.scene.links) == sum(v.num_planes
                                                         for v in result.scene.views)
    assert {"matcher", "alignment", "single_view", "fuser", "total"} - {"matcher"} <= set(
        result.timings)


def _write_pair(synth, folder: Path) -> list[str]:
    paths = []
    for v, view in enumerate(synth.views):
        img = folder / f"img{v}.png"
        cv2.imwrite(str(img), view.frame.rgb[..., ::-1])
        np.save(folder / f"depth{v}.npy", view.frame.depth)
        np.save(folder / f"normals{v}.npy", view.frame.normals)
        paths.append(str(img))
    return paths


def test_cli_match_writes_cameras(synth_pair, tmp_path: Path) -> None:
    from monoplane.cli import main

    images = _write_pair(synth_pair, tmp_path)
    K = synth_pair.views[0].frame.K
    intr = f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}"
    assert main(["match", *images, "--intrinsics", intr, "--out", str(tmp_path / "sfm"),
                 "--quiet"]) == 0
    cams = json.loads((tmp_path / "sfm" / "cameras.json").read_text())["cameras"]
    assert [c["image"] for c in cams] == ["img0", "img1"]
    from monoplane.datamodel import Camera

    c0, c1 = (Camera(np.array(c["K"]), np.array(c["R"]), np.array(c["t"]), 256, 192)
              for c in cams)
    np.testing.assert_allclose(c0.K, K, atol=1e-9)
    v0, v1 = synth_pair.views
    rot, trans = relative_pose_error(c0, c1, v0.R, v0.t, v1.R, v1.t)
    assert rot < 2.0 and trans < 10.0
    assert (tmp_path / "sfm" / "points.ply").is_file()


def test_cli_match_unrelated_images_is_a_one_line_error(tmp_path: Path, capsys) -> None:
    from monoplane.cli import main

    rng = np.random.default_rng(0)
    paths = []
    for i in range(2):
        p = tmp_path / f"noise{i}.png"
        cv2.imwrite(str(p), cv2.GaussianBlur(rng.integers(0, 256, (192, 256, 3), np.uint8),
                                             (0, 0), 1.0))
        paths.append(str(p))
    assert main(["match", *paths, "--out", str(tmp_path / "o"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "verified matches" in err[0]
    assert not (tmp_path / "o").exists()


def test_cli_multiview_end_to_end(synth_pair, tmp_path: Path) -> None:
    from monoplane.cli import main

    images = _write_pair(synth_pair, tmp_path)
    K = synth_pair.views[0].frame.K
    code = main(["multiview", *images,
                 "--depth", str(tmp_path / "depth0.npy"), str(tmp_path / "depth1.npy"),
                 "--normals", str(tmp_path / "normals0.npy"), str(tmp_path / "normals1.npy"),
                 "--relative-depth", "--intrinsics", f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}",
                 "--set", "cues.plugin=given", "--out", str(tmp_path / "mv"), "--quiet"])
    assert code == 0
    doc = json.loads((tmp_path / "mv" / "scene.json").read_text())
    assert len(doc["cameras"]) == 2 and len(doc["planes"]) >= 3
    assert (tmp_path / "mv" / "view_001" / "labels.png").is_file()


def test_cli_multiview_writes_scene_glb_report_and_recording(synth_pair, tmp_path: Path) -> None:
    import os
    import shutil
    import subprocess

    import pygltflib

    from monoplane.cli import main

    pytest.importorskip("rerun", reason="the rerun extra is not installed (setup.sh installs it)")
    images = _write_pair(synth_pair, tmp_path)
    K = synth_pair.views[0].frame.K
    out, rrd = tmp_path / "mv", tmp_path / "mv.rrd"
    assert main(["multiview", *images,
                 "--depth", str(tmp_path / "depth0.npy"), str(tmp_path / "depth1.npy"),
                 "--normals", str(tmp_path / "normals0.npy"), str(tmp_path / "normals1.npy"),
                 "--relative-depth", "--intrinsics", f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}",
                 "--set", "cues.plugin=given", "--out", str(out), "--report",
                 "--rerun", str(rrd), "--quiet"]) == 0
    doc = json.loads((out / "scene.json").read_text())
    gltf = pygltflib.GLTF2().load(str(out / "scene.glb"))
    names = {n.name for n in gltf.nodes}
    assert {f"plane_{p['id']}" for p in doc["planes"]} <= names
    assert {"camera_0", "camera_1"} <= names and len(gltf.cameras) == 2
    assert (out / "view_000" / "planes.glb").is_file()
    report = (out / "report.html").read_text()
    assert 'src="summary.png"' in report and (out / "summary.png").is_file()
    assert "Interactive 3D view" in report
    if shutil.which("rerun"):  # the viewer's CLI, shipped with rerun-sdk
        env = {**os.environ, "XDG_CONFIG_HOME": str(tmp_path / "rerun-config")}
        subprocess.run(["rerun", "analytics", "disable"], env=env, check=True,
                       capture_output=True)
        subprocess.run(["rerun", "rrd", "verify", str(rrd)], env=env, check=True,
                       capture_output=True)
        printed = subprocess.run(["rerun", "rrd", "print", str(rrd)], env=env, check=True,
                                 capture_output=True, text=True).stdout
        for entity in ("/world/view_000", "/world/view_001/labels", "/world/sfm_points"):
            assert f" - {entity} - " in printed
