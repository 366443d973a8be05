"""The per-frame function every engine runs, and the output layout that makes resume work.

:func:`process_frame` is ``(job, frame spec) -> FrameResult``: it loads the frame's files, runs
the pipeline the job's config describes and writes ``<out>/<name>/`` with
:func:`monoplane.export.save`, exactly as ``monoplane run`` does. It never raises for
a bad frame: the failure comes back as a one-line reason. The pipeline (and any ONNX session
its stages open) is built once per process and reused for every later frame of the same config.

Completeness: ``save`` writes into a hidden temporary sibling folder and renames it into place,
so ``<out>/<name>/`` appears whole or not at all, whenever the process is killed. A frame counts
as done when its folder holds every file the output formats on by default state they write for
a frame (:func:`monoplane.export.output_files`, third-party formats included), and
``report.html`` when reports are asked for. Temporary folders left by a killed run are deleted
by :func:`clean_stale` at the start of the next run.
"""

from __future__ import annotations

import functools
import json
import shutil
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from monoplane.batch.specs import FrameSpec
from monoplane.errors import MonoplaneError
from monoplane.version import __version__

REPORT_FILE = "report.html"
#: Folder of ``index.html``'s thumbnails and of the one 3D viewer script every frame report of
#: the batch shares.
ASSETS = "index_files"


@dataclass(frozen=True)
class BatchJob:
    """What every worker needs besides the frame: picklable and small.

    Attributes
    ----------
    config : dict
        Resolved pipeline config (:meth:`monoplane.host.config.ResolvedConfig.to_dict`).
    out : str
        Batch output folder; frame ``name`` goes to ``out/name``.
    report : bool
        Also write each frame's ``report.html``.
    """

    config: dict[str, Any]
    out: str
    report: bool = False


@dataclass
class FrameResult:
    """The outcome of one frame, as listed in ``summary.json``.

    Attributes
    ----------
    name : str
    status : {"ok", "failed", "skipped"}
    planes : int or None
        Number of planes (None when failed).
    seconds : float or None
        Wall time of the frame in its worker: reading, pipeline and writing (None when skipped).
    error : str or None
        One-line reason of a failure.
    """

    name: str
    status: str
    planes: int | None = None
    seconds: float | None = None
    error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "status": self.status, "planes": self.planes,
                "seconds": None if self.seconds is None else round(self.seconds, 4),
                "error": self.error}


@dataclass
class BatchSummary:
    """What ``summary.json`` holds.

    Attributes
    ----------
    frames : list of FrameResult
        One per input frame, in input order (frames an interrupt left undone are absent).
    config : dict
        The resolved pipeline config every frame ran with.
    interrupted : bool
        The run was stopped (Ctrl-C) before every frame was done.
    """

    frames: list[FrameResult]
    config: dict[str, Any]
    engine: str = "local"
    workers: int | None = None
    seconds: float = 0.0
    interrupted: bool = False
    notes: list[str] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)

    def count(self, status: str) -> int:
        """Number of frames with ``status`` (``"ok"``, ``"failed"`` or ``"skipped"``)."""
        return sum(f.status == status for f in self.frames)

    @property
    def failed(self) -> list[FrameResult]:
        return [f for f in self.frames if f.status == "failed"]

    def to_dict(self) -> dict[str, Any]:
        return {
            "monoplane_version": __version__,
            **self.info,
            "engine": self.engine,
            "workers": self.workers,
            "seconds": round(self.seconds, 3),
            "interrupted": self.interrupted,
            "notes": self.notes,
            "counts": {s: self.count(s) for s in ("ok", "failed", "skipped")},
            "frames": [f.to_dict() for f in self.frames],
            "config": self.config,
        }


def one_line(exc: BaseException) -> str:
    """A one-line reason for a failure: the user-facing message, or the type and text of a bug."""
    if isinstance(exc, MonoplaneError):
        text = str(exc)
    elif isinstance(exc, OSError) and exc.strerror:
        text = exc.strerror + (f": {exc.filename}" if exc.filename else "")
    else:
        text = f"internal error: {type(exc).__name__}: {exc}"
    return " ".join(text.split()) or type(exc).__name__


@dataclass
class _Cache:
    key: str = ""
    pipeline: Any = None


_CACHE = _Cache()  # one pipeline per process: the last config asked for


def has_pipeline() -> bool:
    """Whether this process has built a pipeline (and any ONNX session) with
    :func:`pipeline_for`."""
    return _CACHE.pipeline is not None


def pipeline_for(config: dict[str, Any]):  # -> monoplane.Pipeline
    """This process's pipeline for ``config``, built (with every stage) on first use."""
    from monoplane.host.pipeline import Pipeline  # loads OpenCV, which only workers need

    key = json.dumps(config, sort_keys=True, default=str)
    if _CACHE.key != key:
        pipe = Pipeline.from_config(config)
        for kind in pipe.config.stages:  # build the stages (and ONNX sessions) now, once
            pipe.stage(kind)
        _CACHE.key, _CACHE.pipeline = key, pipe
    return _CACHE.pipeline


def process_frame(job: BatchJob, spec: FrameSpec) -> FrameResult:
    """Run one frame and write its output folder atomically.

    Parameters
    ----------
    job : BatchJob
        Config and output folder.
    spec : FrameSpec
        The frame's files.

    Returns
    -------
    FrameResult
        ``"ok"`` with the plane count, or ``"failed"`` with a one-line reason; never raises
        for a bad frame or a stage error.
    """
    # these load OpenCV, which only the worker processes running frames need
    from monoplane.export.saving import save
    from monoplane.io.frames import load_frame

    start = time.perf_counter()
    try:
        pipe = pipeline_for(job.config)
        frame = load_frame(spec.image, depth=spec.depth, normals=spec.normals,
                           intrinsics=spec.intrinsics, depth_scale=spec.depth_scale,
                           nan_as_invalid=spec.nan_as_invalid, depth_kind=spec.depth_kind,
                           depth_encoding=spec.depth_encoding)
        rec = pipe.run(frame.with_(name=spec.name))
        report = None
        if job.report:  # one copy of the 3D viewer (1 MB) for all frame reports
            # the report loads OpenCV
            from monoplane.report.frame import write_frame_report
            from monoplane.report.viewer import install_viewer

            viewer = f"../{ASSETS}/{install_viewer(Path(job.out) / ASSETS)}"
            report = functools.partial(write_frame_report, rec, viewer=viewer)
        # overwrite=True: the caller already decided this frame must be (re)computed.
        save(rec, Path(job.out) / spec.name, overwrite=True, also=report, pm=pipe.pm)
    except Exception as exc:
        return FrameResult(spec.name, "failed", seconds=time.perf_counter() - start,
                           error=one_line(exc))
    return FrameResult(spec.name, "ok", planes=rec.num_planes,
                       seconds=time.perf_counter() - start)


def is_complete(folder: Path, report: bool = False) -> bool:
    """Whether ``folder`` holds a whole frame output (and ``report.html`` if ``report``)."""
    names = frame_output_files() + ((REPORT_FILE,) if report else ())
    return folder.is_dir() and all((folder / n).is_file() for n in names)


@functools.cache
def frame_output_files() -> tuple[str, ...]:
    """The files ``monoplane run`` writes for a frame: those the output formats on by default
    state (:func:`monoplane.export.output_files`), looked up once per process."""
    from monoplane.export.saving import output_files  # loads OpenCV

    return output_files("frame")


def __getattr__(name: str) -> Any:
    if name == "OUTPUT_FILES":  # a constant until 0.2.0: the formats are plugins now
        import warnings

        warnings.warn("monoplane.batch.frame.OUTPUT_FILES is deprecated; use "
                      "monoplane.export.output_files('frame') (the old name goes in 0.3.0)",
                      DeprecationWarning, stacklevel=2)
        return frame_output_files()
    raise AttributeError(f"module 'monoplane.batch.frame' has no attribute {name!r}")


def stored_result(folder: Path) -> tuple[int | None, dict[str, Any] | None]:
    """Plane count and config recorded in a complete frame folder's ``planes.json``."""
    try:
        doc = json.loads((folder / "planes.json").read_text())
        return len(doc["planes"]), doc.get("config")
    except (OSError, ValueError, KeyError, TypeError):
        return None, None


def clean_stale(out: Path) -> list[Path]:
    """Delete temporary folders that a killed run left in ``out``; returns what was removed.

    These are the hidden ``.<name>.<random>.partial`` / ``.old`` siblings of
    :func:`monoplane.export.files.atomic_output_dir`. Call it only while holding the batch lock,
    so that no live run is writing them.
    """
    removed = []
    for p in out.iterdir():
        if p.name.startswith(".") and p.is_dir() and p.name.endswith((".partial", ".old")):
            shutil.rmtree(p, ignore_errors=True)
            removed.append(p)
    return removed
