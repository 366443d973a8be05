"""``monoplane bench --batch``: the batch command timed per worker count
(monoplane/batch/throughput.py)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from monoplane.batch.throughput import (
    BatchBenchResult,
    BatchSetting,
    bench_batch,
    format_batch_bench,
)
from monoplane.cli import main
from monoplane.errors import InvalidInput


def test_bench_batch_runs_the_command_for_every_setting() -> None:
    result = bench_batch("seq-ransac", (96, 72), frames=2, workers=(1, 2), repeat=1,
                         progress=False)
    assert [(s.engine, s.workers) for s in result.settings] == [("local", 1), ("local", 2)]
    for s in result.settings:
        assert len(s.command_s) == len(s.batch_s) == 1
        # The batch's own time excludes the interpreter's start and imports.
        assert 0 < s.batch_s[0] < s.command_s[0]
    assert result.settings[0].command_speedup == result.settings[0].batch_speedup == [1.0]
    ref, two = result.settings
    assert two.batch_speedup[0] == pytest.approx(ref.batch_s[0] / two.batch_s[0])
    text = format_batch_bench(result)
    assert "2 frames 96x72" in text and "frames/s" in text
    assert BatchBenchResult.from_dict(json.loads(json.dumps(result.to_dict()))) == result


def test_format_batch_bench_medians_and_markdown() -> None:
    result = BatchBenchResult("monoplane", 640, 480, 20, "mild", [
        BatchSetting("local", 1, [6.0, 7.0, 6.5], [5.0, 6.0, 5.5], [1.0] * 3, [1.0] * 3),
        BatchSetting("local", 2, [4.0, 4.4, 4.2], [3.0, 3.5, 3.2], [1.5, 1.6, 1.55],
                     [1.67, 1.71, 1.72]),
    ])
    lines = format_batch_bench(result).splitlines()
    assert lines[0].endswith("medians of 3 rounds")
    assert lines[2].split() == ["local", "1", "6.50", "5.50", "3.64", "1.00x", "1.00x"]
    assert lines[3].split() == ["local", "2", "4.20", "3.20", "6.25", "1.55x", "1.71x"]
    md = format_batch_bench(result, markdown=True)
    assert "| local | 2 | 4.20 | 3.20 | 6.25 | 1.55x | 1.71x |" in md


@pytest.mark.parametrize("kwargs, message", [
    ({"workers": (0, 2)}, "--workers"),
    ({"workers": ()}, "--workers"),
    ({"frames": 0}, "--frames"),
    ({"engines": ("spark",)}, "spark"),
])
def test_bench_batch_rejects_bad_requests(kwargs: dict, message: str) -> None:
    with pytest.raises(InvalidInput, match=message):
        bench_batch(**{"size": (64, 48), "frames": 1, "repeat": 1, "progress": False,
                       **kwargs})


@pytest.mark.parametrize("argv, message", [
    (["--batch", "--workers", "1,x"], "--workers"),
    (["--batch", "--sizes", "96x72,128x96"], "one size"),
    (["--workers", "2"], "--batch only"),
])
def test_bench_batch_cli_errors(argv: list[str], message: str,
                                capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--no-progress", *argv]) != 0
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_bench_batch_json_is_rendered_again(tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    result = BatchBenchResult("monoplane", 96, 72, 2, "mild",
                              [BatchSetting("local", 1, [2.0], [1.0], [1.0], [1.0])])
    path = tmp_path / "batch.json"
    path.write_text(json.dumps({"kind": "batch", "settings": {}, "result": result.to_dict()}))
    assert main(["bench", "--from-json", str(path), "--markdown"]) == 0
    assert "| local | 1 | 2.00 | 1.00 | 2.00 | 1.00x | 1.00x |" in capsys.readouterr().out
