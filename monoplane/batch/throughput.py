"""Batch throughput against the number of workers (``monoplane bench --batch``).

Frames
    ``frames`` synthetic single-view frames of one size, written once into a temporary folder
    in the layout of ``data_samples/room_000`` (:func:`monoplane.synth.batchset.write_frame_folder`).

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
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from monoplane.errors import InvalidInput


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
    """

    engine: str
    workers: int
    command_s: list[float] = field(default_factory=list)
    batch_s: list[float] = field(default_factory=list)
    command_speedup: list[float] = field(default_factory=list)
    batch_speedup: list[float] = field(default_factory=list)


@dataclass
class BatchBenchResult:
    """All settings of one ``monoplane bench --batch`` run."""

    preset: str
    width: int
    height: int
    frames: int
    level: str
    settings: list[BatchSetting]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``kind: "batch"``)."""
        return {"kind": "batch", **asdict(self)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> BatchBenchResult:
        """Inverse of :meth:`to_dict`."""
        return cls(data["preset"], data["width"], data["height"], data["frames"],
                   data["level"], [BatchSetting(**s) for s in data["settings"]])


def _median(values: Sequence[float]) -> float:
    return statistics.median(values) if values else float("nan")


def _run_command(args: list[str], out: Path, frames: int) -> tuple[float, float]:
    """Run one ``monoplane batch`` command; its wall seconds and its summary's seconds."""
    start = time.perf_counter()
    proc = subprocess.run(args, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise InvalidInput(f"'{' '.join(args[3:])}' exited with {proc.returncode}: {last}")
    summary = json.loads((out / "summary.json").read_text())
    if summary["counts"]["ok"] != frames:
        raise InvalidInput(f"the batch in {out} did {summary['counts']['ok']} of {frames} "
                           f"frames: {summary['counts']}")
    return wall, float(summary["seconds"])


def bench_batch(preset: str = "monoplane", size: tuple[int, int] = (640, 480),
                frames: int = 20, workers: Sequence[int] = (1, 2),
                engines: Sequence[str] = ("local",), repeat: int = 3, seed: int = 0,
                level: str = "mild", overrides: Sequence[str] = (),
                progress: bool = True) -> BatchBenchResult:
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

    Returns
    -------
    BatchBenchResult
    """
    from monoplane.batch.engines import check_engine
    from monoplane.synth.batchset import write_frame_folder

    if frames < 1 or repeat < 1:
        raise InvalidInput(f"--frames and --repeat must be at least 1, got {frames} and "
                           f"{repeat}")
    if not workers or min(workers) < 1:
        raise InvalidInput(f"--workers must list counts of at least 1, got {list(workers)}")
    for engine in engines:
        check_engine(engine)
    settings = [BatchSetting(e, w) for e in dict.fromkeys(engines) for w in workers]
    with tempfile.TemporaryDirectory(prefix="monoplane-bench-batch-") as tmp:
        root = Path(tmp)
        write_frame_folder(root / "frames", frames, size[0], size[1], level, seed)
        for rnd in range(repeat):
            for s in settings:
                out = root / f"out-{s.engine}-{s.workers}"
                args = [sys.executable, "-m", "monoplane.cli", "batch", str(root / "frames"),
                        "--out", str(out), "--preset", preset, "--engine", s.engine,
                        "--workers", str(s.workers), "--overwrite", "--quiet"]
                for item in overrides:
                    args += ["--set", item]
                wall, own = _run_command(args, out, frames)
                s.command_s.append(wall)
                s.batch_s.append(own)
                if progress:
                    print(f"round {rnd + 1}/{repeat}: {s.engine} --workers {s.workers}: "
                          f"{wall:.2f} s ({own:.2f} s in the batch)", file=sys.stderr)
            for s in settings:
                ref = next(r for r in settings if r.engine == s.engine)
                s.command_speedup.append(ref.command_s[-1] / s.command_s[-1])
                s.batch_speedup.append(ref.batch_s[-1] / s.batch_s[-1])
    return BatchBenchResult(preset, size[0], size[1], frames, level, settings)


def format_batch_bench(result: BatchBenchResult, markdown: bool = False) -> str:
    """One row per setting: medians of command and batch seconds, frames/s and speed-ups."""
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
    if markdown:
        lines = [f"| {' | '.join(head)} |", f"|{'---|' * len(head)}"]
        lines += [f"| {' | '.join(r)} |" for r in rows]
        return title + "\n\n" + "\n".join(lines)
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(head)]
    lines = ["  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True))]
    lines += ["  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
    return title + "\n" + "\n".join(lines)
