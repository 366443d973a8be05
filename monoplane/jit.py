"""Compiled kernels (numba, compiled on first use and cached on disk) and the threads they run on.

:func:`kernel` marks a plain-Python loop function as a numba ``nopython`` kernel. It is
compiled the first time it is called, not when its module is imported (importing numba alone
takes a noticeable fraction of a second, which commands that never run RANSAC should not pay),
and the machine code is cached on disk (``cache=True``): the first run on a machine compiles
every kernel once (15-30 s in all), later processes load them. ``setup.sh`` pays that cost
at installation: it runs :mod:`monoplane.warmup`, which calls every kernel once. Each kernel
wrapper is listed in :func:`kernels`, so the warm-up can check that it reached all of them.

numba looks for a writable cache directory next to the module (``__pycache__``), then in the
user's cache (``~/.cache/numba`` or ``NUMBA_CACHE_DIR``); when there is none it refuses to
compile a ``cache=True`` function. Then the kernel is compiled without a cache instead, with
a :class:`RuntimeWarning`, so a read-only installation still runs (it compiles in every
process).

Kernels are called only with arrays of fixed dtypes (documented per kernel), so each compiles
exactly one specialisation. Their plain-Python originals stay available as ``.py_func``.

Kernels release the GIL (``nogil``), so independent calls (the dense CRF's kernels, chunks of a
kNN query) run in parallel Python threads: :func:`run_threaded`, on at most
:func:`thread_budget` threads. Threads rather than numba's ``parallel=True`` because the work
comes in a few coarse pieces, and because numba's threading layers must not be running when
the batch driver forks its workers.
"""

from __future__ import annotations

import functools
import os
import threading
import types
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])
T = TypeVar("T")


def inline(fn: F) -> F:
    """Mark a small function as callable from the kernels of its own module.

    It stays a plain Python function; when a kernel that calls it is compiled, it is compiled
    too and inlined into that kernel. Keep it in the module of the kernels that call it:
    numba's disk cache of a kernel is invalidated when the kernel's own source file changes,
    not when a helper in another file does.

    Parameters
    ----------
    fn : callable
        A function numba can compile in nopython mode, calling no kernels (other helpers of
        its module are fine).

    Returns
    -------
    callable
        ``fn`` itself, marked.
    """
    fn._monoplane_inline = True  # type: ignore[attr-defined]
    return fn


def _with_helpers(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn``, or a copy of it whose globals map the :func:`inline` helpers it names to their
    compiled versions (numba resolves a kernel's global names when it compiles it)."""
    import numba

    env = fn.__globals__
    names = [n for n in fn.__code__.co_names if getattr(env.get(n), "_monoplane_inline", False)]
    if not names:
        return fn
    # Helpers may call helpers: each is given its own compiled ones the same way.
    env = {**env, **{n: numba.njit(inline="always")(_with_helpers(env[n])) for n in names}}
    clone = types.FunctionType(fn.__code__, env, fn.__name__, fn.__defaults__, fn.__closure__)
    clone.__qualname__, clone.__module__, clone.__doc__ = fn.__qualname__, fn.__module__, fn.__doc__
    return clone


def _compile(fn: Callable[..., Any]) -> Callable[..., Any]:
    import numba

    fn = _with_helpers(fn)
    try:
        return numba.njit(cache=True, nogil=True)(fn)
    except RuntimeError as exc:  # no writable cache location for this module
        warnings.warn(f"numba cannot cache {fn.__module__}.{fn.__qualname__} ({exc}); "
                      f"it will be compiled again in every process", RuntimeWarning,
                      stacklevel=3)
        return numba.njit(cache=False, nogil=True)(fn)


#: Every :func:`kernel` wrapper created so far (modules register theirs when imported).
_KERNELS: list[Callable[..., Any]] = []


def kernels() -> list[Callable[..., Any]]:
    """The :func:`kernel` wrappers of every module imported so far; ``k.is_compiled()`` says
    whether ``k`` has been compiled (or loaded from the disk cache) in this process."""
    return list(_KERNELS)


def kernel(fn: F) -> F:
    """Compile ``fn`` with numba (nopython, cached on disk) on its first call.

    Parameters
    ----------
    fn : callable
        A function numba can compile in nopython mode. It must not call other kernels
        (they are ordinary Python callables until compiled); it may call :func:`inline`
        helpers of its own module.

    Returns
    -------
    callable
        A wrapper with the same signature; ``wrapper.py_func`` is ``fn`` itself.
    """
    compiled: Callable[..., Any] | None = None
    lock = threading.Lock()  # threads calling it first together compile it once

    @functools.wraps(fn)
    def call(*args: Any) -> Any:
        nonlocal compiled
        if compiled is None:
            with lock:
                if compiled is None:
                    compiled = _compile(fn)
        return compiled(*args)

    call.py_func = fn  # type: ignore[attr-defined]
    call.is_compiled = lambda: (  # type: ignore[attr-defined]
        compiled is not None and bool(getattr(compiled, "signatures", True)))
    _KERNELS.append(call)
    return call  # type: ignore[return-value]


def thread_budget() -> int:
    """Threads one frame may use: ``OMP_NUM_THREADS`` when set (the batch and multi-view worker
    pools set it to cores / workers, so parallel frames do not oversubscribe the cores), else
    the number of CPUs."""
    try:
        return max(1, int(os.environ.get("OMP_NUM_THREADS", "")))
    except ValueError:
        return _cpu_count()


@functools.cache
def _cpu_count() -> int:
    # Asked about twenty times a frame; os.cpu_count() reads /sys each time (about 40 µs).
    return max(1, os.cpu_count() or 1)


_POOLS: dict[str, tuple[Any, ThreadPoolExecutor] | None] = {
    "work": None, "background": None, "pool": None}


def _executor(threads: int, role: str = "work") -> ThreadPoolExecutor:
    # One long-lived pool per process, role and size: starting threads for every call would
    # cost more than small calls take. Keyed by pid too, since a forked child has none of the
    # parent's threads.
    key = (os.getpid(), threads)
    entry = _POOLS[role]
    if entry is None or entry[0] != key:
        entry = _POOLS[role] = (key, ThreadPoolExecutor(threads,
                                                         thread_name_prefix=f"monoplane-{role}"))
    return entry[1]


def run_threaded(tasks: Sequence[Callable[[], T]]) -> list[T]:
    """Call every task, on up to :func:`thread_budget` threads; results in task order.

    Parameters
    ----------
    tasks : sequence of callables
        Independent zero-argument calls, normally of ``nogil`` kernels (pure-Python work
        gains nothing from threads). Pass the most expensive first: they start first.

    Returns
    -------
    list
        ``[task() for task in tasks]``.

    Notes
    -----
    A task may call this again (a chunk of pixels querying the point index, say): the nested
    call runs its tasks on the calling worker, one after the other. Handing them to the same
    workers would leave every worker waiting for tasks queued behind itself.
    """
    threads = min(len(tasks), thread_budget())
    if threads < 2 or getattr(_worker, "busy", False):
        return [task() for task in tasks]
    return list(_executor(threads).map(_as_worker, tasks))


#: Per-thread flag: set while a thread runs a task of :func:`run_threaded`.
_worker = threading.local()


def _as_worker(task: Callable[[], T]) -> T:
    _worker.busy = True
    try:
        return task()
    finally:
        _worker.busy = False


def in_background(task: Callable[[], T], role: str = "background") -> Callable[[], T]:
    """Start ``task`` on a background thread, when the thread budget allows two or more.

    The caller goes on with work that does not need the result, then calls the returned
    function, which waits for the task and returns its result (or raises its exception). With
    a budget of one thread the task runs here and now, before this returns.

    Parameters
    ----------
    task : callable
        A zero-argument call; its own :func:`run_threaded` calls run on the worker threads
        (the background thread is not one of them, so it cannot starve them).
    role : {"background", "pool"}
        Which background thread: tasks of one role run one after the other, in the order
        they were started. ``"background"`` takes the frame's long tasks (the neighbour
        graph, then a refiner's preparation), ``"pool"`` the RANSAC's short per-pool ones,
        which must not queue behind those.

    Returns
    -------
    callable
        Zero-argument function returning ``task()``.
    """
    if thread_budget() < 2:
        result = task()
        return lambda: result
    return _executor(1, role).submit(task).result


def chunks(n: int, min_size: int, per_thread: int = 1) -> list[tuple[int, int]]:
    """Split ``range(n)`` into at most ``per_thread`` × :func:`thread_budget` contiguous
    ``(start, stop)`` pieces of at least ``min_size`` items (one piece when ``n`` is small).
    More pieces than threads balance work that is uneven along ``range(n)``: each thread
    takes the next piece when it is free."""
    parts = max(1, min(per_thread * thread_budget(), n // max(min_size, 1)))
    bounds = [round(i * n / parts) for i in range(parts + 1)]
    return list(zip(bounds[:-1], bounds[1:], strict=True))
