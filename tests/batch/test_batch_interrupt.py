"""A batch killed with SIGKILL resumes without half-written frames; Ctrl-C stops it cleanly.

Each test runs ``monoplane batch`` in its own process group, waits until the first frame
folder appears (so the kill lands mid-batch), then signals the whole group the way a terminal
(Ctrl-C) or an OOM killer would.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from batch_helpers import BROKEN, GOOD, read_labels

from monoplane.batch import run_batch
from monoplane.batch.frame import is_complete
from monoplane.host.registry import AUTOLOAD_ENV

TIMEOUT = 60.0


def start_batch(frames: Path, out: Path) -> subprocess.Popen:
    env = {**os.environ, AUTOLOAD_ENV: "1",
           "PYTHONPATH": os.pathsep.join([str(Path(__file__).parents[2]),
                                          os.environ.get("PYTHONPATH", "")])}
    return subprocess.Popen(
        [sys.executable, "-m", "monoplane.cli", "batch", str(frames), "--out", str(out),
         "--workers", "1"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)


def wait_for_first_frame(proc: subprocess.Popen, out: Path) -> None:
    deadline = time.monotonic() + TIMEOUT
    while time.monotonic() < deadline:
        if out.is_dir() and any(not p.name.startswith(".") and p.is_dir()
                                for p in out.iterdir()):
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.05)
    raise AssertionError("no frame finished in time")


def worker_pids(pid: int) -> list[int]:
    """Pool workers among a process's children (not multiprocessing's resource tracker)."""
    path = Path(f"/proc/{pid}/task/{pid}/children")
    kids = [int(c) for c in path.read_text().split()] if path.exists() else []
    out = []
    for kid in kids:
        try:
            cmdline = Path(f"/proc/{kid}/cmdline").read_bytes()
        except FileNotFoundError:
            continue
        if b"resource_tracker" not in cmdline:  # forked workers share the driver's cmdline
            out.append(kid)
    return out


def alive(pid: int) -> bool:
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
    return "State:\tZ" not in status


def test_resume_after_sigkill(frames_dir, reference_labels, tmp_path):
    out = tmp_path / "out"
    proc = start_batch(frames_dir, out)
    wait_for_first_frame(proc, out)
    os.killpg(proc.pid, signal.SIGKILL)  # the driver and its worker, with no warning
    proc.wait(timeout=TIMEOUT)
    proc.communicate()
    frames = [p for p in out.iterdir() if not p.name.startswith(".")]
    assert frames and all(is_complete(p) for p in frames if p.is_dir())
    done_before = {p.name for p in frames if p.is_dir()}
    assert done_before < set(GOOD)  # the kill landed mid-batch
    # What a kill during the final rename leaves behind; the next run must delete it.
    (out / f".{GOOD[-1]}.x1y2z3.partial").mkdir(exist_ok=True)
    (out / f".{GOOD[-1]}.x1y2z3.partial" / "labels.png").write_bytes(b"half")

    summary = run_batch(frames_dir, out, workers=2, progress=False)
    status = {f.name: f.status for f in summary.frames}
    assert status[BROKEN] == "failed"
    for name in GOOD:
        assert status[name] == ("skipped" if name in done_before else "ok")
        np.testing.assert_array_equal(read_labels(out / name), reference_labels[name])
    assert not [p for p in out.iterdir() if p.name.endswith((".partial", ".old"))]


def test_ctrl_c_stops_workers_cleanly(frames_dir, tmp_path):
    out = tmp_path / "out"
    proc = start_batch(frames_dir, out)
    wait_for_first_frame(proc, out)
    workers = worker_pids(proc.pid)
    assert workers, "the local engine runs frames in worker processes"
    os.killpg(proc.pid, signal.SIGINT)  # what a terminal sends on Ctrl-C
    _, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 130, err
    assert err.decode().strip().splitlines()[-1] == "monoplane: interrupted"
    assert not [pid for pid in workers if alive(pid)]
    assert not [p for p in out.iterdir() if p.name.endswith((".partial", ".old"))]
    doc = json.loads((out / "summary.json").read_text())
    assert doc["interrupted"] is True
    assert all(f["status"] in ("ok", "failed") for f in doc["frames"])
    assert all(is_complete(out / f["name"]) for f in doc["frames"] if f["status"] == "ok")
