"""``monoplane eval`` and ``monoplane bench`` through the command line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from monoplane.cli import main

TINY = ["--n", "1", "--size", "96x72", "--no-progress"]


def test_eval_baseline_prints_the_paper_columns_and_writes_json(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "scores.json"
    assert main(["eval", "--baseline", "open3d-ransac", "--level", "clean", *TINY,
                 "--json", str(out)]) == 0
    text = capsys.readouterr().out
    for column in ("VOI", "RI", "SC", "R@0.05m", "R@0.1m", "R@0.6m", "s/frame"):
        assert column in text
    assert "open3d-ransac" in text
    data = json.loads(out.read_text())
    assert data["settings"]["width"] == 96 and data["settings"]["level"] == "clean"
    assert data["methods"][0]["n_frames"] == 1


def test_eval_preset_row(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["eval", "--preset", "seq-ransac", *TINY]) == 0
    assert "seq-ransac" in capsys.readouterr().out


@pytest.mark.parametrize("argv, message", [
    (["eval", *TINY], "nothing to evaluate"),
    (["eval", "--baseline", "nope", *TINY], "unknown baseline 'nope'"),
    (["eval", "--baseline", "open3d-ransac", "--n", "0"], "--n must be at least 1"),
    (["eval", "--baseline", "open3d-ransac", "--size", "big"], "WIDTHxHEIGHT"),
    (["eval", "--multiview", "--baseline", "open3d-ransac", *TINY], "--multiview"),
    (["eval", "--baseline", "open3d-ransac", "--baseline-set", "open3d-ransac.bogus=1", *TINY],
     "no option 'bogus'; valid options: epsilon, max_planes"),
    (["eval", "--baseline", "open3d-ransac", "--baseline-set", "open3d-ransac.max_planes=x",
      *TINY], "open3d-ransac.max_planes must be an integer"),
    (["eval", "--baseline", "open3d-ransac", "--baseline-set", "cgal.epsilon=0.01", *TINY],
     "'cgal' is not a baseline of this run"),
    (["bench", "--sizes", "x", "--no-progress"], "WIDTHxHEIGHT"),
    (["bench", "--repeat", "0", "--no-progress"], "--repeat"),
    (["bench", "--objects", "3-1", "--no-progress"], "--objects takes ranges"),
    (["bench", "--objects", "few", "--no-progress"], "--objects takes ranges"),
    (["bench", "--objects", "1-2", "--complexity", "--no-progress"], "not both"),
    (["bench", "--batch", "--complexity", "--no-progress"], "not --batch"),
])
def test_user_errors_are_one_line(argv: list[str], message: str,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err
    assert len(err.splitlines()) == 1


@pytest.mark.parametrize("command", ["eval", "bench"])
def test_help_has_examples(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main([command, "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    assert "examples:" in text and f"monoplane {command}" in text


def test_bench_prints_stage_rows(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench.json"
    assert main(["bench", "--preset", "seq-ransac", "--sizes", "96x72", "--repeat", "1",
                 "--frames", "1", "--no-baselines", "--no-progress", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    for row in ("cues", "ransac", "refiner", "total", "96x72 ms", "throughput", "peak RSS"):
        assert row in text
    data = json.loads(out.read_text())
    names = [s["name"] for s in data["results"][0]["stages"]]
    assert names[0] == "cues" and names[-1] == "total"
    assert data["results"][0]["stages"][-1]["peak_mib"] > 0
    assert data["results"][0]["max_rss_mib"] > 0 and data["settings"]["frames"] == 1
    # The saved run re-renders to the same table (how docs/evaluation.md is regenerated).
    assert main(["bench", "--from-json", str(out)]) == 0
    assert capsys.readouterr().out == text


def test_bench_complexity_levels_in_table_and_json(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "levels.json"
    assert main(["bench", "--preset", "seq-ransac", "--sizes", "96x72", "--repeat", "1",
                 "--frames", "1", "--objects", "1,4-6", "--no-baselines", "--no-progress",
                 "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "96x72 1 obj ms" in text and "96x72 4-6 obj ms" in text
    assert "time against plane count" in text
    data = json.loads(out.read_text())
    assert data["settings"]["objects"] == [[1, 1], [4, 6]]
    assert [r["objects"] for r in data["results"]] == [[1, 1], [4, 6]]
    assert data["results"][1]["per_frame"][0]["objects"] == 4
    assert data["results"][1]["gt_planes"] > 0
    assert main(["bench", "--from-json", str(out)]) == 0
    assert capsys.readouterr().out == text


def test_bench_complexity_is_the_default_objects_ranges() -> None:
    from monoplane.evaluation.bench import COMPLEXITY_LEVELS
    from monoplane.evaluation.bench_options import parse_object_ranges

    levels = [(0, 0), (1, 2), (4, 6), (8, 12)]  # the first: bare rooms
    assert parse_object_ranges(None, True) == list(COMPLEXITY_LEVELS) == levels
    assert parse_object_ranges(None, False) is None
    assert parse_object_ranges("0, 3-5", False) == [(0, 0), (3, 5)]


def test_eval_report_writes_html(tmp_path: Path) -> None:
    out = tmp_path / "report"
    assert main(["eval", "--baseline", "open3d-ransac", *TINY, "--report", str(out)]) == 0
    assert (out / "report.html").is_file()
