"""``monoplane cloud`` and ``monoplane eval --data`` through the command line."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import pytest

from monoplane.cli import main
from monoplane.testing import box_frame


def write_cloud(path: Path) -> np.ndarray:
    frame, _ = box_frame(64, 48)
    points = frame.points().reshape(-1, 3)
    points = points[np.random.default_rng(0).permutation(len(points))]
    o3d.io.write_point_cloud(str(path), o3d.geometry.PointCloud(
        o3d.utility.Vector3dVector(points)))
    return points


@pytest.mark.parametrize("suffix", [".ply", ".pcd", ".xyz"])
def test_cloud_writes_every_output(tmp_path: Path, suffix: str,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    points = write_cloud(tmp_path / f"box{suffix}")
    out = tmp_path / "out"
    assert main(["cloud", str(tmp_path / f"box{suffix}"), "--out", str(out)]) == 0
    assert "3 planes" in capsys.readouterr().out
    labels = np.load(out / "labels.npy")
    assert labels.shape == (len(points),) and labels.dtype == np.int32
    doc = json.loads((out / "planes.json").read_text())
    assert doc["num_planes"] == 3
    for plane in doc["planes"]:
        mine = points[labels == plane["id"]]
        assert len(mine) == plane["num_points"]
        resid = mine @ np.array(plane["normal"]) + plane["offset"]
        # Metres, as the input; a point next to a crease may sit on the other side of it.
        assert np.percentile(np.abs(resid), 95) < 1e-3 and np.abs(resid).max() < 0.05
    assert len(o3d.io.read_point_cloud(str(out / "labelled.ply")).points) == len(points)
    assert len(o3d.io.read_triangle_mesh(str(out / "planes.ply")).triangles) > 0
    assert (out / "planes.glb").is_file() and (out / "config.toml").is_file()
    assert not (out / "report.html").exists()


def test_cloud_report_is_an_html_page(tmp_path: Path) -> None:
    write_cloud(tmp_path / "box.ply")
    out = tmp_path / "out"
    assert main(["cloud", str(tmp_path / "box.ply"), "--out", str(out), "--report",
                 "--quiet"]) == 0
    text = (out / "report.html").read_text()
    assert "Interactive 3D view" in text and "viewer/model-viewer-umd.min.js" in text
    assert text.count('class="swatch"') == 3  # the plane table
    if "3D views are missing" not in text:  # rendered: the summary sheet and its figures
        assert 'src="summary.png"' in text and (out / "summary.png").is_file()
        assert (out / "cloud3d_birdseye.png").is_file()


def test_cloud_report_up_hint(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    write_cloud(tmp_path / "box.ply")
    out = tmp_path / "out"
    assert main(["cloud", str(tmp_path / "box.ply"), "--out", str(out), "--report", "--quiet",
                 "--up", "none"]) == 0
    text = (out / "report.html").read_text()
    assert "3D views are missing" in text or "3D views: up is" in text
    for bad in ("1,2", "0,0,0", "up"):
        with pytest.raises(SystemExit):
            main(["cloud", str(tmp_path / "box.ply"), "--out", str(tmp_path / "o"), "--up", bad])
        assert "--up: expected X,Y,Z" in capsys.readouterr().err


def test_cloud_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["cloud", str(tmp_path / "missing.ply"), "--out", str(tmp_path / "o")]) == 2
    assert "not found" in capsys.readouterr().err
    (tmp_path / "bad.obj").write_text("v 0 0 0\n")
    assert main(["cloud", str(tmp_path / "bad.obj"), "--out", str(tmp_path / "o")]) == 2
    assert "unsupported format" in capsys.readouterr().err
    write_cloud(tmp_path / "box.ply")
    assert main(["cloud", str(tmp_path / "box.ply"), "--out", str(tmp_path / "o"),
                 "--set", "refiner.plugin=dense-crf"]) == 2
    assert "images only" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def make_dataset(root: Path) -> None:
    for i, (size, focal) in enumerate((((128, 96), 80.0), ((96, 72), 50.0))):
        frame, labels = box_frame(*size, focal=focal)
        d = root / f"frame_{i}"
        d.mkdir(parents=True)
        np.save(d / "depth.npy", frame.depth)
        K = frame.K
        (d / "intrinsics.json").write_text(json.dumps(
            {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}))
        cv2.imwrite(str(d / "gt_labels.png"), labels.astype(np.uint16))


@pytest.mark.parametrize("extra", [["--preset", "range"], ["--as-cloud", "--preset", "cloud"]])
def test_eval_data_scores_segcomp(tmp_path: Path, extra: list[str],
                                  capsys: pytest.CaptureFixture[str]) -> None:
    make_dataset(tmp_path / "data")
    out = tmp_path / "scores.json"
    assert main(["eval", "--data", str(tmp_path / "data"), *extra, "--baseline",
                 "open3d-ransac", "--no-progress", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "correct@0.8" in text and "missed" in text
    data = json.loads(out.read_text())
    ours = data["methods"][0]
    assert ours["n_frames"] == 2 and ours["n_gt"] == 3
    assert ours["correct"] == ours["n_gt"] and ours["voi"] < 0.2
    # Per-frame records are flat: scores and SegComp counts by name beside the run's facts.
    first = ours["frames"][0]
    assert first["frame"] == "frame_0" and first["tolerance"] == 0.8 and not first["failed"]
    assert {"voi", "ri", "sc", "correct", "missed", "n_gt", "n_planes", "seconds"} <= set(first)


def test_eval_data_passes_baseline_options(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    make_dataset(tmp_path / "data")
    out = tmp_path / "scores.json"
    # A minimum support of 40 % keeps the back wall only: one correct detection of three.
    assert main(["eval", "--data", str(tmp_path / "data"), "--baseline", "open3d-ransac",
                 "--baseline-set", "open3d-ransac.min_support=0.4", "--no-progress",
                 "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert data["settings"]["baseline_options"] == {"open3d-ransac": {"min_support": 0.4}}
    assert data["methods"][0]["correct"] == 1 and data["methods"][0]["n_gt"] == 3


def test_eval_data_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["eval", "--data", str(tmp_path), "--preset", "range", "--no-progress"]) == 2
    assert "gt_labels.png" in capsys.readouterr().err
    assert main(["eval", "--as-cloud", "--preset", "cloud"]) == 2
    assert "--data" in capsys.readouterr().err
