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
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])


def _compile(fn: Callable[..., Any]) -> Callable[..., Any]:
    import numba

    try:
        return numba.njit(cache=True, nogil=True)(fn)
    except RuntimeError as exc:  # no writable cache location for this module
        warnings.warn(f"numba cannot cache {fn.__module__}.{fn.__qualname__} ({exc}); "
                      f"it will be compiled again in every process", RuntimeWarning,
                      stacklevel=3)
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
    compiled: Callable[..., Any] | None = None

    @functools.wraps(fn)
    def call(*args: Any) -> Any:
        nonlocal compiled
        if compiled is None:
            compiled = _compile(fn)
        return compiled(*args)

    call.py_func = fn  # type: ignore[attr-defined]
    return call  # type: ignore[return-value]
