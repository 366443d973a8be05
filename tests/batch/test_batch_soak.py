"""Memory and drift of ``monoplane bench --batch``: the process tree's memory, and the time per
frame at the start and at the end of a batch.

The 1000-frame soak is slow-marked; short batches check the measurement in the default run.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from monoplane.batch.throughput import (
    BatchBenchResult,
    BatchSetting,
    bench_batch,
    format_batch_bench,
    tree_usage,
)


def test_tree_usage_counts_the_children() -> None:
    alone, _, cpu = tree_usage(os.getpid())
    assert cpu[os.getpid()] > 0
    # A child holding 64 MiB of touched memory, which says when it holds it.
    child = subprocess.Popen(
        [sys.executable, "-c", "import sys, time; x = bytearray(64 << 20); print(1, flush=True);"
                               " time.sleep(60)"], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout is not None and child.stdout.readline().strip() == "1"
        rss, pss, _ = tree_usage(os.getpid())
        assert rss > alone + 60 and pss > 60
    finally:
        child.kill()
        child.wait()


def test_long_batch_cycles_over_distinct_frames_and_reports_memory() -> None:
    result = bench_batch("seq-ransac", (64, 48), frames=8, workers=(2,), repeat=1,
                         distinct=3, window=3, interval=0.05, progress=False)
    assert (result.frames, result.distinct, result.window) == (8, 3, 3)
    (s,) = result.settings
    assert len(s.peak_rss) == len(s.frame_first) == len(s.frame_last) == 1
    assert 100 < s.peak_rss[0] < 4096 and 0 < s.peak_pss[0] <= s.peak_rss[0]
    assert s.frame_first[0] > 0 and s.frame_last[0] > 0
    assert len(s.cpu_first) == len(s.cpu_last) == 1
    text = format_batch_bench(result)
    assert "process tree" in text and "first / last 3 frames (3 distinct frames)" in text
    assert BatchBenchResult.from_dict(json.loads(json.dumps(result.to_dict()))) == result


def test_memory_table_medians() -> None:
    result = BatchBenchResult("monoplane", 128, 96, 1000, "mild", [
        BatchSetting("local", 2, [40.0], [38.0], [1.0], [1.0], [470.0], [300.0], [460.0],
                     [462.0], [0.070], [0.0714], [0.055], [None])], distinct=50, window=200)
    lines = format_batch_bench(result).splitlines()
    assert lines[-1].split() == ["local", "2", "470", "300", "460", "/", "462", "70.0", "/",
                                 "71.4", "(x1.02)", "55.0", "/", "-"]
    saved = {k: v for k, v in result.to_dict().items() if k not in ("distinct", "window")}
    assert "process tree" not in format_batch_bench(BatchBenchResult.from_dict(saved))


@pytest.mark.slow
def test_soak_1000_frames_two_workers() -> None:
    """Memory stays bounded and frames do not slow down over 1000 frames (docs/batch.md)."""
    result = bench_batch("monoplane", (128, 96), frames=1000, workers=(2,), repeat=1,
                         progress=False)
    (s,) = result.settings
    assert s.peak_rss[0] < 1024, s  # MiB, the driver and both workers together
    assert s.rss_last[0] <= 1.1 * s.rss_first[0] + 20, s  # no growth beyond noise
    # CPU per frame, not wall time: on a shared machine the wall time follows the load.
    assert s.cpu_last[0] <= 1.15 * s.cpu_first[0], s
