"""Per-stage timing, throughput and memory of a preset against baselines (``monoplane bench``).

Frames
    Each size runs the preset on ``frames`` synthetic frames (seeds ``seed .. seed+frames-1``,
    ``monoplane.synth.generate(seed, level, width, height)``, view 0), each ``repeat`` times.
    Medians are over all those runs.

Scene complexity
    With ``objects`` ranges (e.g. :data:`COMPLEXITY_LEVELS`: 0, 1-2, 4-6 and 8-12 objects), every
    size runs once per range on its own frames: frame ``i`` of range ``(lo, hi)`` is
    ``generate(seed + i, level, width, height, objects=lo + i % (hi - lo + 1))``, the same room
    and camera as the usual scene of that seed, furnished with that many objects in view. Each
    (size, range) is one result with the mean ground-truth and found plane counts beside its
    times, and per-frame medians in :attr:`BenchResult.per_frame`: time against plane count.

Your own frames
    With ``data`` (:class:`monoplane.evaluation.bench_frames.DataSource`, ``monoplane bench
    --data DIR``) the frames are read from a folder instead (the layouts ``monoplane batch``
    reads, or a Redwood-style ``depth/`` + ``image/`` sequence; see
    :mod:`monoplane.evaluation.bench_frames`), and the sizes and objects ranges do not apply:
    one result, whose size is that of the first frame.
    Frames without normals (depth-only) have them estimated by the preset's cue stage, inside
    the timed call; a baseline needs normals, so it gets the ones the preset estimated and its
    time does not include them.

Time
    Every entry of ``Reconstruction.timings``: the stage kinds the pipeline times (``cues``,
    ``ransac``, ``refiner``), their sub-steps (``ransac.graph``, ``refiner.crf``, ...) and the
    wall time of the whole call (``total``); throughput is ``1 / median total``. The first call
    of a fresh process is reported apart (``first call``): it loads the numba kernels from
    their on-disk cache (or compiles them once, the first time ever). ``total CPU`` is the
    median process time (:func:`time.process_time`, every thread of the process) of the whole
    call: on a machine shared with other jobs it grows far less than the wall time, so it is
    the figure to compare across runs there.

Baselines
    Every registered baseline (``monoplane_register_baselines``: the built-in one and those of
    installed plugins) runs on the same frames in the same process. ``call`` is the baseline's
    own call alone (``timings["baseline.call"]``, without converting the cloud into the
    library's data structure), ``total`` the whole baseline call. The ratio is the preset's
    median ``total`` over the baseline's median ``call``. Timed runs are interleaved: each
    frame's preset run is followed at once by the baselines' runs on that frame, so a machine
    whose speed drifts over the minutes of a run (a shared virtual machine's does, by 20-30 %)
    slows both sides of the ratio alike.

Memory
    Each size runs in a fresh child process, so that its peak resident set size
    (``ru_maxrss``, read after one untimed preset run on every frame and before any baseline
    runs) is that size's own: imports, the frames and the preset's peak. One extra untimed run
    traces allocations with :mod:`tracemalloc` and listens to the ``monoplane_stage_finished`` hook:
    a stage's ``MiB`` is the peak of traced memory while it ran, above what was allocated when
    it started. tracemalloc sees Python and numpy allocations, not memory that C++ libraries
    (Open3D, the max-flow solver) allocate for themselves; the RSS covers those.
"""

from __future__ import annotations

import importlib
import multiprocessing
import resource
import sys
import time
import tracemalloc
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.evaluation.baselines import CALL_TIMING, baseline_names, get_baseline
from monoplane.evaluation.bench_frames import DataSource, load_data_frames
from monoplane.evaluation.runner import parse_size
from monoplane.hookspecs import hookimpl
from monoplane.host.allocator import keep_freed_memory
from monoplane.host.registry import get_plugin_manager

if TYPE_CHECKING:
    from monoplane.datamodel import Frame

#: Sizes benchmarked by default: the paper's working resolution and VGA.
DEFAULT_SIZES: tuple[tuple[int, int], ...] = ((256, 192), (640, 480))
#: Scene-complexity levels of ``monoplane bench --complexity``: objects per scene, (min, max).
#: The first is the bare room (walls, floor and ceiling: a few large planes, 3-4 in view).
COMPLEXITY_LEVELS: tuple[tuple[int, int], ...] = ((0, 0), (1, 2), (4, 6), (8, 12))
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
class BaselineBench:
    """Same-run timing of one baseline: median seconds of its core call and of the whole call."""

    name: str
    call_s: float
    total_s: float


@dataclass
class FrameBench:
    """One frame of a result: its scene and its median times over the ``repeat`` runs.

    Attributes
    ----------
    seed : int
        Seed of the synthetic scene; with ``--data``, the frame's index in the run.
    objects : int or None
        Objects in the scene; ``None`` for the usual furnishing.
    gt_planes : int or None
        Ground-truth planes in view; ``None`` for a user's frame (``--data``).
    planes : float
        Planes the preset found (mean over the runs; runs of one frame agree).
    total_s : float
        Median seconds of the preset's whole call.
    baseline_call_s : dict of str to float
        Median seconds of each baseline's core call on this frame.
    """

    seed: int
    objects: int | None
    gt_planes: int | None
    planes: float
    total_s: float
    baseline_call_s: dict[str, float] = field(default_factory=dict)
    name: str | None = None


@dataclass
class BenchResult:
    """Benchmark of one preset at one image size (and one scene-complexity range)."""

    preset: str
    width: int
    height: int
    repeat: int
    stages: list[StageBench] = field(default_factory=list)
    planes: float = 0.0
    max_rss_mib: float = 0.0
    frames: int = 1
    first_call_s: float = 0.0
    baselines: list[BaselineBench] = field(default_factory=list)
    objects: tuple[int, int] | None = None
    gt_planes: float = float("nan")
    per_frame: list[FrameBench] = field(default_factory=list)
    data: str | None = None
    cpu_s: float = float("nan")

    @property
    def column(self) -> str:
        """Column title of this result: the size, and the objects range or data folder."""
        size = f"{self.width}x{self.height}"
        if self.data is not None:
            return f"{Path(self.data).name} {size}"
        if self.objects is None:
            return size
        lo, hi = self.objects
        return f"{size} {lo}-{hi} obj" if hi != lo else f"{size} {lo} obj"

    @property
    def total_s(self) -> float:
        """Median seconds of the whole pipeline call."""
        return next((s.median_s for s in self.stages if s.name == "total"), float("nan"))

    @property
    def fps(self) -> float:
        """Throughput, frames per second (1 / median total)."""
        return 1.0 / self.total_s if self.total_s > 0 else float("nan")

    def ratio(self, baseline: BaselineBench) -> float:
        """Median pipeline time over the baseline's median core-call time."""
        return self.total_s / baseline.call_s if baseline.call_s > 0 else float("nan")

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form for JSON (with the derived throughput and ratios)."""
        return {"preset": self.preset, "width": self.width, "height": self.height,
                "objects": None if self.objects is None else list(self.objects),
                "repeat": self.repeat, "frames": self.frames, "planes": self.planes,
                "gt_planes": None if np.isnan(self.gt_planes) else self.gt_planes,
                "max_rss_mib": self.max_rss_mib, "first_call_s": self.first_call_s,
                "fps": self.fps,
                "stages": [asdict(s) for s in self.stages],
                "baselines": [{**asdict(b), "ratio": self.ratio(b)} for b in self.baselines],
                "per_frame": [asdict(f) for f in self.per_frame], "data": self.data,
                "cpu_s": None if np.isnan(self.cpu_s) else self.cpu_s}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> BenchResult:
        """Inverse of :meth:`to_dict` (derived fields are recomputed; files written before
        the complexity axis have no ``objects``, ``gt_planes`` or ``per_frame``, those before
        the CPU time no ``cpu_s``)."""
        objects = data.get("objects")
        gt_planes = data.get("gt_planes")
        cpu_s = data.get("cpu_s")
        return cls(data["preset"], data["width"], data["height"], data["repeat"],
                   [StageBench(**s) for s in data["stages"]], data["planes"],
                   data["max_rss_mib"], data.get("frames", 1), data.get("first_call_s", 0.0),
                   [BaselineBench(b["name"], b["call_s"], b["total_s"])
                    for b in data.get("baselines", [])],
                   None if objects is None else (int(objects[0]), int(objects[1])),
                   float("nan") if gt_planes is None else float(gt_planes),
                   [FrameBench(**f) for f in data.get("per_frame", [])], data.get("data"),
                   float("nan") if cpu_s is None else float(cpu_s))


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
          repeat: int = 3, seed: int = 0, level: str = "mild",
          overrides: list[str] | None = None, progress: bool = True, frames: int = 5,
          baselines: Sequence[str] | None = None, plugins: Sequence[str] = (),
          isolate: bool = True, objects: Sequence[tuple[int, int]] | None = None,
          data: DataSource | None = None) -> list[BenchResult]:
    """Time and profile a preset, and the baselines on the same frames, at several sizes.

    Parameters
    ----------
    preset : str
        Pipeline preset (the frames carry their cues, so the cue step is a pass-through).
    sizes : sequence of (int, int)
        ``(width, height)`` pairs in pixels.
    repeat : int
        Timed runs per frame.
    seed : int
        Seed of the first synthetic frame.
    level : str
        Cue corruption level of :func:`monoplane.synth.generate`.
    overrides : list of str, optional
        Extra ``table.key=value`` overrides.
    progress : bool
        Show a tqdm progress bar (one step per size) on stderr.
    frames : int
        Synthetic frames per size (seeds ``seed .. seed + frames - 1``).
    baselines : sequence of str, optional
        Baselines to time on the same frames; ``None``: every registered one, ``[]``: none.
    plugins : sequence of str
        Extra plugin modules to register (by import name), e.g. a baseline not installed.
    isolate : bool
        Run each size (and range) in a fresh child process (its own peak RSS; see the module
        docstring) with the command line's allocator policy
        (:func:`~monoplane.host.allocator.keep_freed_memory`). False: in this process, whose
        allocator policy is left as it is.
    objects : sequence of (int, int), optional
        Scene-complexity ranges ``(min, max)`` of objects per scene (e.g.
        :data:`COMPLEXITY_LEVELS`); ``None``: the usual scenes. See the module docstring.
    data : DataSource, optional
        Time on these frames instead of synthetic ones (``sizes``, ``frames``, ``seed``,
        ``level`` and ``objects`` then do not apply; the source has its own frame cap).

    Returns
    -------
    list of BenchResult
        One per size, in the given order; with ``objects``, one per size and range, ranges
        varying fastest; with ``data``, one.
    """
    from tqdm import tqdm

    if repeat < 1:
        raise InvalidInput(f"--repeat must be at least 1, got {repeat}")
    if frames < 1:
        raise InvalidInput(f"--frames must be at least 1, got {frames}")
    if not sizes:
        raise InvalidInput("no image size to benchmark")
    ranges: list[tuple[int, int] | None] = [None]
    if data is not None:
        if objects is not None:
            raise InvalidInput("--objects and --complexity apply to synthetic frames, not --data")
        sizes = [(0, 0)]  # the frames' own
        load_data_frames(data)  # bad input fails here, before any child starts
    if objects is not None:
        ranges = [(int(lo), int(hi)) for lo, hi in objects]
        if not ranges:
            raise InvalidInput("no objects range to benchmark")
        bad = next((r for r in ranges if not 0 <= r[0] <= r[1]), None)
        if bad is not None:
            raise InvalidInput(f"objects range {bad[0]}-{bad[1]}: need 0 <= min <= max")
    # Resolve names now, in this process, so that bad input fails before any child starts.
    from monoplane.host.pipeline import Pipeline  # loads OpenCV

    Pipeline.from_preset(preset, overrides=list(overrides or []))
    names = baseline_names(_plugin_manager(plugins))
    chosen = names if baselines is None else list(baselines)
    unknown = [b for b in chosen if b not in names]
    if unknown:
        raise InvalidInput(f"unknown baseline '{unknown[0]}'; valid choices: "
                           f"{', '.join(names) or '(none)'}")
    args = [(preset, list(overrides or []), size, seed, frames, level, repeat, chosen,
             list(plugins), span, data) for size in sizes for span in ranges]
    results = []
    for arg in tqdm(args, disable=not progress, unit="run", desc="bench"):
        if isolate:
            ctx = multiprocessing.get_context("spawn")
            # The child starts with the C library's default allocator policy: give it the
            # command line's (monoplane.host.allocator), so its peak memory is the CLI's.
            with ProcessPoolExecutor(max_workers=1, mp_context=ctx,
                                     initializer=keep_freed_memory) as pool:
                results.append(pool.submit(_bench_size, *arg).result())
        else:
            results.append(_bench_size(*arg))
    return results


def _plugin_manager(plugins: Sequence[str], *extra: object) -> Any:
    try:
        modules = tuple(importlib.import_module(name) for name in plugins)
    except ImportError as exc:
        raise InvalidInput(f"cannot import plugin module: {exc}") from exc
    return get_plugin_manager(extra_plugins=(*modules, *extra))


def _bench_size(preset: str, overrides: list[str], size: tuple[int, int], seed: int,
                frames: int, level: str, repeat: int, baselines: list[str],
                plugins: list[str], objects: tuple[int, int] | None = None,
                data: DataSource | None = None) -> BenchResult:
    """One size (and objects range), or the data frames, of :func:`bench` (in a child process
    when isolated)."""
    # the pipeline and the generator load OpenCV
    from monoplane.host.pipeline import Pipeline
    from monoplane.synth import generate

    tracker = StagePeakTracker()
    pm = _plugin_manager(plugins, tracker)
    pipe = Pipeline.from_preset(preset, overrides=overrides, pm=pm)
    width, height = size
    counts = [None if objects is None else objects[0] + i % (objects[1] - objects[0] + 1)
              for i in range(frames)]
    views: list[Frame] = []
    gt_planes: list[int | None] = []
    if data is not None:
        views = load_data_frames(data)
        frames, seed = len(views), 0
        counts, gt_planes = [None] * frames, [None] * frames
        height, width = views[0].shape
    for i in range(frames if data is None else 0):  # only the frames and plane counts: the
        view = generate(seed + i, level, width=width, height=height, n_views=1,  # peak RSS is
                        objects=counts[i]).views[0]                             # the preset's
        views.append(view.frame)
        gt_planes.append(len(view.gt_params))
    start = time.perf_counter()
    pipe.run(views[0])
    first_call = time.perf_counter() - start
    tracemalloc.start()
    try:
        tracker.start()
        pipe.run(views[0])
        total_peak = tracker.run_peak()
    finally:
        tracemalloc.stop()
    peaks = {**tracker.peaks, "total": total_peak}
    # Baselines need normals: a depth-only frame's are the ones the preset estimated.
    base_views = [views[0] if views[0].normals is not None else pipe.run(views[0]).frame]
    for frame in views[1:]:  # every frame once before the RSS is read
        rec = pipe.run(frame)
        base_views.append(frame if frame.normals is not None else rec.frame)
    rss = _max_rss_mib()  # before any baseline runs: the preset's own peak
    fns = [get_baseline(name, pm) for name in baselines]
    runs: list[dict[str, float]] = []
    cpu: list[float] = []
    planes = []
    calls: list[list[float]] = [[] for _ in baselines]
    totals: list[list[float]] = [[] for _ in baselines]
    for i, frame in enumerate(views):
        for _ in range(repeat):
            start, start_cpu = time.perf_counter(), time.process_time()
            rec = pipe.run(frame)
            cpu.append(time.process_time() - start_cpu)
            timings = dict(rec.timings)
            timings.setdefault("total", time.perf_counter() - start)
            runs.append(timings)
            planes.append(rec.num_planes)
            for b, fn in enumerate(fns):  # right after, on the same frame (see "Baselines")
                start = time.perf_counter()
                base = fn(base_views[i], seed=seed + i)
                totals[b].append(time.perf_counter() - start)
                calls[b].append(base.timings.get(CALL_TIMING, totals[b][-1]))
    keys = _ordered([k for r in runs for k in r])
    stages = [StageBench(k, float(np.median([r.get(k, 0.0) for r in runs])),
                         peaks[k] / 2**20 if k in peaks else None) for k in keys]
    timed = [BaselineBench(name, float(np.median(c)), float(np.median(t)))
             for name, c, t in zip(baselines, calls, totals, strict=True)]
    per_frame = []
    for i in range(frames):
        rows = slice(i * repeat, (i + 1) * repeat)  # runs are in frame order, repeat each
        per_frame.append(FrameBench(
            seed + i, counts[i], gt_planes[i], float(np.mean(planes[rows])),
            float(np.median([r["total"] for r in runs[rows]])),
            {name: float(np.median(c[rows])) for name, c in zip(baselines, calls, strict=True)},
            views[i].name if data is not None else None))
    known = [f.gt_planes for f in per_frame if f.gt_planes is not None]
    return BenchResult(preset, width, height, repeat, stages, float(np.mean(planes)), rss,
                       frames, first_call, timed, objects,
                       float(np.mean(known)) if known else float("nan"), per_frame,
                       None if data is None else data.path, float(np.median(cpu)))


def parse_sizes(text: str) -> list[tuple[int, int]]:
    """Parse ``"256x192,640x480"`` into ``[(256, 192), (640, 480)]``."""
    sizes = [parse_size(part.strip()) for part in text.split(",") if part.strip()]
    if not sizes:
        raise InvalidInput(f"no size in '{text}'; use e.g. 256x192,640x480")
    return sizes


def format_bench(results: Sequence[BenchResult], markdown: bool = False) -> str:
    """One table: a column pair (median ms, traced MiB) per size (and objects range); a row per
    stage and sub-step, then throughput, first call, peak RSS, the mean found and ground-truth
    plane counts and, per baseline, its call, its whole call and the ratio of the preset's total
    to the baseline's call. With objects ranges a second table follows: time against plane
    count, one row per size and range (:func:`format_complexity`)."""
    if not results:
        return ""
    keys = _ordered([s.name for r in results for s in r.stages])
    header = ["stage"]
    for r in results:
        header += [f"{r.column} ms", "MiB"]
    rows = []
    for k in keys:
        # Sub-steps are indented in text; Markdown cells drop leading spaces, so keep the key.
        label = f"  {k.partition('.')[2]}" if "." in k and not markdown else k
        row = [label]
        for r in results:
            s = next((s for s in r.stages if s.name == k), None)
            row.append(f"{1000 * s.median_s:.1f}" if s else "-")
            row.append(f"{s.peak_mib:.1f}" if s and s.peak_mib is not None else "")
        rows.append(row)
    rows.append(["total CPU (process time)",
                 *[c for r in results for c in (_number(1000 * r.cpu_s), "")]])
    rows.append(["throughput (frames/s)", *[c for r in results for c in (f"{r.fps:.2f}", "")]])
    rows.append(["first call (fresh process)",
                 *[c for r in results for c in (f"{1000 * r.first_call_s:.1f}", "")]])
    rows.append(["peak RSS (MiB)", *[c for r in results for c in ("", f"{r.max_rss_mib:.0f}")]])
    rows.append(["planes found (mean)", *[c for r in results for c in (f"{r.planes:.1f}", "")]])
    rows.append(["ground-truth planes (mean)",
                 *[c for r in results for c in (_number(r.gt_planes), "")]])
    for name in _baseline_names(results):
        found = [next((b for b in r.baselines if b.name == name), None) for r in results]
        rows.append([f"{name}: call", *[c for b in found for c in
                                        (f"{1000 * b.call_s:.1f}" if b else "-", "")]])
        rows.append([f"{name}: whole call", *[c for b in found for c in
                                              (f"{1000 * b.total_s:.1f}" if b else "-", "")]])
        rows.append([f"ratio total / {name} call",
                     *[c for r, b in zip(results, found, strict=True)
                       for c in (f"{r.ratio(b):.2f}x" if b else "-", "")]])
    r0 = results[0]
    title = (f"preset {r0.preset}: median over {r0.frames} frames x {r0.repeat} runs per column; "
             f"MiB = traced peak above the stage's start (tracemalloc); mean planes "
             + ", ".join(f"{r.planes:.1f}" for r in results))
    text = "\n".join([title, *([""] if markdown else []), _render(header, rows, markdown)])
    if any(r.objects is not None or r.data is not None for r in results):
        text += "\n\n" + format_complexity(results, markdown)
    return text


def format_complexity(results: Sequence[BenchResult], markdown: bool = False) -> str:
    """Time against plane count: a row per result (size and objects range) with its objects,
    mean ground-truth and found planes, median total and, per baseline, the median call and
    the ratio of the two; then each frame's planes and times (per-frame medians)."""
    names = _baseline_names(results)
    header = ["size", "objects", "GT planes", "planes found", "total ms"]
    for name in names:
        header += [f"{name} call ms", f"ratio / {name}"]
    rows = []
    for r in results:
        span = ("usual" if r.data is None else "-") if r.objects is None \
            else f"{r.objects[0]}-{r.objects[1]}"
        row = [f"{r.width}x{r.height}", span, _number(r.gt_planes), f"{r.planes:.1f}",
               f"{1000 * r.total_s:.1f}"]
        for name in names:
            b = next((b for b in r.baselines if b.name == name), None)
            row += [f"{1000 * b.call_s:.1f}", f"{r.ratio(b):.2f}x"] if b else ["-", "-"]
        rows.append(row)
    frame_header = ["size", "frame", "objects", "GT planes", "planes found", "total ms",
                    *[f"{name} call ms" for name in names]]
    frame_rows = [[f"{r.width}x{r.height}", f.name or str(f.seed), "-" if f.objects is None
                   else str(f.objects), "-" if f.gt_planes is None else str(f.gt_planes),
                   f"{f.planes:.1f}",
                   f"{1000 * f.total_s:.1f}",
                   *[f"{1000 * f.baseline_call_s[n]:.1f}" if n in f.baseline_call_s else "-"
                     for n in names]]
                  for r in results for f in r.per_frame]
    parts = [f"time against plane count (preset {results[0].preset}; medians; ratio = total / "
             "baseline call)", *([""] if markdown else []), _render(header, rows, markdown)]
    if frame_rows:
        parts += ["", "per frame (medians over its runs)", *([""] if markdown else []),
                  _render(frame_header, frame_rows, markdown)]
    return "\n".join(parts)


def _number(value: float) -> str:
    return "-" if np.isnan(value) else f"{value:.1f}"


def _baseline_names(results: Sequence[BenchResult]) -> list[str]:
    return list(dict.fromkeys(b.name for r in results for b in r.baselines))


def _render(header: list[str], rows: list[list[str]], markdown: bool) -> str:
    """A table as Markdown, or as aligned text (first column left, the others right)."""
    if markdown:
        lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        lines += ["| " + " | ".join(c.strip() or " " for c in row) + " |" for row in rows]
        return "\n".join(lines)
    widths = [max(len(row[c]) for row in [header, *rows]) for c in range(len(header))]

    def line(cells: list[str]) -> str:
        return "  ".join([cells[0].ljust(widths[0]),
                          *[c.rjust(w) for c, w in zip(cells[1:], widths[1:], strict=True)]])

    return "\n".join([line(header), "-" * len(line(header)), *[line(r) for r in rows]])
