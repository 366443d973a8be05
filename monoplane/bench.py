"""Per-stage timing and memory of a pipeline preset on synthetic frames (``monoplane bench``).

Time
    Each size runs ``repeat`` timed pipeline calls on the same synthetic frame
    (``monoplane.synth.generate(seed, level, width, height)``, view 0) and reports the median of
    every entry of ``Reconstruction.timings``: the stage kinds the pipeline times (``cues``,
    ``ransac``, ``refiner``), the RANSAC driver's sub-steps (``ransac.cloud``, ``ransac.graph``,
    ``ransac.search``, ``ransac.label``, ``ransac.finalize``) and the wall time of the whole
    call (``total``). Timed runs do not trace memory.

Memory
    One extra, untimed run comes first (it also warms caches and imports). It traces
    allocations with :mod:`tracemalloc` and listens to the ``monoplane_stage_finished`` hook:
    a stage's figure is the peak of traced memory while it ran, *above* what was allocated when
    it started (the peak is reset at every stage boundary). tracemalloc sees every allocation
    made through Python's allocators, numpy arrays included, but not memory that C++ libraries
    (Open3D, the max-flow solver, the dense-CRF lattice) allocate for themselves. As a coarse
    complement the process's peak resident set size (``ru_maxrss``) after the size's runs is
    reported too; it only ever grows, so it bounds rather than measures each size.
"""

from __future__ import annotations

import resource
import sys
import time
import tracemalloc
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.hookspecs import hookimpl

#: Sizes benchmarked by default: the paper's working resolution and VGA.
DEFAULT_SIZES: tuple[tuple[int, int], ...] = ((256, 192), (640, 480))
#: Stage kinds in pipeline order, for sorting the table.
_STAGE_ORDER = ("cues", "ransac", "refiner")


class StagePeakTracker:
    """Pluggy plugin recording, per stage kind, the traced-memory peak of each stage call.

    Call :meth:`start` right before the pipeline runs; tracemalloc must be tracing.
    """

    def __init__(self) -> None:
        self.peaks: dict[str, int] = {}
        self._base = 0
        self._run_base = 0
        self._run_peak = 0

    def start(self) -> None:
        """Begin a new run (and its first stage window) at the current traced size."""
        self.peaks.clear()
        tracemalloc.reset_peak()
        self._base = self._run_base = self._run_peak = tracemalloc.get_traced_memory()[0]

    def run_peak(self) -> int:
        """Peak traced bytes since :meth:`start`, above the traced size at that moment."""
        return max(self._run_peak, tracemalloc.get_traced_memory()[1]) - self._run_base

    @hookimpl
    def monoplane_stage_finished(self, kind: str, name: str, seconds: float,
                                 frame_name: str) -> None:
        if not tracemalloc.is_tracing():  # timed runs are not traced
            return
        current, peak = tracemalloc.get_traced_memory()
        self.peaks[kind] = max(self.peaks.get(kind, 0), peak - self._base)
        self._run_peak = max(self._run_peak, peak)
        tracemalloc.reset_peak()
        self._base = current


@dataclass
class StageBench:
    """One row of the table.

    Attributes
    ----------
    name : str
        Timing key (``"ransac"``, ``"ransac.search"``, ``"total"``, ...).
    median_s : float
        Median seconds over the timed runs.
    peak_mib : float or None
        Traced peak memory above the stage's start, MiB; ``None`` for sub-steps (no hook).
    """

    name: str
    median_s: float
    peak_mib: float | None = None


@dataclass
class BenchResult:
    """Benchmark of one preset at one image size."""

    preset: str
    width: int
    height: int
    repeat: int
    stages: list[StageBench] = field(default_factory=list)
    planes: int = 0
    max_rss_mib: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form for JSON."""
        return {"preset": self.preset, "width": self.width, "height": self.height,
                "repeat": self.repeat, "planes": self.planes, "max_rss_mib": self.max_rss_mib,
                "stages": [{"name": s.name, "median_s": s.median_s, "peak_mib": s.peak_mib}
                           for s in self.stages]}


def _order(key: str) -> tuple[int, str, int]:
    """Sort key: stages in pipeline order, each followed by its sub-steps, ``total`` last.

    Sub-steps of one stage compare equal, so a stable sort keeps them in the order the
    pipeline recorded them.
    """
    if key == "total":
        return (len(_STAGE_ORDER) + 1, "", 0)
    parent, _, child = key.partition(".")
    rank = _STAGE_ORDER.index(parent) if parent in _STAGE_ORDER else len(_STAGE_ORDER)
    return (rank, parent, 1 if child else 0)


def _ordered(keys: Sequence[str]) -> list[str]:
    return sorted(dict.fromkeys(keys), key=_order)


def _max_rss_mib() -> float:
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    # Linux reports KiB, macOS bytes.
    return rss / (1024.0 * 1024.0) if sys.platform == "darwin" else rss / 1024.0


def bench(preset: str = "monoplane", sizes: Sequence[tuple[int, int]] = DEFAULT_SIZES,
          repeat: int = 5, seed: int = 0, level: str = "mild",
          overrides: list[str] | None = None, progress: bool = True) -> list[BenchResult]:
    """Time and profile a preset at several image sizes.

    Parameters
    ----------
    preset : str
        Pipeline preset (the cue provider is forced to ``given``: the synthetic frame carries
        its cues, so ``cues`` measures the pass-through only).
    sizes : sequence of (int, int)
        ``(width, height)`` pairs in pixels.
    repeat : int
        Timed runs per size (median reported).
    seed : int
        Synthetic scene seed.
    level : str
        Cue corruption level of :func:`monoplane.synth.generate`.
    overrides : list of str, optional
        Extra ``table.key=value`` overrides.
    progress : bool
        Show a tqdm progress bar on stderr.

    Returns
    -------
    list of BenchResult
        One per size, in the given order.
    """
    from tqdm import tqdm

    from monoplane.pipeline import Pipeline
    from monoplane.plugin_manager import get_plugin_manager
    from monoplane.synth import generate

    if repeat < 1:
        raise InvalidInput(f"--repeat must be at least 1, got {repeat}")
    if not sizes:
        raise InvalidInput("no image size to benchmark")
    tracker = StagePeakTracker()
    pm = get_plugin_manager(extra_plugins=(tracker,))
    pipe = Pipeline.from_preset(preset, overrides=["cues.plugin=given", *(overrides or [])],
                                pm=pm)
    results = []
    bar = tqdm(total=len(sizes) * (repeat + 1), disable=not progress, unit="run", desc="bench")
    try:
        for width, height in sizes:
            bar.set_postfix_str(f"{width}x{height}")
            frame = generate(seed, level, width=width, height=height, n_views=1).views[0].frame
            tracemalloc.start()
            try:
                tracker.start()
                pipe.run(frame)
                total_peak = tracker.run_peak()
            finally:
                tracemalloc.stop()
            peaks = {**tracker.peaks, "total": total_peak}
            bar.update(1)
            runs: list[dict[str, float]] = []
            planes = 0
            for _ in range(repeat):
                start = time.perf_counter()
                rec = pipe.run(frame)
                timings = dict(rec.timings)
                timings.setdefault("total", time.perf_counter() - start)
                runs.append(timings)
                planes = rec.num_planes
                bar.update(1)
            keys = _ordered([k for r in runs for k in r])
            stages = [StageBench(k, float(np.median([r.get(k, 0.0) for r in runs])),
                                 peaks[k] / 2**20 if k in peaks else None) for k in keys]
            results.append(BenchResult(preset, width, height, repeat, stages, planes,
                                       _max_rss_mib()))
    finally:
        bar.close()
    return results


def parse_sizes(text: str) -> list[tuple[int, int]]:
    """Parse ``"256x192,640x480"`` into ``[(256, 192), (640, 480)]``."""
    from monoplane.evaluation.runner import parse_size

    sizes = [parse_size(part.strip()) for part in text.split(",") if part.strip()]
    if not sizes:
        raise InvalidInput(f"no size in '{text}'; use e.g. 256x192,640x480")
    return sizes


def format_bench(results: Sequence[BenchResult]) -> str:
    """Aligned text table: one column pair (median ms, peak MiB) per size, one row per stage."""
    if not results:
        return ""
    keys = _ordered([s.name for r in results for s in r.stages])
    header = ["stage"]
    for r in results:
        header += [f"{r.width}x{r.height} ms", "MiB"]
    rows = []
    for k in keys:
        label = f"  {k.partition('.')[2]}" if "." in k else k
        row = [label]
        for r in results:
            s = next((s for s in r.stages if s.name == k), None)
            row.append(f"{1000 * s.median_s:.1f}" if s else "-")
            row.append(f"{s.peak_mib:.1f}" if s and s.peak_mib is not None else "")
        rows.append(row)
    widths = [max(len(row[c]) for row in [header, *rows]) for c in range(len(header))]

    def line(cells: list[str]) -> str:
        return "  ".join([cells[0].ljust(widths[0]),
                          *[c.rjust(w) for c, w in zip(cells[1:], widths[1:], strict=True)]])

    r0 = results[0]
    title = (f"preset {r0.preset}: median of {r0.repeat} runs per size; MiB = traced peak "
             f"above the stage's start (tracemalloc)")
    foot = "; ".join(f"{r.width}x{r.height}: {r.planes} planes, process max RSS "
                     f"{r.max_rss_mib:.0f} MiB" for r in results)
    return "\n".join([title, line(header), "-" * len(line(header)), *[line(r) for r in rows],
                      foot])
