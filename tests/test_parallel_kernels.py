"""Parallel numba kernels (``monoplane.jit.parallel_kernel``): the same bits for any thread
count (each prange iteration writes its own outputs, no reduction across them), and the
results of their plain Python originals up to libm rounding (relative 1e-12)."""

import numba
import numpy as np
import pytest

from monoplane import graphcut
from monoplane.stages import scorers


@pytest.fixture
def cloud():
    rng = np.random.default_rng(3)
    points = rng.uniform(-1, 1, size=(3000, 3))
    normals = rng.normal(size=(3000, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    planes = rng.normal(size=(40, 4))
    planes[:, :3] /= np.linalg.norm(planes[:, :3], axis=1, keepdims=True)
    planes[:, 3] *= 0.05
    pool = np.sort(rng.choice(3000, size=1700, replace=False)).astype(np.int64)
    edges = rng.integers(0, 3000, size=(5000, 2)).astype(np.int64)
    colors = rng.uniform(0, 1, size=(3000, 3))
    return points, normals, planes, pool, edges, colors


def _calls(cloud):
    points, normals, planes, pool, edges, colors = cloud
    eps, eps_n = 0.3, np.deg2rad(10.0)
    return [
        (scorers._costs, (points, normals, pool, planes, planes[:, :3].copy(), eps, eps_n,
                          kind)) for kind in (scorers._INLIERS, scorers._MSAC,
                                              scorers._MSAC_NORMAL)
    ] + [
        (graphcut._data_costs, (points, normals, pool, planes[0], planes[0, :3].copy(), eps,
                                eps_n, use)) for use in (False, True)
    ] + [
        (graphcut._proximity_weights, (points, edges, normals, colors, 0.005, 0.1, 5.0,
                                       1.0, 1.0, 1.0)),
    ]


def _run(fn, args, threads):
    previous = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        out = fn(*args)
        return list(out) if isinstance(out, tuple) else [out]
    finally:
        numba.set_num_threads(previous)


def test_parallel_kernels_are_thread_count_independent_and_match_python(cloud):
    for fn, args in _calls(cloud):
        one = _run(fn, args, 1)
        for got, want in zip(_run(fn, args, 2), one, strict=True):
            np.testing.assert_array_equal(got, want)
        expected = fn.py_func(*args)
        expected = expected if isinstance(expected, tuple) else (expected,)
        for got, want in zip(one, expected, strict=True):
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_parallel_kernels_run_serially_off_the_main_thread(cloud):
    from concurrent.futures import ThreadPoolExecutor

    calls = _calls(cloud)
    with ThreadPoolExecutor(2) as pool:
        results = list(pool.map(lambda c: c[0](*c[1]), calls + calls))
    for (fn, args), got in zip(calls + calls, results, strict=True):
        want = _run(fn, args, 1)
        got = list(got) if isinstance(got, tuple) else [got]
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g, w)
