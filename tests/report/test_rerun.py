"""Rerun recordings: ``monoplane.log_rerun`` and ``--rerun FILE.rrd`` on run, cloud and batch
(multiview: tests/test_multiview.py). Each file must pass ``rerun rrd verify``, and ``rerun rrd
print`` must list the entities docs/reports.md promises."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from report_fixtures import make_scene

import monoplane
from monoplane.cli import main

pytest.importorskip("rerun", reason="the rerun extra is not installed (setup.sh installs it)")


@pytest.fixture(scope="module")
def rerun_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """Environment for the ``rerun`` CLI with its usage reporting turned off (in a config
    folder of its own, so the user's setting is left alone)."""
    import os

    if shutil.which("rerun") is None:
        pytest.skip("the rerun CLI of rerun-sdk is not on PATH")
    env = {**os.environ, "XDG_CONFIG_HOME": str(tmp_path_factory.mktemp("rerun-config"))}
    subprocess.run(["rerun", "analytics", "disable"], env=env, check=True, capture_output=True)
    return env


def entities(path: Path, env: dict[str, str]) -> dict[str, set[str]]:
    """Entity path -> the archetype components its chunks carry, after ``rerun rrd verify``."""
    verify = subprocess.run(["rerun", "rrd", "verify", str(path)], env=env, capture_output=True,
                            text=True, timeout=120)
    assert verify.returncode == 0, verify.stdout + verify.stderr
    printed = subprocess.run(["rerun", "rrd", "print", str(path)], env=env, capture_output=True,
                             text=True, timeout=120, check=True).stdout
    found: dict[str, set[str]] = {}
    for entity, columns in re.findall(r" - (/\S*) - data columns: \[([^\]]*)\]", printed):
        found.setdefault(entity, set()).update(columns.split())
    return found


SINGLE_VIEW = {
    "/world": {"ViewCoordinates:xyz", "AnnotationContext:context"},
    "/world/camera": {"Pinhole:image_from_camera", "Pinhole:resolution"},
    "/world/camera/image": {"Image:buffer"},
    "/world/camera/depth": {"DepthImage:buffer"},
    "/world/camera/labels": {"SegmentationImage:buffer"},
    "/world/points": {"Points3D:positions", "Points3D:colors", "Points3D:class_ids"},
}


def _assert_single_view(found: dict[str, set[str]], num_planes: int) -> None:
    for entity, columns in SINGLE_VIEW.items():
        assert columns <= found.get(entity, set()), (entity, found.get(entity))
    meshes = {e for e in found if e.startswith("/world/planes/")}
    assert meshes == {f"/world/planes/plane_{i}" for i in range(1, num_planes + 1)}
    for e in meshes:
        assert {"Mesh3D:vertex_positions", "Mesh3D:triangle_indices",
                "Mesh3D:vertex_colors"} <= found[e]


def test_log_rerun_of_one_view(room, tmp_path: Path, rerun_env: dict[str, str]) -> None:
    monoplane.log_rerun(room, tmp_path / "room.rrd")
    _assert_single_view(entities(tmp_path / "room.rrd", rerun_env), room.num_planes)
    assert not list(tmp_path.glob(".*partial"))


def test_log_rerun_of_a_scene_has_one_camera_per_view(tmp_path: Path,
                                                       rerun_env: dict[str, str]) -> None:
    scene = make_scene(2)
    monoplane.log_rerun(scene, tmp_path / "scene.rrd")
    found = entities(tmp_path / "scene.rrd", rerun_env)
    for v in range(2):
        view = f"/world/view_{v:03d}"
        assert {"Transform3D:translation", "Transform3D:mat3x3",
                "Pinhole:image_from_camera"} <= found[view]
        for child, column in (("image", "Image:buffer"), ("depth", "DepthImage:buffer"),
                              ("labels", "SegmentationImage:buffer")):
            assert column in found[f"{view}/{child}"]
        assert "Points3D:positions" in found[f"/world/points/view_{v:03d}"]
    assert "Points3D:positions" in found["/world/sfm_points"]
    assert "AnnotationContext:context" in found["/world"]
    assert {e for e in found if e.startswith("/world/planes/plane_")} <= {
        f"/world/planes/plane_{g}" for g in range(scene.planes.shape[0])}


def test_log_rerun_into_a_given_stream(room) -> None:
    import rerun as rr

    stream = rr.RecordingStream("test")
    assert monoplane.log_rerun(room, recording=stream) is stream
    with pytest.raises(monoplane.InvalidInput, match="cannot log a str"):
        monoplane.log_rerun("room", recording=stream)


def test_missing_extra_is_one_line_naming_it(sample_dir: Path, tmp_path: Path,
                                             monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setitem(sys.modules, "rerun", None)  # import rerun now raises ImportError
    out = tmp_path / "out"
    assert main(["run", str(sample_dir / "rgb.png"), "--depth", str(sample_dir / "depth.npy"),
                 "--out", str(out), "--rerun", str(tmp_path / "r.rrd"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["monoplane: error: --rerun needs the Rerun SDK: pip install "
                   "'monoplane[rerun]'"]
    assert not out.exists()  # failed before any work


def test_rerun_path_must_be_an_rrd_file(sample_dir: Path, tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", str(sample_dir / "rgb.png"), "--depth", str(sample_dir / "depth.npy"),
                 "--out", str(tmp_path / "o"), "--rerun", str(tmp_path / "r.txt")]) == 2
    assert "suffix .rrd" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_run_writes_a_recording(sample_dir: Path, tmp_path: Path,
                                rerun_env: dict[str, str]) -> None:
    rrd = tmp_path / "rec" / "run.rrd"  # missing folders are created
    assert main(["run", str(sample_dir / "rgb.png"), "--depth", str(sample_dir / "depth.npy"),
                 "--intrinsics", str(sample_dir / "intrinsics.json"), "--out",
                 str(tmp_path / "out"), "--rerun", str(rrd), "--quiet"]) == 0
    planes = len(json.loads((tmp_path / "out" / "planes.json").read_text())["planes"])
    _assert_single_view(entities(rrd, rerun_env), planes)


def test_cloud_writes_a_recording(tmp_path: Path, rerun_env: dict[str, str]) -> None:
    import open3d as o3d

    from monoplane.testing import box_frame

    frame, _ = box_frame(64, 48)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(frame.points().reshape(-1, 3)))
    o3d.io.write_point_cloud(str(tmp_path / "box.ply"), pcd)
    assert main(["cloud", str(tmp_path / "box.ply"), "--out", str(tmp_path / "out"),
                 "--rerun", str(tmp_path / "cloud.rrd"), "--quiet"]) == 0
    found = entities(tmp_path / "cloud.rrd", rerun_env)
    assert {"Points3D:positions", "Points3D:class_ids"} <= found["/world/points"]
    # The same plane meshes as planes.glb (a plane too small to outline has none in either).
    import pygltflib

    meshes = [m.name for m in pygltflib.GLTF2().load(str(tmp_path / "out" / "planes.glb")).meshes]
    assert len(meshes) >= 2
    assert {e for e in found if e.startswith("/world/planes/")} == {
        f"/world/planes/{name}" for name in meshes}


def test_batch_writes_one_recording_with_a_frame_timeline(sample_dir: Path, tmp_path: Path,
                                                          rerun_env: dict[str, str]) -> None:
    frames = tmp_path / "frames"
    for name in ("a", "b"):
        shutil.copytree(sample_dir, frames / name,
                        ignore=shutil.ignore_patterns("frames", "out*", "*.rrd"))
    rrd = tmp_path / "batch.rrd"
    assert main(["batch", str(frames), "--out", str(tmp_path / "out"), "--workers", "1",
                 "--rerun", str(rrd), "--quiet"]) == 0
    found = entities(rrd, rerun_env)
    _assert_single_view(found, len(json.loads(
        (tmp_path / "out" / "a" / "planes.json").read_text())["planes"]))
    printed = subprocess.run(["rerun", "rrd", "print", "-vv", str(rrd)], env=rerun_env,
                             capture_output=True, text=True, check=True).stdout
    assert "index_name: frame" in printed
    # Both frames were logged: two images on the timeline.
    assert re.search(r"with 2 rows .* - /world/camera/image ", printed)
    assert (tmp_path / "out" / "a" / "planes.glb").is_file()


def test_points_are_thinned_to_the_cap(room, monkeypatch: pytest.MonkeyPatch) -> None:
    from monoplane.export import rerun_log

    monkeypatch.setattr(rerun_log, "MAX_POINTS", 1000)
    points, colors, classes = rerun_log._view_points(room, room.labels)
    assert 0 < len(points) <= 1000 and colors is not None and len(colors) == len(points)
    assert set(np.unique(classes)) <= set(range(room.num_planes + 1))
