"""The Ray engine loses a node mid-batch and still finishes every frame, once, with the labels of
the local engine.

A two-node Ray cluster runs on this machine (``ray.cluster_utils.Cluster``: a head and a worker
node, one CPU each). ``monoplane batch --engine ray --ray-address HOST:PORT --workers 2`` runs in
this process while a watcher thread removes the worker node once a third of the frames are
written and a frame is running on that node, so that one frame is lost with its node and has
to run again on the head.
"""

from __future__ import annotations

import csv
import json
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from batch_helpers import read_labels

from monoplane.batch import run_batch
from monoplane.cli import main
from monoplane.synth.batchset import write_frame_folder

#: Frames in the batch, rows of a manifest over DISTINCT synthetic frames (writing fewer,
#: larger frames keeps the test short while each frame runs long enough to be caught mid-way).
FRAMES = 24
DISTINCT = 6
TIMEOUT = 60.0


@pytest.fixture(scope="module")
def manifest(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("cluster_frames")
    folders = write_frame_folder(root, n=DISTINCT, width=256, height=192)
    path = root / "frames.csv"
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["name", "image", "depth", "normals", "intrinsics"])
        for i in range(FRAMES):
            f = folders[i % DISTINCT].name
            out.writerow([f"f{i:02d}", f"{f}/rgb.png", f"{f}/depth.npy", f"{f}/normals.npy",
                          f"{f}/intrinsics.json"])
    return path


def _busy_on(raylet_pid: int) -> bool:
    """Whether a worker process of the node whose raylet is ``raylet_pid`` runs a frame (Ray
    titles a worker process after the task it executes)."""
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            ppid = int((proc / "stat").read_text().rsplit(")", 1)[1].split()[1])
            title = (proc / "cmdline").read_bytes()
        except (OSError, IndexError, ValueError):
            continue  # the process ended while we looked
        if ppid == raylet_pid and title.startswith(b"ray::process_frame"):
            return True
    return False


def _done(out: Path) -> int:
    if not out.is_dir():
        return 0
    return sum(p.is_dir() and not p.name.startswith(".") for p in out.iterdir())


def test_worker_node_lost_mid_batch(manifest: Path, tmp_path: Path,
                                    capsys: pytest.CaptureFixture[str]) -> None:
    ray = pytest.importorskip("ray")
    from ray.cluster_utils import Cluster

    local = run_batch(manifest, tmp_path / "local", workers=2, progress=False)
    assert local.count("ok") == FRAMES

    out = tmp_path / "ray"
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    removed: dict[str, object] = {}
    try:
        worker = cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        raylet_pid = worker.all_processes["raylet"][0].process.pid

        def remove_when_busy() -> None:
            try:
                deadline = time.monotonic() + TIMEOUT
                while time.monotonic() < deadline:
                    done = _done(out)
                    if done >= FRAMES // 3 and _busy_on(raylet_pid):
                        cluster.remove_node(worker)
                        removed["after"] = done
                        return
                    time.sleep(0.01)
                removed["error"] = "no frame ran on the worker node after a third of the batch"
            except Exception as exc:  # reported by the test below, not lost in the thread
                removed["error"] = repr(exc)

        watcher = threading.Thread(target=remove_when_busy, daemon=True)
        watcher.start()
        code = main(["batch", str(manifest), "--out", str(out), "--engine", "ray",
                     "--ray-address", cluster.address, "--workers", "2"])
        watcher.join(TIMEOUT)
    finally:
        if ray.is_initialized():
            ray.shutdown()
        cluster.shutdown()

    captured = capsys.readouterr()
    assert "error" not in removed, removed
    assert FRAMES // 3 <= removed["after"] < FRAMES, removed  # the node left mid-batch
    assert code == 0, captured
    doc = json.loads((out / "summary.json").read_text())
    names = [f["name"] for f in doc["frames"]]
    assert names == [f"f{i:02d}" for i in range(FRAMES)]  # every frame once, in input order
    assert doc["counts"] == {"ok": FRAMES, "failed": 0, "skipped": 0}
    # The frame that was running on the lost node ran again, and the run says so.
    retried = [n for n in doc["notes"] if "ran again after its Ray worker was lost" in n]
    assert retried, doc["notes"]
    assert all(f"note: {n}" in captured.out for n in retried)
    for name in names:
        np.testing.assert_array_equal(read_labels(out / name),
                                      read_labels(tmp_path / "local" / name))
    assert not [p for p in out.iterdir() if p.name.endswith((".partial", ".old"))]


@pytest.mark.parametrize("address, message", [
    ("head", "use auto, HOST:PORT"),
    ("10.0.0.5:6379:1", "use auto, HOST:PORT"),
    ("127.0.0.1:99999", "port 99999 is out of range"),
])
def test_bad_ray_address_fails_before_any_output(address: str, message: str, manifest: Path,
                                                 tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["batch", str(manifest), "--out", str(out), "--engine", "ray",
                 "--ray-address", address]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists()


def test_unreachable_ray_address_fails_in_seconds(manifest: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    ray = pytest.importorskip("ray")
    if ray.is_initialized():  # a session already joined would be used instead
        pytest.skip("Ray is initialised in this process")
    start = time.monotonic()
    code = main(["batch", str(manifest), "--out", str(tmp_path / "out"), "--engine", "ray",
                 "--ray-address", "127.0.0.1:1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "cannot reach Ray at 127.0.0.1:1" in err and err.count("\n") == 1
    assert time.monotonic() - start < 30  # Ray alone retries for minutes


def _fake_ray(monkeypatch: pytest.MonkeyPatch, get, wait, cpus: float = 2.0) -> None:
    """Replace Ray by a stand-in: a task's object ref is its frame spec."""
    import types

    rx = types.SimpleNamespace(
        RayError=Exception, WorkerCrashedError=_WorkerCrashed, NodeDiedError=OSError,
        LocalRayletDiedError=OSError, ObjectLostError=OSError, OutOfMemoryError=OSError)

    def remote(**_):
        return lambda fn: types.SimpleNamespace(remote=lambda job, spec: spec)

    fake = types.SimpleNamespace(
        is_initialized=lambda: True, cluster_resources=lambda: {"CPU": cpus}, remote=remote,
        put=lambda x: x, wait=wait, get=get, cancel=lambda ref, force: None, exceptions=rx)
    monkeypatch.setitem(sys.modules, "ray", fake)
    monkeypatch.setitem(sys.modules, "ray.exceptions", rx)


class _WorkerCrashed(Exception):
    pass


def _specs(*names: str) -> list:
    from monoplane.batch.specs import FrameSpec

    return [FrameSpec(name=n, depth="d.npy") for n in names]


def test_retries_are_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    """A frame whose worker dies on every attempt fails after RAY_ATTEMPTS; one that loses its
    worker once runs again and succeeds."""
    from monoplane.batch import engines
    from monoplane.batch.frame import BatchJob, FrameResult

    crashes = {"always": 99, "once": 1}

    def get(spec):
        if crashes.get(spec.name, 0):
            crashes[spec.name] -= 1
            raise _WorkerCrashed("the worker died")
        return FrameResult(spec.name, "ok", planes=1)

    _fake_ray(monkeypatch, get, lambda refs, num_returns, timeout: (refs[:1], refs[1:]))
    notes: list[str] = []
    results = {r.name: r for r in engines.run_ray(BatchJob({}, "out"),
                                                  _specs("always", "once", "fine"), 2,
                                                  notes=notes)}
    assert results["once"].status == results["fine"].status == "ok"
    assert results["always"].status == "failed"
    assert f"lost on all {engines.RAY_ATTEMPTS} attempts" in results["always"].error
    assert sum("always" in n for n in notes) == engines.RAY_ATTEMPTS - 1
    assert [n for n in notes if n.startswith("once")] == [
        f"once: ran again after its Ray worker was lost (_WorkerCrashed, attempt 1 of "
        f"{engines.RAY_ATTEMPTS})"]


def test_a_cluster_without_cpus_fails_the_rest(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every node with a CPU lost: after RAY_NO_CPU_SECONDS the frames fail, the batch ends."""
    from monoplane.batch import engines
    from monoplane.batch.frame import BatchJob

    monkeypatch.setattr(engines, "RAY_NO_CPU_SECONDS", 0.0)
    _fake_ray(monkeypatch, get=None, wait=lambda refs, num_returns, timeout: ([], refs),
              cpus=0.0)
    results = list(engines.run_ray(BatchJob({}, "out"), _specs("a", "b", "c"), 2))
    assert sorted(r.name for r in results) == ["a", "b", "c"]
    assert all(r.status == "failed" and "no CPU" in r.error for r in results)
