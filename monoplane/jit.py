"""Compiled kernels: numba, compiled on first use and cached on disk.

:func:`kernel` marks a plain-Python loop function as a numba ``nopython`` kernel. It is
compiled the first time it is called, not when its module is imported (importing numba alone
takes a noticeable fraction of a second, which commands that never run RANSAC should not pay),
and the machine code is cached on disk (``cache=True``): the first run on a machine compiles
every kernel once (see ``monoplane bench`` for the warm-up time), later processes load them.

numba looks for a writable cache directory next to the module (``__pycache__``), then in the
user's cache (``~/.cache/numba`` or ``NUMBA_CACHE_DIR``); when there is none it refuses to
compile a ``cache=True`` function. Then the kernel is compiled without a cache instead, with
a :class:`RuntimeWarning`, so a read-only installation still runs (it compiles in every
process).

Kernels are called only with arrays of fixed dtypes (documented per kernel), so each compiles
exactly one specialisation. Their plain-Python originals stay available as ``.py_func``.
"""

from __future__ import annotations

import functools
import os
import threading
import types
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])


def _compile(fn: Callable[..., Any], parallel: bool) -> Callable[..., Any]:
    import numba

    if parallel:
        if not os.environ.get("NUMBA_THREADING_LAYER"):
            # OpenMP's fork-join waits for every thread at each launch: on a busy machine
            # (more runnable threads than cores) the many short kernel calls of a RANSAC then
            # ran several times slower than on one thread (measured on 2 cores, load 8).
            # numba's own work queue did not degrade; it only serves one launching thread at a
            # time, which _lazy guarantees. Effective until the first parallel launch.
            numba.config.THREADING_LAYER = "workqueue"
        # The same code with numba's prange in place of this module's plain one.
        scope = dict(fn.__globals__, prange=numba.prange)
        fn = types.FunctionType(fn.__code__, scope, fn.__name__, fn.__defaults__, fn.__closure__)

    try:
        return numba.njit(cache=True, nogil=True, parallel=parallel)(fn)
    except RuntimeError as exc:  # no writable cache location for this module
        warnings.warn(f"numba cannot cache {fn.__module__}.{fn.__qualname__} ({exc}); "
                      f"it will be compiled again in every process", RuntimeWarning,
                      stacklevel=3)
        return numba.njit(cache=False, nogil=True, parallel=parallel)(fn)


def _compile_serial(fn: Callable[..., Any]) -> Callable[..., Any]:
    """A parallel kernel's loops compiled serially (``prange`` as ``range``). Not cached on
    disk: its cache entry would share the parallel version's file and signature."""
    import numba

    scope = dict(fn.__globals__, prange=range)
    fn = types.FunctionType(fn.__code__, scope, fn.__name__, fn.__defaults__, fn.__closure__)
    return numba.njit(cache=False, nogil=True)(fn)


def kernel(fn: F) -> F:
    """Compile ``fn`` with numba (nopython, cached on disk) on its first call.

    Parameters
    ----------
    fn : callable
        A function numba can compile in nopython mode. It must not call other kernels
        (they are ordinary Python callables until compiled).

    Returns
    -------
    callable
        A wrapper with the same signature; ``wrapper.py_func`` is ``fn`` itself.
    """
    return _lazy(fn, parallel=False)


def parallel_kernel(fn: F) -> F:
    """:func:`kernel` compiled with ``parallel=True``: its ``numba.prange`` loops run on
    ``NUMBA_NUM_THREADS`` threads (all cores unless set; ``monoplane batch`` sets it to the
    cores per worker) when called from the main thread, serially from other threads.

    Only loops whose iterations write disjoint outputs may use ``prange``: no reduction
    across iterations, so that the result does not depend on the thread count or schedule.
    In ``py_func`` ``prange`` is the plain ``range``.
    """
    return _lazy(fn, parallel=True)


def prange(*args: int) -> range:
    """The plain ``range``; in a :func:`parallel_kernel` it is compiled as ``numba.prange``.

    Kernels import it from here rather than from numba so that importing a kernel module does
    not import numba (:func:`_compile` swaps it in when the kernel is compiled).
    """
    return range(*args)


def _lazy(fn: F, parallel: bool) -> F:
    compiled: Callable[..., Any] | None = None
    serial: Callable[..., Any] | None = None

    @functools.wraps(fn)
    def call(*args: Any) -> Any:
        nonlocal compiled, serial
        if parallel and threading.current_thread() is not threading.main_thread():
            # Parallel launches come from the main thread only (the work-queue threading
            # layer is not re-entrant); other threads run the same loops serially, with
            # the same results (no reduction crosses prange iterations).
            if serial is None:
                serial = _compile_serial(fn)
            return serial(*args)
        if compiled is None:
            compiled = _compile(fn, parallel)
        return compiled(*args)

    call.py_func = fn  # type: ignore[attr-defined]
    return call  # type: ignore[return-value]
