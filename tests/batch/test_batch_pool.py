"""The reusable worker pool: per-worker setup once, results in order, failures per item."""

from __future__ import annotations

import os

import pytest

from monoplane.batch import WorkerDied, WorkerInitError, WorkerPool, map_ordered
from monoplane.host.pool import fork_if_available

_STATE: dict[str, object] = {}


def setup_worker(offset: int) -> None:
    _STATE["offset"] = offset
    _STATE["pid"] = os.getpid()
    _STATE["setups"] = _STATE.get("setups", 0) + 1  # type: ignore[operator]


def add_offset(x: int) -> tuple[int, int, int]:
    if x == 13:
        raise ValueError("unlucky item 13")
    if x == 666:
        os._exit(3)  # a worker that dies, as on a segfault
    return x + _STATE["offset"], _STATE["pid"], _STATE["setups"]  # type: ignore[return-value]


def failing_setup() -> None:
    raise RuntimeError("no model file")


def test_map_ordered_runs_setup_once_per_worker():
    results = map_ordered(add_offset, range(12), workers=2, initializer=setup_worker,
                          initargs=(100,))
    assert [r[0] for r in results] == [x + 100 for x in range(12)]
    assert {r[2] for r in results} == {1}  # each worker was set up exactly once
    assert len({r[1] for r in results}) <= 2 and os.getpid() not in {r[1] for r in results}


def thread_limits(_: object) -> tuple[str | None, set[int]]:
    from threadpoolctl import threadpool_info

    return os.environ.get("OMP_NUM_THREADS"), {p["num_threads"] for p in threadpool_info()}


@pytest.mark.skipif(fork_if_available() != "fork", reason="fork is Linux-only here")
def test_forked_workers_get_their_thread_share(monkeypatch):
    import numpy  # noqa: F401  (loads a BLAS pool in this process before the fork)

    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    with WorkerPool(2, threads_per_worker=1, start_method="fork") as pool:
        env, blas = pool.map(thread_limits, [0])[0]
    assert env == "1" and blas == {1}


@pytest.mark.parametrize("start_method", ["spawn", fork_if_available()])
def test_item_errors_and_dead_workers_are_reported_per_item(start_method):
    with WorkerPool(2, setup_worker, (0,), start_method=start_method) as pool:
        outcomes = sorted(pool.imap_unordered(add_offset, [1, 13, 666, 4, 5]),
                          key=lambda o: o.index)
        assert [o.value[0] if o.error is None else None for o in outcomes] == [
            1, None, None, 4, 5]
        assert isinstance(outcomes[1].error, ValueError)
        assert "unlucky item 13" in str(outcomes[1].error)
        assert isinstance(outcomes[2].error, WorkerDied)
        assert "exit status 3" in str(outcomes[2].error)
        # The dead worker was replaced: the pool still runs work on two processes.
        assert [r[0] for r in pool.map(add_offset, [7, 8])] == [7, 8]
        with pytest.raises(ValueError, match="unlucky"):
            pool.map(add_offset, [1, 13])


def test_failing_initializer_is_one_clear_error():
    with pytest.raises(WorkerInitError, match="no model file"):
        map_ordered(add_offset, [1], workers=1, initializer=failing_setup)


def test_fork_is_chosen_only_without_other_threads():
    import threading

    assert fork_if_available() in ("fork", "spawn")
    stop = threading.Event()
    helper = threading.Thread(target=stop.wait)
    helper.start()
    try:
        assert fork_if_available() == "spawn"  # another thread is alive: forking is not safe
    finally:
        stop.set()
        helper.join()
