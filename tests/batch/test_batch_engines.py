"""Both engines give ``monoplane run``'s labels pixel for pixel, and a broken frame in the middle
fails alone with a one-line reason."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from batch_helpers import BROKEN, GOOD, read_labels

from monoplane.batch import run_batch
from monoplane.batch.index import write_index
from monoplane.batch.specs import read_frames
from monoplane.cli import main
from monoplane.export import output_files


def check_batch_output(out: Path, summary, reference: dict[str, np.ndarray]) -> None:
    by_name = {f.name: f for f in summary.frames}
    assert [f.name for f in summary.frames] == sorted([*GOOD, BROKEN])  # input order
    for name in GOOD:
        assert by_name[name].status == "ok", by_name[name]
        assert sorted(p.name for p in (out / name).iterdir()) == sorted(output_files("frame"))
        np.testing.assert_array_equal(read_labels(out / name), reference[name])
        assert by_name[name].planes == int(reference[name].max())
    bad = by_name[BROKEN]
    assert bad.status == "failed" and bad.planes is None
    assert "cannot read depth" in bad.error and "depth.npy" in bad.error
    assert "\n" not in bad.error
    assert not (out / BROKEN).exists()
    assert not [p for p in out.iterdir() if p.name.endswith((".partial", ".old"))]
    doc = json.loads((out / "summary.json").read_text())
    assert doc["counts"] == {"ok": 3, "failed": 1, "skipped": 0}
    assert doc["config"]["preset"] == "monoplane"
    assert {tuple(sorted(f)) for f in doc["frames"]} == {
        ("error", "name", "planes", "seconds", "status")}


def test_local_engine_matches_run(frames_dir, reference_labels, tmp_path, capsys):
    out = tmp_path / "out"
    summary = run_batch(frames_dir, out, workers=2, progress=False)
    check_batch_output(out, summary, reference_labels)

    # The index page: one thumbnail per finished frame, the failure's reason, two plots.
    index = write_index(summary, read_frames(frames_dir), out)
    text = index.read_text()
    assert text.count("<svg") == 2 and "cannot read depth" in text
    for name in GOOD:
        assert (out / "index_files" / f"{name}.png").is_file()
        assert f'href="{name}/planes.json"' in text

    # Run again from the CLI: finished frames are skipped, the broken one is retried and fails
    # again, so the exit status is 1.
    code = main(["batch", str(frames_dir), "--out", str(out), "--workers", "1"])
    captured = capsys.readouterr()
    assert code == 1
    assert f"failed: {BROKEN}: cannot read depth" in captured.out
    assert "0 done, 1 failed, 3 skipped" in captured.out
    doc = json.loads((out / "summary.json").read_text())
    assert [f["status"] for f in doc["frames"]] == ["skipped", "failed", "skipped", "skipped"]
    assert doc["frames"][0]["planes"] == summary.frames[0].planes

    # Resuming with another config would mix two configs in one folder: refused up front.
    code = main(["batch", str(frames_dir), "--out", str(out), "--set", "ransac.seed=1"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err
    assert "was made with a different config" in err and "--overwrite" in err
    # --overwrite recomputes every frame with the new config.
    code = main(["batch", str(frames_dir), "--out", str(out), "--set", "ransac.seed=1",
                 "--overwrite", "--workers", "2", "--quiet"])
    assert code == 1
    doc = json.loads((out / "summary.json").read_text())
    assert [f["status"] for f in doc["frames"]] == ["ok", "failed", "ok", "ok"]
    assert doc["config"]["ransac"]["seed"] == 1
    assert "seed = 1" in (out / GOOD[0] / "config.toml").read_text()


@pytest.fixture(scope="module")
def ray_session():
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
             configure_logging=False)
    try:
        yield ray
    finally:
        ray.shutdown()


def test_ray_engine_matches_run(ray_session, frames_dir, reference_labels, tmp_path):
    out = tmp_path / "out"
    summary = run_batch(frames_dir, out, engine="ray", workers=2, progress=False)
    check_batch_output(out, summary, reference_labels)
    assert ray_session.is_initialized()  # a session the caller started is left running
