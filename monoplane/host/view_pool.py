"""Per-view work of a multi-view run (cues, RANSAC, refiner) in a pool of processes.

The view pool is built on the worker pool of :mod:`monoplane.host.pool`, which batches use
too. It differs from a batch in one way: it is opened *before* structure from motion, so its
workers start while the matcher runs, and the host process takes over every view no worker has
started once it waits for the results.

Python API::

    from monoplane.host.view_pool import ViewPool, process_view
    with ViewPool(pipe, workers=2, n_views=len(frames)) as pool:
        tasks = pool.submit(process_view, frames)   # runs in the background
        ...                                          # e.g. SfM in this process
        reconstructions = tasks.result()
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

from monoplane.host.pipeline import Pipeline
from monoplane.host.pool import WorkerInitError, WorkerPool, default_workers

if TYPE_CHECKING:
    from monoplane.datamodel import Frame, Reconstruction

# Each worker builds the pipeline once from the config (initializer), then takes one view per task.
_PIPE: Pipeline | None = None

#: Per-view stages whose seconds make up a view's time (``timings["per_view"]``).
VIEW_STAGES = ("cues", "ransac", "refiner")


def _init_view_worker(config: dict[str, Any]) -> None:
    """Worker initializer: build this worker's pipeline from the resolved config."""
    global _PIPE
    _PIPE = Pipeline.from_config(config)


def process_view(frame: Frame) -> Reconstruction:
    """Cues, RANSAC and refiner on one frame with the pool's pipeline (picklable view task).

    ``rec.frame`` is the frame with its cues; ``rec.timings`` holds each stage's seconds.
    """
    assert _PIPE is not None, "process_view runs in a ViewPool"
    timings: dict[str, float] = {}
    return _PIPE.segment(_PIPE.prepare(frame, timings), timings)


@contextlib.contextmanager
def _thread_budget(threads: int | None) -> Iterator[None]:
    """Within the block, this process's kernels use ``threads`` threads, like a worker's
    (:func:`monoplane.jit.thread_budget` reads ``OMP_NUM_THREADS``); None or a value the user
    set leaves it alone."""
    import os

    if threads is None or "OMP_NUM_THREADS" in os.environ:
        yield
        return
    os.environ["OMP_NUM_THREADS"] = str(threads)
    try:
        yield
    finally:
        os.environ.pop("OMP_NUM_THREADS", None)


class ViewTasks:
    """Per-view tasks under way in a :class:`ViewPool`; :meth:`result` collects them.

    The pool's workers take the views one at a time, driven from a background thread (which
    only waits on the workers' pipes), so this process is free meanwhile, e.g. to run SfM.
    Views no worker has taken when :meth:`result` is called are run in this process, so the
    host's core helps finish the batch instead of idling.
    """

    def __init__(self, views: ViewPool, fn: Callable[[Frame], Any], frames: list[Frame]) -> None:
        import threading

        self._views, self._fn, self._frames = views, fn, list(frames)
        self._lock = threading.Lock()
        self._next = 0  # first view nobody has taken
        self._values: dict[int, Any] = {}
        self._errors: dict[int, BaseException] = {}
        self._pool_failure: BaseException | None = None
        self._thread = None
        if views.pool is not None:
            self._thread = threading.Thread(target=self._drive, args=(views.pool,), daemon=True,
                                            name="monoplane-view-pool")
            self._thread.start()

    def _take(self) -> int | None:
        with self._lock:
            if self._next >= len(self._frames):
                return None
            self._next += 1
            return self._next - 1

    def stop(self) -> None:
        """Hand out no further views; return once the workers' running views have finished."""
        with self._lock:
            self._next = len(self._frames)
        if self._thread is not None:
            self._thread.join()

    def _drive(self, pool: Any) -> None:
        taken: list[int] = []  # view of each item handed to the pool, in hand-out order

        def hand_out():  # pulled by the pool whenever a worker is idle
            while (v := self._take()) is not None:
                taken.append(v)
                yield self._frames[v]

        try:
            for outcome in pool.imap_unordered(self._fn, hand_out()):
                v = taken[outcome.index]
                if outcome.error is None:
                    self._values[v] = outcome.value
                else:
                    self._errors[v] = outcome.error
        except BaseException as exc:  # e.g. WorkerInitError: result() runs the rest here
            self._pool_failure = exc

    def result(self) -> list[Any]:
        """Every view's result, in input order, once all are done.

        Raises
        ------
        Exception
            The error of the first failing view (by input position), after all views ran.
        """
        global _PIPE
        previous, _PIPE = _PIPE, self._views.pipe
        try:
            with _thread_budget(self._views.threads):
                while (v := self._take()) is not None:
                    self._run_here(v)
            if self._thread is not None:
                self._thread.join()
                self._thread = None
                if self._pool_failure is not None:
                    self._views.pool_failed(self._pool_failure)
                    # Views the pool took but never finished run here.
                    for v in range(len(self._frames)):
                        if v not in self._values and v not in self._errors:
                            self._run_here(v)
        finally:
            _PIPE = previous
        for v in sorted(self._errors):
            raise self._errors[v]
        return [self._values[v] for v in range(len(self._frames))]

    def _run_here(self, v: int) -> None:
        try:
            self._values[v] = self._fn(self._frames[v])
        except Exception as exc:
            self._errors[v] = exc


class ViewPool:
    """Runs per-view tasks in ``workers`` processes: this one and ``workers - 1`` workers.

    Opened before structure from motion so that the workers start (and import) while the
    matcher runs; this process joins in once it waits for the results
    (:meth:`ViewTasks.result`). A worker costs its start-up (a fresh interpreter importing
    NumPy, SciPy, OpenCV and the project, and loading the compiled kernels: over a second of
    CPU), so with ``workers`` 2 one worker and this process share the views rather than two
    workers while this one waits. In-process, the tasks use ``pipe`` itself.

    Parameters
    ----------
    pipe : Pipeline
        The pipeline whose config the workers rebuild.
    workers : int
        Processes that run views, this one included (1: this process alone).
    n_views : int
        Number of views (no more workers than views are started).
    """

    def __init__(self, pipe: Pipeline, workers: int, n_views: int) -> None:
        self.pipe = pipe
        self.pool = None
        self._tasks: list[ViewTasks] = []
        #: Threads each view may use (the thread budget of the workers and of this process
        #: while it runs views), so that the processes together fill the cores once.
        self.threads: int | None = None
        size = min(workers, n_views) - 1
        if size >= 1:
            self.threads = max(1, default_workers() // (size + 1))
            self.pool = WorkerPool(size, _init_view_worker, (pipe.config.to_dict(),),
                                   threads_per_worker=self.threads)

    def __enter__(self) -> ViewPool:
        if self.pool is not None:
            self.pool.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        # Tasks nobody collected (the host failed meanwhile): let their running views finish,
        # so the driver thread is done with the workers before they are stopped.
        for tasks in self._tasks:
            tasks.stop()
        if self.pool is not None:
            self.pool.__exit__(*exc)

    def submit(self, fn: Callable[[Frame], Any], frames: list[Frame]) -> ViewTasks:
        """Start ``fn`` on every frame in the workers; :meth:`ViewTasks.result` collects."""
        tasks = ViewTasks(self, fn, frames)
        self._tasks.append(tasks)
        return tasks

    def map(self, fn: Callable[[Frame], Any], frames: list[Frame]) -> list[Any]:
        """``[fn(f) for f in frames]`` in input order; the first failure propagates."""
        return self.submit(fn, frames).result()

    def pool_failed(self, exc: BaseException) -> None:
        """Stop using the workers after ``exc``; later views run in this process."""
        import sys

        if not isinstance(exc, WorkerInitError):
            raise exc
        # E.g. a script without an ``if __name__ == "__main__":`` guard, which spawned
        # workers cannot import: run the views here instead.
        print(f"monoplane: warning: per-view workers could not start ({exc}); "
              "running the views in this process (in a script, put the calls under "
              "'if __name__ == \"__main__\":' or pass workers=1)", file=sys.stderr)
        if self.pool is not None:
            self.pool.__exit__(None, None, None)
            self.pool = None
            self.threads = None  # this process alone: all its cores
