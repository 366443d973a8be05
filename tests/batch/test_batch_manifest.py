"""Manifests: relative paths, depth-only rows, and one-line errors naming file and row."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from batch_helpers import GOOD, read_labels, run_cli_labels

from monoplane.batch import read_frames, run_batch
from monoplane.cli import main
from monoplane.errors import InvalidInput


def test_manifest_relative_paths_and_depth_only_row(frames_dir, reference_labels, tmp_path):
    # The manifest sits beside a copy of two frames and names them relatively; the depth-only
    # row stores its depth as a 16-bit PNG in millimetres (depth_scale 1000).
    data = tmp_path / "export"
    for name in GOOD[:2]:
        shutil.copytree(frames_dir / name, data / name)
    depth_m = np.load(data / GOOD[1] / "depth.npy")
    cv2.imwrite(str(data / GOOD[1] / "depth_mm.png"), np.round(depth_m * 1000).astype(np.uint16))
    rows = [
        {"name": "with_rgb", "image": f"{GOOD[0]}/rgb.png", "depth": f"{GOOD[0]}/depth.npy",
         "normals": f"{GOOD[0]}/normals.npy", "intrinsics": f"{GOOD[0]}/intrinsics.json"},
        {"name": "depth_only", "image": "", "depth": f"{GOOD[1]}/depth_mm.png",
         "intrinsics": f"{GOOD[1]}/intrinsics.json", "depth_scale": 1000},
    ]
    manifest = data / "frames.jsonl"
    manifest.write_text("".join(json.dumps(r) + "\n" for r in rows))
    out = tmp_path / "out"
    summary = run_batch(manifest, out, workers=2, progress=False)
    assert [(f.name, f.status) for f in summary.frames] == [("with_rgb", "ok"),
                                                          ("depth_only", "ok")]
    np.testing.assert_array_equal(read_labels(out / "with_rgb"), reference_labels[GOOD[0]])
    folder = data / GOOD[1]
    expected = run_cli_labels(["--depth", str(folder / "depth_mm.png"), "--depth-scale", "1000",
                               "--intrinsics", str(folder / "intrinsics.json")],
                              tmp_path / "run_depth_only")
    np.testing.assert_array_equal(read_labels(out / "depth_only"), expected)
    assert expected.max() >= 2

    # The same frames as CSV (empty cells = absent) give the same specs.
    csv_path = data / "frames.csv"
    header = ["name", "image", "depth", "normals", "intrinsics", "depth_scale"]
    lines = [",".join(header)] + [",".join(str(r.get(k, "")) for k in header) for r in rows]
    csv_path.write_text("\n".join(lines) + "\n")
    assert read_frames(csv_path) == read_frames(manifest)


@pytest.mark.parametrize("content, suffix, message", [
    ('{"name": "a", "depth": "d.npy"}\n', ".jsonl", "row 1: missing column 'image'"),
    ('{"image": "rgb.png"}\n{"image": "rgb.png", "colour": "x"}\n', ".jsonl",
     "row 2: unknown column 'colour'; valid columns: name, image"),
    ('{"image": "rgb.png"}\n\n{"image": "nope/rgb.png"}\n', ".jsonl",
     "row 3: image file not found"),
    ("name,image\na,rgb.png\nb,missing.png\n", ".csv", "row 3: image file not found"),
    ("name,depth\na,d.npy\n", ".csv", "row 1: the header lacks the required column 'image'"),
    ("name,image,depth_scale\na,rgb.png,-5\n", ".csv", "row 2: depth_scale must be positive"),
    ('{"image": ""}\n', ".jsonl", "row 1: a depth-only row (empty image) needs a depth file"),
    ('{"image": "rgb.png"}\n{"image": "rgb.png"}\n', ".jsonl",
     "row 2: frame name 'rgb' is already used on row 1"),
    ('{"image": "rgb.png"\n', ".jsonl", "row 1: not valid JSON"),
])
def test_bad_manifest_is_one_line_naming_file_and_row(tmp_path, capsys, content, suffix,
                                                      message):
    cv2.imwrite(str(tmp_path / "rgb.png"), np.zeros((8, 8, 3), np.uint8))
    np.save(tmp_path / "d.npy", np.ones((8, 8), np.float32))
    manifest = tmp_path / f"frames{suffix}"
    manifest.write_text(content)
    with pytest.raises(InvalidInput, match="row"):
        read_frames(manifest)
    out = tmp_path / "out"
    assert main(["batch", str(manifest), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith(f"monoplane: error: {manifest}, "), err
    assert message in err
    assert not out.exists()  # nothing written before the input is known to be good


def test_bad_batch_input(tmp_path, capsys):
    assert main(["batch", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert "batch input not found" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["batch", str(tmp_path / "empty"), "--out", str(tmp_path / "o")]) == 2
    assert "no frame sub-folders" in capsys.readouterr().err
    (tmp_path / "list.txt").write_text("x")
    assert main(["batch", str(tmp_path / "list.txt"), "--out", str(tmp_path / "o")]) == 2
    assert "must be .jsonl or .csv" in capsys.readouterr().err


def test_bad_engine_arguments_fail_before_any_output(frames_dir, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["batch", str(frames_dir), "--out", str(out), "--ray-address", "auto"]) == 2
    assert "--ray-address needs --engine ray" in capsys.readouterr().err
    assert main(["batch", str(frames_dir), "--out", str(out), "--workers", "0"]) == 2
    assert "--workers must be at least 1" in capsys.readouterr().err
    assert main(["batch", str(frames_dir), "--out", str(out), "--set", "labeler.nope=1"]) == 2
    assert "nope" in capsys.readouterr().err
    assert not out.exists()


def test_one_batch_per_output_folder(frames_dir, tmp_path, capsys):
    from monoplane.batch.runner import batch_lock

    out = tmp_path / "out"
    out.mkdir()
    with batch_lock(out):
        assert main(["batch", str(frames_dir), "--out", str(out)]) == 2
    assert f"another monoplane batch is writing to {out}" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == [".monoplane-batch.lock"]


def test_unsafe_frame_name(tmp_path):
    cv2.imwrite(str(tmp_path / "rgb.png"), np.zeros((8, 8, 3), np.uint8))
    (tmp_path / "m.jsonl").write_text('{"name": "../escape", "image": "rgb.png"}\n')
    with pytest.raises(InvalidInput, match=r"m.jsonl, row 1: frame name '\.\./escape'"):
        read_frames(tmp_path / "m.jsonl")


def test_folder_layout_finds_cues(frames_dir: Path):
    specs = read_frames(frames_dir, depth_scale=None)
    assert [s.name for s in specs] == ["frame_000", "frame_001", "frame_002", "frame_003"]
    s = specs[0]
    assert s.image.endswith("frame_000/rgb.png") and s.depth.endswith("frame_000/depth.npy")
    assert s.normals.endswith("normals.npy") and s.intrinsics.endswith("intrinsics.json")


def test_index_histogram_counts_every_value():
    import re

    from monoplane.batch.index import svg_histogram

    svg = svg_histogram([3, 5, 5, 9, None], "planes per frame", "planes", integer=True)
    bars = [(float(lo), int(n)) for lo, n in
            re.findall(r"<title>([-\d.]+) to [-\d.]+ planes: (\d+)</title>", svg)]
    assert sum(n for _, n in bars) == 4
    assert dict(bars)[4.5] == 2  # the bin from 4.5 to 5.5 holds both fives
    assert "no data" in svg_histogram([], "t", "s")


def test_pipeline_is_built_once_per_process_and_config():
    from monoplane.batch.frame import pipeline_for
    from monoplane.host.pipeline import Pipeline

    cfg = Pipeline.from_preset("monoplane").config.to_dict()
    first = pipeline_for(cfg)
    assert pipeline_for(dict(cfg)) is first
    assert set(first._stages) == set(first.config.stages)  # every stage built up front
    other = Pipeline.from_preset("monoplane", overrides={"ransac.seed": 3}).config.to_dict()
    assert pipeline_for(other) is not first
