"""Where :func:`~monoplane.batch.frame.process_frame` runs: a local process pool or Ray.

Both engines take the frames still to do and yield one :class:`FrameResult` per frame as soon
as it is known (in completion order). Neither knows anything about stages: each worker warms
the same per-process pipeline cache once and then calls the same per-frame function.

Ray design: one Ray task per frame (``num_cpus=1``, no automatic retry), at most ``workers``
in flight, refilled as results come back. Ray reuses its worker processes for tasks, so each
worker builds the pipeline once. Tasks were chosen over an actor pool because a task is not tied
to a node: when a worker process or a whole node is lost, the driver submits the lost frame
again and Ray places it on whatever CPU is left, whereas a replacement actor needs a free CPU
of its own and waits forever for one when the cluster has shrunk. The driver, not Ray, does
the retries so that it can bound them, count them per frame and report them. Ray Data's
``map_batches`` would need neither less code nor give a result (and a progress tick) per frame.
"""

from __future__ import annotations

import logging
import re
import socket
import time
from collections import deque
from collections.abc import Iterator, Sequence
from types import ModuleType
from typing import Any

from monoplane.batch.frame import (
    BatchJob,
    FrameResult,
    has_pipeline,
    one_line,
    pipeline_for,
    process_frame,
)
from monoplane.batch.specs import FrameSpec
from monoplane.errors import InvalidInput, MonoplaneError
from monoplane.host.pool import WorkerInitError, WorkerPool, default_workers, fork_if_available

ENGINES = ("local", "ray")


class EngineError(MonoplaneError):
    """An engine could not start (Ray missing or unreachable, workers that fail to start)."""


# ---- local ---------------------------------------------------------------------------------

_JOB: BatchJob | None = None


def _init_local_worker(job: BatchJob) -> None:
    global _JOB
    _JOB = job
    pipeline_for(job.config)


def _run_local_frame(spec: FrameSpec) -> FrameResult:
    assert _JOB is not None, "worker used before _init_local_worker"
    return process_frame(_JOB, spec)


def run_local(job: BatchJob, specs: Sequence[FrameSpec], workers: int
              ) -> Iterator[FrameResult]:
    """Run frames on ``workers`` local processes (never more than there are frames)."""
    if not specs:
        return
    try:
        # The batch driver only reads files and resolves the config, so its workers may fork
        # from it and skip re-importing everything (see monoplane.host.pool). Not when this
        # process has built a pipeline itself (Python API use): its ONNX sessions' threads
        # would not exist in the children.
        method = "spawn" if has_pipeline() else fork_if_available()
        with WorkerPool(min(workers, len(specs)), _init_local_worker, (job,),
                        start_method=method) as pool:
            for outcome in pool.imap_unordered(_run_local_frame, specs):
                if outcome.error is not None:
                    yield FrameResult(specs[outcome.index].name, "failed",
                                      error=one_line(outcome.error))
                else:
                    yield outcome.value
    except WorkerInitError as exc:
        raise EngineError(f"batch workers could not start: {exc}") from exc


# ---- ray ------------------------------------------------------------------------------------

#: Attempts of a frame whose Ray worker or node was lost before it reported back (the first
#: run included). A frame that kills its worker every time (a segfault, the OOM killer) fails
#: after these; a frame that was on a node the cluster lost runs again on a surviving one.
RAY_ATTEMPTS = 3

#: Seconds the driver waits with frames in flight while the cluster has no CPU at all (every
#: worker node lost, none added) before it fails the frames still to do.
RAY_NO_CPU_SECONDS = 120.0

#: Seconds to wait for a TCP connection to an explicit Ray address before giving up. Ray itself
#: retries an unreachable address for minutes, printing a warning every few seconds.
RAY_CONNECT_SECONDS = 5.0

_RAY_ADDRESS = re.compile(r"^(?:ray://)?(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+)(?::(\d{1,5}))?$")


def _text(exc: BaseException) -> str:
    """An exception's text on one line (Ray's are often multi-line)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def _import_ray():  # -> module
    try:
        import ray
    except ImportError:
        raise EngineError("the ray engine needs Ray: pip install 'monoplane[ray]'") from None
    return ray


def parse_ray_address(address: str) -> tuple[str, int] | None:
    """Check a ``--ray-address``; the host and port to probe, or None for ``auto``.

    Parameters
    ----------
    address : str
        ``"auto"``, ``"HOST:PORT"`` (the GCS address of a running cluster, as ``ray start
        --head`` prints it) or ``"ray://HOST[:PORT]"`` (Ray Client, port 10001 by default).

    Raises
    ------
    InvalidInput
        Any other form.
    """
    if address == "auto":
        return None
    match = _RAY_ADDRESS.match(address)
    client = address.startswith("ray://")
    if match is None or (not client and match.group(2) is None):
        raise InvalidInput(f"--ray-address {address!r}: use auto, HOST:PORT (the cluster's GCS "
                           "address) or ray://HOST:PORT (Ray Client)")
    port = int(match.group(2) or 10001)
    if not 0 < port < 65536:
        raise InvalidInput(f"--ray-address {address!r}: port {port} is out of range")
    return match.group(1).strip("[]"), port


def _probe(address: str) -> None:
    """Fail in seconds, not minutes, when nothing listens at an explicit address."""
    target = parse_ray_address(address)
    if target is None:
        return
    try:
        socket.create_connection(target, timeout=RAY_CONNECT_SECONDS).close()
    except OSError as exc:
        raise EngineError(f"cannot reach Ray at {address}: {exc.strerror or _text(exc)}"
                          ) from None


def _lost_worker_errors() -> tuple[type[BaseException], ...]:
    """Ray errors that mean the frame's worker process or node went away, not the frame."""
    from ray import exceptions as rx

    return (rx.WorkerCrashedError, rx.NodeDiedError, rx.LocalRayletDiedError,
            rx.ObjectLostError, rx.OutOfMemoryError)


def _join_ray(ray: ModuleType, address: str | None, workers: int | None) -> bool:
    """Start or join Ray unless this process has already; True when it started it here.

    Raises
    ------
    EngineError
        When Ray cannot be started or joined (one line naming where).
    """
    from ray.exceptions import RayError

    if ray.is_initialized():
        return False
    if address:
        _probe(address)
    try:
        if address:
            ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING)
        else:
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False,
                     logging_level=logging.WARNING)
    except (ConnectionError, RayError, ValueError, RuntimeError) as exc:
        where = f"at {address}" if address else "locally"
        raise EngineError(f"cannot start or join Ray {where}: {_text(exc)}") from None
    return True


def _ray_result(ray: ModuleType, ref: Any, name: str, attempt: int,
                notes: list[str] | None) -> FrameResult | None:
    """The result of a finished frame task, or None when its worker was lost and the frame
    should run again (attempt ``attempt`` of :data:`RAY_ATTEMPTS`; a note says so)."""
    from ray.exceptions import RayError

    try:
        return ray.get(ref)
    except _lost_worker_errors() as exc:
        if attempt < RAY_ATTEMPTS:
            if notes is not None:
                notes.append(f"{name}: ran again after its Ray worker was "
                             f"lost ({type(exc).__name__}, attempt {attempt} of "
                             f"{RAY_ATTEMPTS})")
            return None
        return FrameResult(name, "failed",
                           error=f"its Ray worker was lost on all {attempt} "
                                 f"attempts; the last time: {_text(exc)}")
    except RayError as exc:  # process_frame returns failures; this is Ray's or a bug
        return FrameResult(name, "failed", error=one_line(exc))


def run_ray(job: BatchJob, specs: Sequence[FrameSpec], workers: int | None,
            address: str | None = None, notes: list[str] | None = None
            ) -> Iterator[FrameResult]:
    """Run frames as Ray tasks, at most ``workers`` at once, retrying frames whose worker died.

    Parameters
    ----------
    job, specs
        As :func:`run_local`.
    workers : int, optional
        Frames in flight at once (each task takes one CPU); default: the cluster's CPUs when
        the run starts. For a local instance (no ``address``) it is also the number of CPUs
        Ray may use.
    address : str, optional
        ``"auto"`` (a cluster started with ``ray start`` on this machine), ``"HOST:PORT"`` (the
        GCS address of a running cluster) or ``"ray://HOST:PORT"`` (Ray Client). Without it a
        local Ray instance is started and shut down at the end. When Ray is already
        initialised in this process, it is used as is.
    notes : list of str, optional
        Receives one line per frame that ran again, naming the frame and what was lost.

    Yields
    ------
    FrameResult
        One per frame, in completion order. A frame whose worker process or node was lost is
        submitted again, up to :data:`RAY_ATTEMPTS` attempts in all. Its output folder is only
        ever created or replaced by a rename, so an attempt that died mid-write leaves nothing
        behind, and the folder holds the output of one whole attempt.
    """
    if not specs:
        return
    ray = _import_ray()
    started = _join_ray(ray, address, workers)
    pending: dict = {}
    try:
        n = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        # Ray reuses its worker processes for later tasks, so each worker builds the pipeline
        # (pipeline_for) once, as in the local pool. No retries by Ray: see the loop below.
        task = ray.remote(num_cpus=1, max_retries=0)(process_frame)
        job_ref = ray.put(job)
        queue = deque(range(len(specs)))  # input order; a retried frame goes to the front
        attempts = [0] * len(specs)
        no_cpu_since: float | None = None
        while queue or pending:
            while queue and len(pending) < n:
                i = queue.popleft()
                attempts[i] += 1
                pending[task.remote(job_ref, specs[i])] = i
            done, _ = ray.wait(list(pending), num_returns=1, timeout=5.0)
            if not done:
                # Frames stay queued while no node has a CPU; after a while that is an answer.
                if ray.cluster_resources().get("CPU", 0) > 0:
                    no_cpu_since = None
                    continue
                if no_cpu_since is None:
                    no_cpu_since = time.monotonic()
                if time.monotonic() - no_cpu_since < RAY_NO_CPU_SECONDS:
                    continue
                reason = (f"the Ray cluster has had no CPU for {RAY_NO_CPU_SECONDS:.0f} s "
                          "(every worker node lost)")
                for ref, i in list(pending.items()):
                    ray.cancel(ref, force=True)
                    yield FrameResult(specs[i].name, "failed", error=reason)
                for i in queue:
                    yield FrameResult(specs[i].name, "failed", error=reason)
                pending.clear()
                queue.clear()
                break
            i = pending.pop(done[0])
            result = _ray_result(ray, done[0], specs[i].name, attempts[i], notes)
            if result is None:
                queue.appendleft(i)
                continue
            yield result
    finally:
        for ref in pending:  # Ctrl-C or an error: stop what still runs
            try:
                ray.cancel(ref, force=True)
            except Exception:  # already finished, or Ray shutting down: nothing to stop
                pass
        if started:
            ray.shutdown()


def check_engine(engine: str, ray_address: str | None = None) -> None:
    """Fail before any work on an unknown engine, a misplaced address or Ray not installed."""
    if engine not in ENGINES:
        raise InvalidInput(f"unknown engine {engine!r}; choose one of {', '.join(ENGINES)}")
    if engine == "local" and ray_address:
        raise InvalidInput("--ray-address needs --engine ray")
    if ray_address:
        parse_ray_address(ray_address)
    if engine == "ray":
        _import_ray()


def run_engine(engine: str, job: BatchJob, specs: Sequence[FrameSpec], workers: int | None,
               ray_address: str | None = None, notes: list[str] | None = None
               ) -> Iterator[FrameResult]:
    """Dispatch to :func:`run_local` or :func:`run_ray` (``notes``: see :func:`run_ray`)."""
    check_engine(engine, ray_address)
    if engine == "local":
        return run_local(job, specs, workers or default_workers())
    return run_ray(job, specs, workers, ray_address, notes)
