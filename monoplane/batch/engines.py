"""Where :func:`~monoplane.batch.frame.process_frame` runs: a local process pool or Ray.

Both engines take the frames still to do and yield one :class:`FrameResult` per frame as soon
as it is known (in completion order). Neither knows anything about stages: each worker warms
the same per-process pipeline cache once and then calls the same per-frame function.

Ray design: one actor per worker (``num_cpus=1``) holds the pipeline; the driver keeps exactly
one frame in flight per actor and refills it as results come back. An actor pool was chosen
over Ray Data's ``map_batches`` because it gives a result (and a progress tick) per frame, lets
the driver attribute a crashed worker to the one frame it was running and replace the actor,
and needs neither pyarrow nor a Dataset for what is a plain list of file paths.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

from monoplane.batch.frame import (
    BatchJob,
    FrameResult,
    has_pipeline,
    one_line,
    pipeline_for,
    process_frame,
)
from monoplane.batch.pool import WorkerPool
from monoplane.batch.specs import FrameSpec
from monoplane.errors import InvalidInput, MonoplaneError

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
    from monoplane.batch.pool import WorkerInitError, fork_if_available

    try:
        # The batch driver only reads files and resolves the config, so its workers may fork
        # from it and skip re-importing everything (see monoplane.batch.pool). Not when this
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


# ---- ray -----------------------------------------------------------------------------------


class RayFrameWorker:
    """Ray actor body: holds one pipeline for the actor's lifetime."""

    def __init__(self, job: BatchJob) -> None:
        self.job = job
        pipeline_for(job.config)

    def ready(self) -> bool:
        return True

    def run(self, spec: FrameSpec) -> FrameResult:
        return process_frame(self.job, spec)


def _text(exc: BaseException) -> str:
    """An exception's text on one line (Ray's are often multi-line)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def _import_ray():  # -> module
    try:
        import ray
    except ImportError:
        raise EngineError("the ray engine needs Ray: pip install 'monoplane[ray]'") from None
    return ray


def run_ray(job: BatchJob, specs: Sequence[FrameSpec], workers: int | None,
            address: str | None = None) -> Iterator[FrameResult]:
    """Run frames on Ray actors.

    Parameters
    ----------
    job, specs
        As :func:`run_local`.
    workers : int, optional
        Number of actors; default: every CPU of the cluster. For a local instance (no
        ``address``) it is also the number of CPUs Ray may use.
    address : str, optional
        ``"auto"`` (a cluster started with ``ray start`` on this machine) or
        ``"ray://host:port"`` (Ray Client). Without it a local Ray instance is started and shut
        down at the end. When Ray is already initialised in this process, it is used as is.
    """
    if not specs:
        return
    ray = _import_ray()
    from ray.exceptions import RayActorError, RayError, RayTaskError

    started = False
    if not ray.is_initialized():
        try:
            if address:
                ray.init(address=address, log_to_driver=False)
            else:
                ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        except (ConnectionError, RayError, ValueError, RuntimeError) as exc:
            where = f"at {address}" if address else "locally"
            raise EngineError(f"cannot start or join Ray {where}: {_text(exc)}") from None
        started = True
    actors: list = []
    try:
        n = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
        n = min(n, len(specs))
        actor_cls = ray.remote(num_cpus=1, max_restarts=0)(RayFrameWorker)
        actors = [actor_cls.remote(job) for _ in range(n)]
        try:
            ray.get([a.ready.remote() for a in actors])
        except RayError as exc:
            raise EngineError(f"Ray workers could not start: {_text(exc)}") from None
        queue = list(range(len(specs)))[::-1]  # pop() from the end = input order
        pending: dict = {}

        def submit(slot: int) -> None:
            i = queue.pop()
            pending[actors[slot].run.remote(specs[i])] = (slot, i)

        for slot in range(n):
            if queue:
                submit(slot)
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            slot, i = pending.pop(done[0])
            try:
                result = ray.get(done[0])
            except RayActorError as exc:
                result = FrameResult(specs[i].name, "failed",
                                     error=f"Ray worker died while running this frame: "
                                           f"{one_line(exc)}")
                ray.kill(actors[slot], no_restart=True)
                actors[slot] = actor_cls.remote(job)
            except RayTaskError as exc:  # process_frame returns failures; this is a bug
                result = FrameResult(specs[i].name, "failed", error=one_line(exc))
            yield result
            if queue:
                submit(slot)
    finally:
        for a in actors:
            try:
                ray.kill(a, no_restart=True)
            except Exception:  # already dead or Ray shutting down: nothing left to stop
                pass
        if started:
            ray.shutdown()


def check_engine(engine: str, ray_address: str | None = None) -> None:
    """Fail before any work on an unknown engine, a misplaced address or Ray not installed."""
    if engine not in ENGINES:
        raise InvalidInput(f"unknown engine {engine!r}; choose one of {', '.join(ENGINES)}")
    if engine == "local" and ray_address:
        raise InvalidInput("--ray-address needs --engine ray")
    if engine == "ray":
        _import_ray()


def run_engine(engine: str, job: BatchJob, specs: Sequence[FrameSpec], workers: int | None,
               ray_address: str | None = None) -> Iterator[FrameResult]:
    """Dispatch to :func:`run_local` or :func:`run_ray`."""
    from monoplane.batch.pool import default_workers

    check_engine(engine, ray_address)
    if engine == "local":
        return run_local(job, specs, workers or default_workers())
    return run_ray(job, specs, workers, ray_address)
