"""Benchmark helpers of ``monoplane bench`` (monoplane/bench.py)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from monoplane.bench import (
    BaselineBench,
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
    result = BenchResult("monoplane", 256, 192, 3, stages, 7, 400.0, frames=2,
                         first_call_s=2.0, baselines=[BaselineBench("peer", 0.25, 0.5)])
    text = format_bench([result])
    rows = [line.split()[0] for line in text.splitlines()[3:9]]
    assert rows == ["cues", "ransac", "search", "label", "refiner", "total"]
    assert "700.0" in text and "7.0" in text
    # Throughput 1 / 1 s, the baseline's call 250 ms and whole call 500 ms, ratio 1 s / 0.25 s.
    assert result.fps == 1.0 and result.ratio(result.baselines[0]) == 4.0
    for expected in ("throughput", "1.00", "250.0", "500.0", "4.00x", "2000.0", "400"):
        assert expected in text
    assert format_bench([result], markdown=True).splitlines()[2].startswith("| stage |")
    # The JSON form round-trips.
    again = BenchResult.from_dict(result.to_dict())
    assert format_bench([again]) == text


def test_bench_runs_a_preset_and_a_baseline_on_several_frames() -> None:
    results = bench("seq-ransac", [(96, 72), (128, 96)], repeat=1, frames=2, progress=False,
                    baselines=["open3d-ransac"], isolate=False)
    assert [(r.width, r.height) for r in results] == [(96, 72), (128, 96)]
    for r in results:
        names = [s.name for s in r.stages]
        assert names[0] == "cues" and names[-1] == "total" and "ransac" in names
        total = r.stages[-1]
        assert total.median_s >= max(s.median_s for s in r.stages[:-1]) * 0.99
        assert total.peak_mib is not None
        assert total.peak_mib >= max(s.peak_mib or 0.0 for s in r.stages[:-1])
        assert r.frames == 2 and r.first_call_s > 0 and r.max_rss_mib > 0
        (peer,) = r.baselines
        assert peer.name == "open3d-ransac" and 0 < peer.call_s <= peer.total_s


def test_bench_rejects_bad_requests() -> None:
    with pytest.raises(InvalidInput, match="no-such"):
        bench("seq-ransac", [(96, 72)], baselines=["no-such"], progress=False)
    with pytest.raises(InvalidInput, match="--frames"):
        bench("seq-ransac", [(96, 72)], frames=0, progress=False)
