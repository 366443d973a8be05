"""monoplane.jit: kernels compile on first call, and run uncached (with a warning) when numba
has no writable cache directory; row pieces for threads."""

import numba
import numpy as np
import pytest

from monoplane.jit import chunks, kernel


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


def test_kernels_inline_the_helpers_of_their_module(tmp_path, monkeypatch):
    # A module with a helper and a kernel calling it, as the library's modules have them.
    (tmp_path / "helper_module.py").write_text(
        "from monoplane.jit import inline, kernel\n"
        "@inline\n"
        "def twice(x):\n"
        "    return 2 * x\n"
        "@inline\n"
        "def four_times(x):\n"
        "    return twice(twice(x))\n"
        "@kernel\n"
        "def plus_one_twice(x):\n"
        "    return twice(x) + 1\n"
        "@kernel\n"
        "def plus_one_four_times(x):\n"
        "    return four_times(x) + 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    import helper_module

    assert helper_module.plus_one_twice(3) == 7 == helper_module.plus_one_twice.py_func(3)
    assert helper_module.twice(3) == 6  # still a plain function outside kernels
    assert helper_module.plus_one_four_times(3) == 13  # a helper calling a helper


def test_background_roles_run_their_tasks_on_separate_threads(monkeypatch):
    import threading

    from monoplane.jit import in_background

    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    release = threading.Event()
    slow = in_background(lambda: release.wait(5.0))  # holds the "background" thread
    # A "pool" task does not queue behind it.
    assert in_background(lambda: threading.current_thread().name, role="pool")().startswith(
        "monoplane-pool")
    release.set()
    assert slow() is True
    # One thread: the task runs at once, here.
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    ran = []
    get = in_background(lambda: ran.append(threading.current_thread().name) or 7, role="pool")
    assert ran == [threading.current_thread().name] and get() == 7


def test_run_threaded_inside_run_threaded_runs_on_the_worker(monkeypatch):
    # Two workers, each running a task that asks for two more: handed to the same two
    # workers they would wait for each other forever; nested calls run where they are.
    import threading

    from monoplane.jit import run_threaded

    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    both = threading.Barrier(2, timeout=5.0)  # both outer tasks run at the same time

    def outer(k):
        both.wait()
        me = threading.current_thread().name
        return run_threaded([lambda j=j: (k, j, threading.current_thread().name == me)
                             for j in range(2)])

    result = run_threaded([lambda k=k: outer(k) for k in range(2)])
    assert result == [[(k, j, True) for j in range(2)] for k in range(2)]


def test_chunks_cover_the_range_in_pieces_per_thread(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    assert chunks(480, 64) == [(0, 240), (240, 480)]
    pieces = chunks(480, 16, per_thread=4)
    assert len(pieces) == 8 and pieces[0] == (0, 60) and pieces[-1] == (420, 480)
    assert all(a[1] == b[0] for a, b in zip(pieces[:-1], pieces[1:], strict=True))
    # Never more pieces than min_size allows, and one for a short range.
    assert chunks(40, 16, per_thread=4) == [(0, 20), (20, 40)]
    assert chunks(10, 16, per_thread=4) == [(0, 10)]
