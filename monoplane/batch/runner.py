"""``run_batch``: frames in, one output folder per frame plus ``summary.json`` out.

Order of work: read and check every frame spec (a bad manifest fails before any work), resolve
the config once (a bad key fails before any work), lock the output folder, delete temporary
folders a killed run left behind, skip complete frames, run the rest on the chosen engine with a
progress bar, then write ``summary.json`` (and ``index.html`` with ``report``) atomically.
"""

from __future__ import annotations

import contextlib
import dataclasses
import fcntl
import json
import os
import sys
import tempfile
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from tqdm import tqdm

from monoplane.batch.engines import check_engine, run_engine
from monoplane.batch.frame import (
    BatchJob,
    BatchSummary,
    FrameResult,
    clean_stale,
    is_complete,
    stored_result,
)
from monoplane.batch.specs import FrameSpec, absolute_paths, check_name, read_frames
from monoplane.errors import InvalidInput

LOCK_FILE = ".monoplane-batch.lock"


class _Bar(tqdm):
    # No monitor thread: the local engine forks its workers from this process, and forking is
    # only clean from a process that runs no other thread.
    monitor_interval = 0

def write_json_atomic(path: Path, doc: dict[str, Any]) -> None:
    """Write JSON to a temporary sibling and rename it over ``path``."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.fchmod(fd, 0o644)  # mkstemp makes it private; a summary is meant to be shared
        with os.fdopen(fd, "w") as fh:
            json.dump(doc, fh, indent=2)
            fh.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def batch_lock(out: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``out`` so two batches never write (or clean) it at once."""
    with open(out / LOCK_FILE, "w") as fh:
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise InvalidInput(f"another monoplane batch is writing to {out}") from None
        yield


def _json_roundtrip(doc: dict[str, Any]) -> dict[str, Any]:
    return json.loads(json.dumps(doc, default=str))


def plan(specs: Sequence[FrameSpec], out: Path, config: dict[str, Any], overwrite: bool,
         report: bool) -> tuple[list[FrameSpec], dict[str, FrameResult]]:
    """Split frames into those to run and those already decided (skipped or failed).

    Raises
    ------
    InvalidInput
        If a complete frame folder was made with a different config (resuming would mix two
        configs in one batch).
    """
    todo: list[FrameSpec] = []
    decided: dict[str, FrameResult] = {}
    wanted = _json_roundtrip(config)
    for spec in specs:
        folder = out / spec.name
        if overwrite or not folder.exists():
            todo.append(spec)
        elif is_complete(folder):
            planes, stored = stored_result(folder)
            if stored is not None and _json_roundtrip(stored) != wanted:
                raise InvalidInput(
                    f"{folder} was made with a different config; pass --overwrite to recompute "
                    "every frame, or choose another --out")
            if report and not is_complete(folder, report=True):
                todo.append(spec)  # our own output, only the report is missing
            else:
                decided[spec.name] = FrameResult(spec.name, "skipped", planes=planes)
        else:
            decided[spec.name] = FrameResult(
                spec.name, "failed",
                error=f"{folder} exists but is not a complete frame output; pass --overwrite")
    return todo, decided


@dataclass(frozen=True)
class BatchOptions:
    """How :func:`run_batch` runs a batch: the pipeline, the engine and how frames are read.

    Attributes
    ----------
    config, preset, overrides
        Pipeline configuration, as :meth:`monoplane.Pipeline.from_config`.
    workers : int, optional
        Worker processes (local) or actors (ray); default: all cores (local), all cluster
        CPUs (ray).
    engine : {"local", "ray"}
    ray_address : str, optional
        ``"auto"``, ``"HOST:PORT"`` (a running cluster's GCS address) or ``"ray://HOST:PORT"``
        (Ray Client); default: a local Ray instance.
    overwrite : bool
        Recompute every frame; by default complete frame folders are skipped.
    report : bool
        Write each frame's ``report.html`` and the batch's ``index.html``.
    depth_scale, depth_kind, nan_as_invalid, depth_encoding
        Defaults for every frame (a manifest's ``depth_scale`` and ``depth_encoding``
        columns win).
    progress : bool
        Show a progress bar on stderr.
    """

    config: str | Path | dict[str, Any] | None = None
    preset: str | None = None
    overrides: dict[str, Any] | list[str] | None = None
    workers: int | None = None
    engine: str = "local"
    ray_address: str | None = None
    overwrite: bool = False
    report: bool = False
    depth_scale: float | None = None
    depth_kind: str = "metric"
    nan_as_invalid: bool = False
    depth_encoding: str = "scaled"
    progress: bool = True

    @classmethod
    def of(cls, options: BatchOptions | None = None, **fields: Any) -> BatchOptions:
        """``options`` (default: the defaults) with ``fields`` replaced.

        Raises
        ------
        TypeError
            When a keyword is not a field (the message lists them).
        """
        valid = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(fields) - valid)
        if unknown:
            raise TypeError(f"run_batch() got an unexpected keyword argument '{unknown[0]}'; "
                            f"options: {', '.join(sorted(valid))}")
        return dataclasses.replace(options or cls(), **fields)


def _read_specs(source: str | Path | Sequence[FrameSpec], opts: BatchOptions,
                notes: list[str]) -> tuple[list[FrameSpec], str]:
    """The frame specs of ``source`` and how to name it in messages; checks their names."""
    if isinstance(source, (str, Path)):
        specs = read_frames(source, opts.depth_scale, opts.depth_kind, opts.nan_as_invalid,
                            notes, opts.depth_encoding)
        source_text = str(source)
    else:
        # Workers may run elsewhere (Ray) with another working directory: absolute paths.
        specs = [absolute_paths(s) for s in source]
        source_text = f"{len(specs)} frame specs"
        for spec in specs:
            check_name(spec.name, "FrameSpec")
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        dup = next(n for n in names if names.count(n) > 1)
        raise InvalidInput(f"frame name {dup!r} appears twice in {source_text}")
    return specs, source_text


def _run_frames(job: BatchJob, todo: list[FrameSpec], decided: dict[str, FrameResult],
                total: int, opts: BatchOptions, notes: list[str]
                ) -> Iterator[FrameResult]:
    """Run ``todo`` on the engine, showing progress over all ``total`` frames; yields each
    result as it comes."""
    counts = {"ok": 0, "failed": sum(r.status == "failed" for r in decided.values()),
              "skipped": sum(r.status == "skipped" for r in decided.values())}
    bar = _Bar(total=total, initial=len(decided), unit="frame", desc="batch",
               disable=not opts.progress, file=sys.stderr, dynamic_ncols=True)
    run_start = time.perf_counter()
    ran = 0
    try:
        for res in run_engine(opts.engine, job, todo, opts.workers, opts.ray_address, notes):
            counts[res.status] += 1
            ran += 1
            fps = ran / max(time.perf_counter() - run_start, 1e-9)
            bar.set_postfix_str(f"done={counts['ok']} failed={counts['failed']} "
                                f"skipped={counts['skipped']} {fps:.2f} fps")
            bar.update()
            yield res
    finally:
        bar.close()


def run_batch(source: str | Path | Sequence[FrameSpec], out: str | Path,
              options: BatchOptions | str | Path | dict[str, Any] | None = None,
              **fields: Any) -> BatchSummary:
    """Reconstruct every frame of a folder or manifest into ``out/<name>/``.

    Parameters
    ----------
    source : path or sequence of FrameSpec
        A folder of frame folders, a ``.jsonl``/``.csv`` manifest (see
        :mod:`monoplane.batch.specs`), or specs built in Python.
    out : path
        Batch output folder (created if missing).
    options : BatchOptions, optional
        How to run it (a config path or dict here is taken as ``config``, as before 0.2.0).
    **fields
        Fields of :class:`BatchOptions` given as keywords, e.g.
        ``run_batch(src, out, preset="range", workers=2)``; they override ``options``.

    Returns
    -------
    BatchSummary
        Also written to ``out/summary.json``.

    Raises
    ------
    InvalidInput, ConfigError
        Bad input list, config or output folder, before any frame runs.
    KeyboardInterrupt
        After stopping the workers and writing ``summary.json`` (``interrupted: true``).
    """
    # numba, SciPy and OpenCV load with the pipeline, when a batch runs: importing
    # monoplane.batch for its specs or pool stays light
    from monoplane.host.pipeline import Pipeline

    if options is not None and not isinstance(options, BatchOptions):
        options, fields = None, {"config": options, **fields}
    opts = BatchOptions.of(options, **fields)
    start = time.perf_counter()
    notes: list[str] = []
    specs, source_text = _read_specs(source, opts, notes)
    if opts.workers is not None and opts.workers < 1:
        raise InvalidInput(f"--workers must be at least 1, got {opts.workers}")
    check_engine(opts.engine, opts.ray_address)
    cfg = Pipeline.from_config(opts.config, preset=opts.preset,
                               overrides=opts.overrides).config.to_dict()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InvalidInput(f"output path {out} is an existing file, not a folder")
    out.mkdir(parents=True, exist_ok=True)
    summary = BatchSummary([], cfg, engine=opts.engine, workers=opts.workers,
                           notes=notes, info={"input": source_text,
                                 "started": datetime.now(UTC).isoformat(
                                     timespec="seconds")})
    with batch_lock(out):
        clean_stale(out)
        todo, decided = plan(specs, out, cfg, opts.overwrite, opts.report)
        job = BatchJob(config=cfg, out=str(out.resolve()), report=opts.report)
        results = dict(decided)
        try:
            for res in _run_frames(job, todo, decided, len(specs), opts, notes):
                results[res.name] = res
        except KeyboardInterrupt:
            summary.interrupted = True
            raise
        finally:
            summary.frames = [results[s.name] for s in specs if s.name in results]
            summary.seconds = time.perf_counter() - start
            write_json_atomic(out / "summary.json", summary.to_dict())
        if opts.report:
            from monoplane.batch.index import write_index  # loads OpenCV and the report

            write_index(summary, specs, out)
    return summary
