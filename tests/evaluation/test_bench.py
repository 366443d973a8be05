"""Benchmark helpers of ``monoplane bench`` (monoplane/bench.py)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from monoplane.bench import (
    BenchResult,
    StageBench,
    StagePeakTracker,
    bench,
    format_bench,
    parse_sizes,
)
from monoplane.errors import InvalidInput


def test_tracker_attributes_each_allocation_to_its_stage() -> None:
    tracker = StagePeakTracker()
    tracemalloc.start()
    try:
        tracker.start()
        kept = np.ones(4 * 2**20 // 8)  # 4 MiB made by "cues" and kept (like a frame)
        tracker.monoplane_stage_finished("cues", "given", 0.0, "f")
        temp = np.ones(2**20 // 8)  # 1 MiB of scratch during "ransac", on top of it
        del temp
        tracker.monoplane_stage_finished("ransac", "x", 0.0, "f")
        del kept
        whole_run = tracker.run_peak()
    finally:
        tracemalloc.stop()
    assert tracker.peaks["cues"] / 2**20 == pytest.approx(4.0, abs=0.2)
    assert tracker.peaks["ransac"] / 2**20 == pytest.approx(1.0, abs=0.2)
    assert whole_run / 2**20 == pytest.approx(5.0, abs=0.3)
    tracker.monoplane_stage_finished("refiner", "none", 0.0, "f")  # not tracing: ignored
    assert "refiner" not in tracker.peaks


def test_parse_sizes() -> None:
    assert parse_sizes("256x192, 640x480") == [(256, 192), (640, 480)]
    with pytest.raises(InvalidInput):
        parse_sizes(",")


def test_format_bench_orders_stages_and_sub_steps() -> None:
    stages = [StageBench("total", 1.0, 5.0), StageBench("ransac.search", 0.5),
              StageBench("refiner", 0.2, 1.0), StageBench("ransac", 0.7, 3.0),
              StageBench("ransac.label", 0.1), StageBench("cues", 0.001, 0.0)]
    text = format_bench([BenchResult("monoplane", 256, 192, 3, stages, 7, 400.0)])
    rows = [line.split()[0] for line in text.splitlines()[3:-1]]
    assert rows == ["cues", "ransac", "search", "label", "refiner", "total"]
    assert "700.0" in text and "7 planes" in text


def test_bench_runs_a_preset_at_two_sizes() -> None:
    results = bench("seq-ransac", [(96, 72), (128, 96)], repeat=2, progress=False)
    assert [(r.width, r.height) for r in results] == [(96, 72), (128, 96)]
    for r in results:
        names = [s.name for s in r.stages]
        assert names[0] == "cues" and names[-1] == "total" and "ransac" in names
        total = r.stages[-1]
        assert total.median_s >= max(s.median_s for s in r.stages[:-1]) * 0.99
        assert total.peak_mib is not None
        assert total.peak_mib >= max(s.peak_mib or 0.0 for s in r.stages[:-1])
