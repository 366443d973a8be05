"""monoplane.jit: kernels compile on first call, and run uncached (with a warning) when numba
has no writable cache directory."""

import numba
import numpy as np
import pytest

from monoplane.jit import kernel


def test_kernel_compiles_on_first_call_and_keeps_the_python_function():
    def total(x):
        s = 0.0
        for v in x:
            s += v
        return s

    k = kernel(total)
    assert k.py_func is total
    assert k(np.arange(4.0)) == 6.0


def test_without_a_writable_cache_the_kernel_still_runs(monkeypatch):
    real = numba.njit

    def njit(**options):
        if options.get("cache"):
            # What numba raises when neither __pycache__ nor the user cache is writable.
            raise RuntimeError("cannot cache function: no locator available")
        return real(**options)

    monkeypatch.setattr(numba, "njit", njit)

    def double(x):
        return 2 * x

    with pytest.warns(RuntimeWarning, match="numba cannot cache"):
        assert kernel(double)(21) == 42
