"""Batches of frames: ``monoplane batch`` and its Python API.

>>> from monoplane.batch import run_batch
>>> summary = run_batch("data_samples", "out/batch", workers=2)     # doctest: +SKIP
>>> summary.count("ok"), summary.failed                               # doctest: +SKIP

* :func:`run_batch` reads a folder of frame folders or a manifest (:mod:`.specs`), skips frames
  already done, runs the rest with :func:`process_frame` on an engine (:mod:`.engines`: a local
  process pool or Ray) and writes ``summary.json`` (and ``index.html``).
* :func:`map_ordered` and :class:`WorkerPool` (:mod:`monoplane.host.pool`, re-exported here)
  are the local worker pool on its own: a picklable function over items with a per-worker
  initializer, for any parallel work.
"""

from monoplane.batch.engines import ENGINES, EngineError
from monoplane.batch.frame import BatchJob, FrameResult, process_frame
from monoplane.batch.runner import BatchOptions, BatchSummary, run_batch
from monoplane.batch.specs import MANIFEST_COLUMNS, FrameSpec, read_frames
from monoplane.host.pool import (
    TaskOutcome,
    WorkerDied,
    WorkerInitError,
    WorkerPool,
    default_workers,
    map_ordered,
)

__all__ = [
    "ENGINES", "MANIFEST_COLUMNS", "BatchJob", "BatchOptions", "BatchSummary", "EngineError",
    "FrameResult", "FrameSpec", "TaskOutcome", "WorkerDied", "WorkerInitError", "WorkerPool",
    "default_workers", "map_ordered", "process_frame", "read_frames", "run_batch",
]
