"""A small process pool: a picklable function over items, one long-lived state per worker.

Why not :class:`concurrent.futures.ProcessPoolExecutor`: when one worker dies (a segfault in
native code, the OOM killer) the executor breaks and fails every pending item, without saying
which item killed it. Here each worker has its own pipe, so the parent always knows which item a
worker was running: that item alone is reported (:class:`WorkerDied`) and a fresh worker takes
the dead one's place. Workers also ignore SIGINT, so that a Ctrl-C in a terminal (which signals
the whole process group) reaches the parent only, which then stops the workers in order.

Typical use (results in input order)::

    from monoplane.host.pool import map_ordered

    def setup(config):             # runs once per worker process
        global PIPE
        PIPE = build_expensive_thing(config)

    def work(item):                # runs once per item, in some worker
        return PIPE(item)

    results = map_ordered(work, items, workers=2, initializer=setup, initargs=(config,))

``work`` and ``setup`` must be importable module-level functions and items and results must
pickle.

Start method: ``spawn`` by default, which is safe whatever the parent has done but makes every
worker import numpy, SciPy, OpenCV and the project again (about 0.7 s of CPU each). A caller
whose process has run no threaded native code yet (no ONNX session, no SfM, no parallel
kernel) may ask for ``fork`` (:func:`fork_if_available`): workers then start from the parent's
already imported modules in a few milliseconds. The batch driver does so; the multi-view driver,
which runs COLMAP in the parent, does not.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sys
import traceback
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from multiprocessing.connection import Connection, wait
from typing import Any

from monoplane.host.allocator import keep_freed_memory

#: Thread-count variables set in each worker (unless the user set them), so that N workers on
#: N cores do not each start N BLAS/OpenMP/numba threads and fight over the cores.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                    "NUMBA_NUM_THREADS")
#: Seconds a worker gets to finish after SIGTERM before it is killed.
TERMINATE_GRACE = 5.0


class WorkerDied(RuntimeError):
    """The worker process running an item exited without returning a result."""


class WorkerInitError(RuntimeError):
    """A worker's initializer raised; the pool cannot run anything."""


@dataclass
class TaskOutcome:
    """What became of one item.

    Attributes
    ----------
    index : int
        Position of the item in the input.
    value : Any
        The function's return value (None on error).
    error : BaseException or None
        The exception the function raised (with the worker's traceback text in
        ``error.remote_traceback`` when it could be attached), or :class:`WorkerDied`.
    """

    index: int
    value: Any = None
    error: BaseException | None = None


def default_workers() -> int:
    """Number of usable cores (the process's CPU affinity where the OS reports it)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def _on_sigterm(signum: int, frame: object) -> None:
    # SystemExit unwinds the running item, so `with` blocks (e.g. atomic output folders) clean up.
    raise SystemExit(128 + signum)


def _portable_error(exc: BaseException) -> BaseException:
    """The exception itself if it pickles, else a RuntimeError with its text."""
    import pickle

    text = "".join(traceback.format_exception(exc))
    try:
        pickle.loads(pickle.dumps(exc))
        out = exc
    except Exception:
        out = RuntimeError(f"{type(exc).__name__}: {exc}")
    try:
        out.remote_traceback = text  # type: ignore[attr-defined]
    except AttributeError:
        pass
    return out


def _die_with_parent() -> None:
    """Ask Linux to send SIGTERM when the parent dies (even by SIGKILL), so that an orphan never
    finishes a frame while the next run cleans up its temporary folder."""
    try:
        import ctypes

        ctypes.CDLL(None).prctl(1, signal.SIGTERM)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the closed pipe still stops idle workers
        pass


def fork_if_available() -> str:
    """``"fork"`` on Linux from a process running no other Python thread, else ``"spawn"``.

    Only for callers that have run no threaded native code (see the module note). A live
    Python thread (monoplane's own kernel thread pool, a progress monitor, the caller's
    threads) means the process has been doing threaded work, so the safe method is chosen.
    """
    import threading

    if not sys.platform.startswith("linux") or threading.active_count() > 1:
        return "spawn"
    return "fork"


def _limit_native_threads(threads: int) -> None:
    """Cap the BLAS pools a forked worker inherited: they read their size from the environment
    when the parent loaded them, before the pool set the thread variables."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(threads)


def _worker_main(conn: Connection, initializer: Callable[..., Any] | None,
                 initargs: tuple, forked_threads: int | None = None) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_sigterm)
    _die_with_parent()
    keep_freed_memory()  # a worker runs frame after frame, as the command line does
    if forked_threads is not None:
        _limit_native_threads(forked_threads)
    try:
        if initializer is not None:
            initializer(*initargs)
    except BaseException as exc:
        conn.send(("init-failed", _portable_error(exc)))
        return
    conn.send(("ready", None))
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):  # the parent is gone
            return
        if task is None:
            return
        index, fn, item = task
        try:
            conn.send(("ok", (index, fn(item))))
        except Exception as exc:
            conn.send(("error", (index, _portable_error(exc))))


class _Worker:
    def __init__(self, ctx: Any, initializer: Callable[..., Any] | None, initargs: tuple,
                 env: dict[str, str], threads: int) -> None:
        self.conn, child = ctx.Pipe(duplex=True)
        forked = threads if ctx.get_start_method() == "fork" else None
        self.process = ctx.Process(target=_worker_main,
                                   args=(child, initializer, initargs, forked), daemon=True)
        saved = {k: os.environ.get(k) for k in env}
        os.environ.update(env)  # the child copies the environment at start()
        try:
            self.process.start()
        finally:
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v
        child.close()
        self.index: int | None = None  # item being run
        self.ready = False


class WorkerPool:
    """A fixed number of worker processes, each initialised once.

    Parameters
    ----------
    workers : int
        Number of processes (at least 1).
    initializer : callable, optional
        Module-level function called once in every worker (also in replacements of dead
        workers) with ``initargs``, e.g. to build a pipeline and its ONNX sessions.
    initargs : tuple
        Picklable arguments of ``initializer``.
    threads_per_worker : int, optional
        Value of the thread-count variables (:data:`THREAD_VARIABLES`) in the workers; default:
        cores // workers (at least 1). Variables the user already set are left alone.
    start_method : {"spawn", "fork", "forkserver"}
        How workers start; ``"fork"`` only from a process that has run no threaded native
        code (see the module note).

    Use it as a context manager; leaving the block stops the workers (SIGTERM, then SIGKILL
    after :data:`TERMINATE_GRACE` seconds for a worker that does not stop).
    """

    def __init__(self, workers: int, initializer: Callable[..., Any] | None = None,
                 initargs: tuple = (), threads_per_worker: int | None = None,
                 start_method: str = "spawn") -> None:
        if int(workers) < 1:
            raise ValueError(f"workers must be at least 1, got {workers}")
        self.workers = int(workers)
        self._ctx = mp.get_context(start_method)
        self._initializer = initializer
        self._initargs = initargs
        threads = threads_per_worker or max(1, default_workers() // self.workers)
        self._threads = threads
        self._env = {k: str(threads) for k in THREAD_VARIABLES if k not in os.environ}
        self._pool = [self._spawn() for _ in range(self.workers)]

    def _spawn(self) -> _Worker:
        return _Worker(self._ctx, self._initializer, self._initargs, self._env, self._threads)

    def __enter__(self) -> WorkerPool:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def imap_unordered(self, fn: Callable[[Any], Any], items: Iterable[Any]
                       ) -> Iterator[TaskOutcome]:
        """Run ``fn`` on every item; yield each outcome as soon as it is known.

        An exception raised by ``fn`` is returned in :attr:`TaskOutcome.error`, and the other
        items go on. A worker that dies is replaced and its item reported as
        :class:`WorkerDied`.

        Raises
        ------
        WorkerInitError
            If a worker's initializer fails (the pool then cannot make progress).
        """
        todo = iter(enumerate(items))
        exhausted = False
        busy = 0
        while True:
            for w in self._pool:  # hand out work to idle, initialised workers
                if w.ready and w.index is None and not exhausted:
                    nxt = next(todo, None)
                    if nxt is None:
                        exhausted = True
                        break
                    w.index = nxt[0]
                    w.conn.send((nxt[0], fn, nxt[1]))
                    busy += 1
            if exhausted and busy == 0:
                return
            waitables: list[Any] = [w.conn for w in self._pool]
            waitables += [w.process.sentinel for w in self._pool]
            ready = set(wait(waitables))
            for slot, w in enumerate(self._pool):
                if w.conn in ready:
                    try:
                        kind, payload = w.conn.recv()
                    except (EOFError, OSError):
                        kind, payload = "dead", None
                    if kind == "ready":
                        w.ready = True
                        continue
                    if kind == "init-failed":
                        raise WorkerInitError(f"worker initializer failed: {payload}") from payload
                    if kind in ("ok", "error"):
                        index, result = payload
                        w.index = None
                        busy -= 1
                        yield (TaskOutcome(index, value=result) if kind == "ok"
                               else TaskOutcome(index, error=result))
                        continue
                if w.process.sentinel in ready or (w.conn in ready):
                    # The pipe closed or the process exited: the worker is gone.
                    w.process.join(timeout=1.0)
                    code = w.process.exitcode
                    lost = w.index
                    w.conn.close()
                    self._pool[slot] = self._spawn()
                    if lost is not None:
                        busy -= 1
                        how = (f"killed by signal {-code}" if code is not None and code < 0
                               else f"exit status {code}")
                        yield TaskOutcome(lost, error=WorkerDied(
                            f"worker process died ({how}) while running this item"))
                    elif not w.ready:
                        raise WorkerInitError(
                            f"a worker process died while starting ({code})")

    def map(self, fn: Callable[[Any], Any], items: Iterable[Any]) -> list[Any]:
        """``[fn(item) for item in items]`` in parallel, in input order.

        Raises
        ------
        Exception
            The error of the first failing item (by input position), after all items ran.
        """
        outcomes = sorted(self.imap_unordered(fn, items), key=lambda o: o.index)
        for o in outcomes:
            if o.error is not None:
                raise o.error
        return [o.value for o in outcomes]

    def close(self) -> None:
        """Stop every worker: a polite request, then SIGTERM, then SIGKILL."""
        for w in self._pool:
            if w.index is None and w.process.is_alive():
                try:
                    w.conn.send(None)
                except (BrokenPipeError, OSError):
                    pass
            else:
                w.process.terminate()
        for w in self._pool:
            w.process.join(timeout=TERMINATE_GRACE)
            if w.process.is_alive():
                w.process.kill()
                w.process.join()
            w.conn.close()
        self._pool = []


def map_ordered(fn: Callable[[Any], Any], items: Iterable[Any], workers: int | None = None,
                initializer: Callable[..., Any] | None = None, initargs: tuple = ()
                ) -> list[Any]:
    """Apply a picklable function to items in worker processes; results in input order.

    Parameters
    ----------
    fn : callable
        Module-level function of one item.
    items : iterable
        Picklable items.
    workers : int, optional
        Worker processes; default :func:`default_workers`, and never more than the items.
    initializer, initargs
        Per-worker setup, see :class:`WorkerPool`.

    Returns
    -------
    list
        ``fn(item)`` for every item, in input order.

    Raises
    ------
    Exception
        The first failing item's exception (by input position), or :class:`WorkerDied`.
    """
    items = list(items)
    if not items:
        return []
    n = min(workers or default_workers(), len(items))
    with WorkerPool(n, initializer, initargs) as pool:
        return pool.map(fn, items)
