"""Batch throughput against the number of workers (``monoplane bench --batch``).

Frames
    ``frames`` synthetic single-view frames of one size, written once into a temporary folder
    in the layout of ``data_samples/room_000``
    (:func:`monoplane.synth.batchset.write_frame_folder`).

Runs
    Each run is the ``monoplane batch`` command a user types (``--overwrite --quiet``, a fresh
    output folder), started as a child process, so that it pays what a user pays: the
    interpreter, the imports, forking the workers and loading the numba kernels in each of
    them. The worker counts (and engines) are run in alternation, ``repeat`` rounds, so that a
    machine whose speed drifts over the minutes of a run slows every setting alike.

Figures, medians over the rounds
    ``command``: wall time of the whole command, from starting the interpreter to its exit.
    ``batch``: the ``seconds`` that ``summary.json`` reports, the time :func:`run_batch` took
    from reading the input to writing the summary: the command less the interpreter's start,
    the imports and its exit, which are the same whatever the number of workers.
    ``frames/s`` is ``frames / batch``. The speed-up of a setting is the median of the
    per-round ratios of the same engine's first worker count to it.

Memory and drift, per setting (medians over the rounds)
    While each command runs, the memory of its whole process tree (the driver, its workers and
    whatever they start) is sampled from ``/proc`` every ``interval`` seconds, with the
    number of frames done: the sum of the processes' RSS (shared pages counted once per
    process, as ``top`` shows them) and of their PSS (shared pages divided among the
    processes that share them). ``peak RSS`` and ``peak PSS`` are the largest sums;
    ``RSS first / last`` the median RSS while the first ``window`` frames ran (from the moment
    every worker had finished a frame, i.e. was warm) and while the last ``window`` ran.
    ``frame ms first / last`` are the median times, in their workers, of the first ``window``
    frames and of the last (input order, the order frames are handed out; from
    ``summary.json``). Those are wall times, so on a machine that other work shares they
    follow its load as much as the batch. ``CPU ms/frame first / last`` does not: the CPU
    time (user + system) the whole tree spent while those frames ran, from the samples, over
    the number of frames done meanwhile. Over a long batch (``--frames 1000``) these show
    whether memory grows and frames slow down as the batch goes on.

Long batches
    Only the first ``distinct`` (50) frames are written; a batch of more frames is a manifest
    cycling over them, so that a 1000-frame batch does not spend minutes writing its input,
    and every stretch of it sees the same mix of scenes.
"""

from __future__ import annotations

import csv
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from monoplane.batch.engines import check_engine
from monoplane.errors import InvalidInput
from monoplane.synth.batchset import write_frame_folder


@dataclass
class BatchSetting:
    """Timings of one (engine, workers) setting over the rounds.

    Attributes
    ----------
    engine : str
        ``"local"`` or ``"ray"``.
    workers : int
        ``--workers`` of the command.
    command_s, batch_s : list of float
        Per round: wall seconds of the whole command, and the batch's own seconds.
    command_speedup, batch_speedup : list of float
        Per round: the engine's first setting's seconds over this one's (1 for that one).
    peak_rss, peak_pss : list of float or None
        Per round: the largest RSS and PSS of the command's process tree, MiB.
    rss_first, rss_last : list of float or None
        Per round: median RSS of the tree while the first and the last ``window`` frames ran
        (None when no sample fell in that stretch: a batch of a few seconds).
    frame_first, frame_last : list of float or None
        Per round: median seconds of the first and the last ``window`` frames in their
        workers.
    cpu_first, cpu_last : list of float or None
        Per round: CPU seconds of the process tree per frame while the first (once the
        workers were warm) and the last ``window`` frames ran.
    """

    engine: str
    workers: int
    command_s: list[float] = field(default_factory=list)
    batch_s: list[float] = field(default_factory=list)
    command_speedup: list[float] = field(default_factory=list)
    batch_speedup: list[float] = field(default_factory=list)
    peak_rss: list[float | None] = field(default_factory=list)
    peak_pss: list[float | None] = field(default_factory=list)
    rss_first: list[float | None] = field(default_factory=list)
    rss_last: list[float | None] = field(default_factory=list)
    frame_first: list[float | None] = field(default_factory=list)
    frame_last: list[float | None] = field(default_factory=list)
    cpu_first: list[float | None] = field(default_factory=list)
    cpu_last: list[float | None] = field(default_factory=list)


@dataclass
class BatchBenchResult:
    """All settings of one ``monoplane bench --batch`` run.

    ``distinct`` frames were written (the batch cycles over them); ``window`` frames at each
    end are compared (0 in runs saved before memory and drift were measured).
    """

    preset: str
    width: int
    height: int
    frames: int
    level: str
    settings: list[BatchSetting]
    distinct: int = 0
    window: int = 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``kind: "batch"``)."""
        return {"kind": "batch", **asdict(self)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> BatchBenchResult:
        """Inverse of :meth:`to_dict`."""
        return cls(data["preset"], data["width"], data["height"], data["frames"],
                   data["level"], [BatchSetting(**s) for s in data["settings"]],
                   data.get("distinct", data["frames"]), data.get("window", 0))


def _median(values: Sequence[float]) -> float:
    return statistics.median(values) if values else float("nan")


def _process_tree(root: int) -> list[int]:
    """``root`` and every process descended from it, from ``/proc``."""
    children: dict[int, list[int]] = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/stat") as fh:
                ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue  # ended while we looked
        children.setdefault(ppid, []).append(int(entry.name))
    tree, todo = [], [root]
    while todo:
        pid = todo.pop()
        tree.append(pid)
        todo.extend(children.get(pid, []))
    return tree


#: Clock ticks per second of /proc's CPU times (the module still imports where there is none).
_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def tree_usage(root: int) -> tuple[float, float, dict[int, float]]:
    """RSS and PSS (MiB) of a process and all its living descendants, and the CPU time each of
    them has used so far (user + system, seconds, by pid) (Linux ``/proc``)."""
    rss = pss = 0
    cpu: dict[int, float] = {}
    for pid in _process_tree(root):
        try:
            with open(f"/proc/{pid}/stat") as fh:
                fields = fh.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{pid}/smaps_rollup") as fh:
                for line in fh:
                    if line.startswith("Rss:"):
                        rss += int(line.split()[1])
                    elif line.startswith("Pss:"):
                        pss += int(line.split()[1])
            cpu[pid] = (int(fields[11]) + int(fields[12])) / _TICK  # utime, stime
        except (OSError, IndexError, ValueError):
            continue  # ended while we looked
    return rss / 1024.0, pss / 1024.0, cpu


@dataclass
class _Run:
    """One command: wall and batch seconds, each frame's seconds (input order), and samples of
    its process tree (seconds since the start, frames done, RSS MiB, PSS MiB, CPU seconds)."""

    wall: float
    batch: float
    frame_s: list[float]
    memory: list[tuple[float, int, float, float, float]]


def _run_command(args: list[str], out: Path, frames: int, interval: float) -> _Run:
    """Run one ``monoplane batch`` command, sampling its process tree's memory."""
    memory: list[tuple[float, int, float, float, float]] = []
    start = time.perf_counter()
    proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)

    used: dict[int, float] = {}  # CPU seconds by pid, kept after a process has ended

    def sample() -> None:
        while proc.poll() is None:
            rss, pss, cpu = tree_usage(proc.pid)
            used.update(cpu)
            done = (sum(e.is_dir() and not e.name.startswith(".") for e in os.scandir(out))
                    if out.is_dir() else 0)
            if rss:
                memory.append((time.perf_counter() - start, done, rss, pss,
                               sum(used.values())))
            time.sleep(interval)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    _, err = proc.communicate()
    wall = time.perf_counter() - start
    sampler.join()
    if proc.returncode != 0:
        last = (err.strip().splitlines() or ["no output"])[-1]
        raise InvalidInput(f"'{' '.join(args[3:])}' exited with {proc.returncode}: {last}")
    summary = json.loads((out / "summary.json").read_text())
    if summary["counts"]["ok"] != frames:
        raise InvalidInput(f"the batch in {out} did {summary['counts']['ok']} of {frames} "
                           f"frames: {summary['counts']}")
    return _Run(wall, float(summary["seconds"]), [float(f["seconds"]) for f in
                                                  summary["frames"]], memory)


def _record(s: BatchSetting, run: _Run, frames: int, window: int) -> None:
    """Add one round's figures to a setting (see the module docstring)."""
    s.command_s.append(run.wall)
    s.batch_s.append(run.batch)
    def median(values: list[float]) -> float | None:  # None: no sample (a short batch)
        return round(statistics.median(values), 4) if values else None

    s.peak_rss.append(max((round(m[2], 1) for m in run.memory), default=None))
    s.peak_pss.append(max((round(m[3], 1) for m in run.memory), default=None))
    s.rss_first.append(median([m[2] for m in run.memory if s.workers <= m[1] < window]))
    s.rss_last.append(median([m[2] for m in run.memory if m[1] >= frames - window]))
    s.frame_first.append(median(run.frame_s[:window]))
    s.frame_last.append(median(run.frame_s[-window:]))

    def cpu_per_frame(samples: list[tuple[float, int, float, float, float]]) -> float | None:
        if len(samples) < 2 or samples[-1][1] == samples[0][1]:
            return None
        return round((samples[-1][4] - samples[0][4]) / (samples[-1][1] - samples[0][1]), 5)

    s.cpu_first.append(cpu_per_frame([m for m in run.memory if s.workers <= m[1] <= window]))
    s.cpu_last.append(cpu_per_frame([m for m in run.memory if m[1] >= frames - window]))


def _write_input(root: Path, frames: int, distinct: int, size: tuple[int, int], level: str,
                 seed: int) -> Path:
    """The batch input: a folder of ``frames`` frames, or a manifest cycling over
    ``distinct`` of them when there are more."""
    folders = write_frame_folder(root / "frames", min(frames, distinct), size[0], size[1],
                                 level, seed)
    if frames <= distinct:
        return root / "frames"
    manifest = root / "frames.csv"
    with open(manifest, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["name", "image", "depth", "normals", "intrinsics"])
        for i in range(frames):
            f = f"frames/{folders[i % distinct].name}"
            out.writerow([f"frame_{i:06d}", f"{f}/rgb.png", f"{f}/depth.npy",
                          f"{f}/normals.npy", f"{f}/intrinsics.json"])
    return manifest


def bench_batch(preset: str = "monoplane", size: tuple[int, int] = (640, 480),
                frames: int = 20, workers: Sequence[int] = (1, 2),
                engines: Sequence[str] = ("local",), repeat: int = 3, seed: int = 0,
                level: str = "mild", overrides: Sequence[str] = (),
                progress: bool = True, distinct: int = 50, window: int = 200,
                interval: float = 0.25) -> BatchBenchResult:
    """Time ``monoplane batch`` on a synthetic folder for each engine and worker count.

    Parameters
    ----------
    preset : str
        Pipeline preset of every command.
    size : (int, int)
        Image width and height in pixels.
    frames : int
        Frames in the folder (seeds ``seed ..``).
    workers : sequence of int
        ``--workers`` values; the first is the reference of the speed-ups.
    engines : sequence of str
        ``local`` and/or ``ray``.
    repeat : int
        Rounds; every setting runs once per round, in alternation.
    seed : int
        Seed of the first frame.
    level : {"clean", "mild", "strong"}
        Cue corruption of the frames.
    overrides : sequence of str
        ``TABLE.KEY=VALUE`` parameter overrides passed on with ``--set``.
    progress : bool
        Print one line per command to stderr.
    distinct : int
        Frames written; a longer batch cycles over them.
    window : int
        Frames compared at each end of the batch (at most half of them).
    interval : float
        Seconds between memory samples.

    Returns
    -------
    BatchBenchResult
    """
    if not Path("/proc/self/smaps_rollup").exists():
        raise InvalidInput("the batch bench reads process memory from /proc/<pid>/smaps_rollup, "
                           "which this system does not have (Linux 4.14 or later)")
    if frames < 1 or repeat < 1:
        raise InvalidInput(f"--frames and --repeat must be at least 1, got {frames} and "
                           f"{repeat}")
    if not workers or min(workers) < 1:
        raise InvalidInput(f"--workers must list counts of at least 1, got {list(workers)}")
    for engine in engines:
        check_engine(engine)
    distinct = max(1, distinct)
    window = max(1, min(window, frames // 2))
    settings = [BatchSetting(e, w) for e in dict.fromkeys(engines) for w in workers]
    with tempfile.TemporaryDirectory(prefix="monoplane-bench-batch-") as tmp:
        root = Path(tmp)
        source = _write_input(root, frames, distinct, size, level, seed)
        for rnd in range(repeat):
            for s in settings:
                out = root / f"out-{s.engine}-{s.workers}"
                args = [sys.executable, "-m", "monoplane.cli", "batch", str(source),
                        "--out", str(out), "--preset", preset, "--engine", s.engine,
                        "--workers", str(s.workers), "--overwrite", "--quiet"]
                for item in overrides:
                    args += ["--set", item]
                run = _run_command(args, out, frames, interval)
                _record(s, run, frames, window)
                if progress:
                    print(f"round {rnd + 1}/{repeat}: {s.engine} --workers {s.workers}: "
                          f"{run.wall:.2f} s ({run.batch:.2f} s in the batch, peak RSS "
                          f"{s.peak_rss[-1]:.0f} MiB)", file=sys.stderr)
            for s in settings:
                ref = next(r for r in settings if r.engine == s.engine)
                s.command_speedup.append(ref.command_s[-1] / s.command_s[-1])
                s.batch_speedup.append(ref.batch_s[-1] / s.batch_s[-1])
    return BatchBenchResult(preset, size[0], size[1], frames, level, settings,
                            min(frames, distinct), window)


def format_batch_bench(result: BatchBenchResult, markdown: bool = False) -> str:
    """One row per setting: medians of command and batch seconds, frames/s and speed-ups; then,
    when measured, a second table of memory and drift (:func:`format_memory`)."""
    head = ["engine", "workers", "command s", "batch s", "frames/s", "speed-up (command)",
            "speed-up (batch)"]
    rows = []
    for s in result.settings:
        batch = _median(s.batch_s)
        rows.append([s.engine, str(s.workers), f"{_median(s.command_s):.2f}", f"{batch:.2f}",
                     f"{result.frames / batch:.2f}",
                     f"{_median(s.command_speedup):.2f}x", f"{_median(s.batch_speedup):.2f}x"])
    rounds = len(result.settings[0].batch_s) if result.settings else 0
    title = (f"batch bench: preset {result.preset}, {result.frames} frames "
             f"{result.width}x{result.height} ({result.level}), medians of {rounds} rounds")
    text = _table(title, head, rows, markdown)
    if result.window and any(s.peak_rss for s in result.settings):
        text += "\n\n" + format_memory(result, markdown)
    return text


def format_memory(result: BatchBenchResult, markdown: bool = False) -> str:
    """One row per setting: medians over the rounds of the process tree's peak RSS and PSS,
    its RSS while the first and the last ``window`` frames ran, and the median frame time of
    those frames."""
    head = ["engine", "workers", "peak RSS MiB", "peak PSS MiB", "RSS first / last MiB",
            "frame ms first / last", "CPU ms/frame first / last"]
    rows = []
    def mid(values: list[float | None], scale: float = 1.0, digits: int = 0) -> str:
        known = [v for v in values if v is not None]
        return f"{statistics.median(known) * scale:.{digits}f}" if known else "-"

    def pair(a: list[float | None], b: list[float | None]) -> str:
        first, last = mid(a, 1000, 1), mid(b, 1000, 1)
        ratio = f" (x{float(last) / float(first):.2f})" if "-" not in (first, last) else ""
        return f"{first} / {last}{ratio}"

    for s in result.settings:
        rows.append([s.engine, str(s.workers), mid(s.peak_rss), mid(s.peak_pss),
                     f"{mid(s.rss_first)} / {mid(s.rss_last)}",
                     pair(s.frame_first, s.frame_last), pair(s.cpu_first, s.cpu_last)])
    title = (f"memory of the command's process tree, and time per frame in the workers, first / "
             f"last {result.window} frames ({result.distinct} distinct frames)")
    return _table(title, head, rows, markdown)


def _table(title: str, head: list[str], rows: list[list[str]], markdown: bool) -> str:
    if markdown:
        lines = [f"| {' | '.join(head)} |", f"|{'---|' * len(head)}"]
        lines += [f"| {' | '.join(r)} |" for r in rows]
        return title + "\n\n" + "\n".join(lines)
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return title + "\n" + "\n".join(lines)
