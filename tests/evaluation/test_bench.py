"""Benchmark helpers of ``monoplane bench`` (monoplane/evaluation/bench.py)."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import cv2
import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.evaluation.bench import (
    BaselineBench,
    BenchResult,
    StageBench,
    StagePeakTracker,
    bench,
    format_bench,
    parse_sizes,
)
from monoplane.evaluation.bench_frames import DataSource, load_data_frames


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


def test_bench_in_this_process_leaves_its_allocator_policy(monkeypatch) -> None:
    # Only an isolated child takes the command line's policy; the caller's stays its own.
    calls: list[None] = []
    monkeypatch.setattr("monoplane.evaluation.bench.keep_freed_memory",
                        lambda: calls.append(None))
    bench("seq-ransac", [(64, 48)], repeat=1, frames=1, progress=False, baselines=[],
          isolate=False)
    assert not calls


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
        # Process time of the whole call: positive, and it reaches the table and the JSON.
        assert r.cpu_s > 0 and r.to_dict()["cpu_s"] == r.cpu_s
        cpu_row = next(line for line in format_bench([r]).splitlines()
                       if line.startswith("total CPU (process time)"))
        assert cpu_row.split()[-1] == f"{1000 * r.cpu_s:.1f}"
        (peer,) = r.baselines
        assert peer.name == "open3d-ransac" and 0 < peer.call_s <= peer.total_s


def test_bench_rejects_bad_requests() -> None:
    with pytest.raises(InvalidInput, match="no-such"):
        bench("seq-ransac", [(96, 72)], baselines=["no-such"], progress=False)
    with pytest.raises(InvalidInput, match="--frames"):
        bench("seq-ransac", [(96, 72)], frames=0, progress=False)


def test_bench_complexity_axis_times_each_objects_range() -> None:
    results = bench("seq-ransac", [(96, 72)], repeat=2, frames=3, progress=False,
                    baselines=["open3d-ransac"], isolate=False, objects=[(1, 2), (8, 9)])
    assert [r.objects for r in results] == [(1, 2), (8, 9)]
    for r, counts in zip(results, ([1, 2, 1], [8, 9, 8]), strict=True):
        # Frame i of range (lo, hi) has lo + i % (hi - lo + 1) objects, seeds 0, 1, 2.
        assert [(f.seed, f.objects) for f in r.per_frame] == list(zip(range(3), counts,
                                                                      strict=True))
        assert r.gt_planes == pytest.approx(np.mean([f.gt_planes for f in r.per_frame]))
        assert r.planes == pytest.approx(np.mean([f.planes for f in r.per_frame]))
        for f in r.per_frame:
            assert f.total_s > 0 and 0 < f.baseline_call_s["open3d-ransac"]
    # More objects in view, more ground-truth planes.
    assert results[1].gt_planes > results[0].gt_planes
    text = format_bench(results)
    assert "96x72 1-2 obj ms" in text and "96x72 8-9 obj ms" in text
    assert "time against plane count" in text and "ground-truth planes (mean)" in text
    again = [BenchResult.from_dict(r.to_dict()) for r in results]
    assert format_bench(again) == text
    assert "| 96x72 | 8-9 |" in format_bench(results, markdown=True)


def test_bench_json_before_the_complexity_axis_still_reads() -> None:
    result = BenchResult("monoplane", 256, 192, 3, [StageBench("total", 0.1, 1.0)], 8.0, 400.0)
    old = {k: v for k, v in result.to_dict().items()
           if k not in ("objects", "gt_planes", "per_frame", "cpu_s")}
    again = BenchResult.from_dict(old)
    assert again.objects is None and np.isnan(again.gt_planes) and again.per_frame == []
    assert "time against plane count" not in format_bench([again])
    # Files written before the CPU time show it as unknown.
    assert np.isnan(again.cpu_s)
    cpu_row = next(line for line in format_bench([again]).splitlines()
                   if line.startswith("total CPU"))
    assert cpu_row.split()[-1] == "-"


@pytest.mark.parametrize("objects", [[(3, 2)], [(-1, 2)], []])
def test_bench_rejects_bad_objects_ranges(objects: list[tuple[int, int]]) -> None:
    with pytest.raises(InvalidInput, match="objects range"):
        bench("seq-ransac", [(96, 72)], objects=objects, progress=False)


def _write_sequence(root: Path, count: int) -> list[np.ndarray]:
    """A Redwood-style sequence of synthetic 96x72 frames: depth/ in millimetres, image/."""
    from monoplane.synth import generate

    (root / "depth").mkdir(parents=True)
    (root / "image").mkdir()
    depths = []
    for i in range(count):
        frame = generate(i, "clean", width=96, height=72, n_views=1).views[0].frame
        mm = np.round(frame.depth * 1000).astype(np.uint16)
        cv2.imwrite(str(root / "depth" / f"{i:05d}.png"), mm)
        cv2.imwrite(str(root / "image" / f"{i:05d}.jpg"), frame.rgb[..., ::-1])
        depths.append(mm / 1000.0)
    return depths


def test_data_frames_of_a_sequence_are_spread_and_depth_only(tmp_path: Path) -> None:
    depths = _write_sequence(tmp_path / "seq", 5)
    source = DataSource(str(tmp_path / "seq"), depth_scale=1000.0,
                        intrinsics="80,80,47.5,35.5", depth_only=True, frames=3)
    frames = load_data_frames(source)
    # Three of five, spread: the first, the middle and the last.
    assert [f.name for f in frames] == ["00000", "00002", "00004"]
    for f, i in zip(frames, (0, 2, 4), strict=True):
        assert f.rgb is None and f.normals is None
        np.testing.assert_allclose(f.depth, depths[i], atol=1e-6)
        assert f.K[0, 0] == 80.0
    with_colour = load_data_frames(DataSource(str(tmp_path / "seq"), depth_scale=1000.0))
    assert len(with_colour) == 5 and with_colour[0].rgb is not None


def test_data_frames_reject_what_they_cannot_read(tmp_path: Path) -> None:
    _write_sequence(tmp_path / "seq", 2)
    with pytest.raises(InvalidInput, match="depth-scale"):
        load_data_frames(DataSource(str(tmp_path / "seq")))
    (tmp_path / "seq" / "image" / "00001.jpg").unlink()
    with pytest.raises(InvalidInput, match="1 images in image/ but 2 depth maps"):
        load_data_frames(DataSource(str(tmp_path / "seq"), depth_scale=1000.0))
    with pytest.raises(InvalidInput, match="not found"):
        load_data_frames(DataSource(str(tmp_path / "nowhere")))


def test_bench_on_data_times_each_frame_with_the_baseline(tmp_path: Path) -> None:
    _write_sequence(tmp_path / "seq", 2)
    source = DataSource(str(tmp_path / "seq"), depth_scale=1000.0, depth_only=True,
                        intrinsics="80,80,47.5,35.5")
    (r,) = bench("seq-ransac", repeat=1, progress=False, baselines=["open3d-ransac"],
                 isolate=False, data=source, overrides=["cues.plugin=given"])
    assert (r.width, r.height, r.frames, r.data) == (96, 72, 2, source.path)
    assert [f.name for f in r.per_frame] == ["00000", "00001"]
    assert all(f.gt_planes is None and f.baseline_call_s["open3d-ransac"] > 0
               for f in r.per_frame)
    assert r.planes > 0 and np.isnan(r.gt_planes)
    text = format_bench([r])
    assert "seq 96x72 ms" in text and "00001" in text
    assert format_bench([BenchResult.from_dict(r.to_dict())]) == text
    with pytest.raises(InvalidInput, match="--data"):
        bench("seq-ransac", data=source, objects=[(1, 2)], progress=False)
