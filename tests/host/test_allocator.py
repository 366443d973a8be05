"""The allocator policy of a process that runs frame after frame (monoplane.host.allocator)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import monoplane
from monoplane.host import allocator
from monoplane.host.allocator import keep_freed_memory


def _frame() -> float:
    """Arrays of a few MiB allocated and freed as a frame's are: one freed before the next,
    larger one is allocated, so the default policy unmaps or trims what the next one needs."""
    a = np.ones(2**19)  # 4 MiB
    b = np.ones(2**18)  # 2 MiB
    del a
    c = np.ones(3 * 2**18)  # 6 MiB
    return float(b.sum() + c.sum())


#: Run in a child process: the policy would otherwise stay with the test process.
_CHILD = """
import resource
from monoplane.host.allocator import keep_freed_memory
from test_allocator import _frame
if not keep_freed_memory():
    print("not glibc")
else:
    _frame()  # the heap grows to the frame's size once
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(10):
        _frame()
    print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc only")
def test_freed_blocks_are_reused_without_faulting_their_pages_in_again() -> None:
    paths = [str(Path(monoplane.__file__).parents[1]), str(Path(__file__).parent)]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}
    env.pop("MONOPLANE_KEEP_FREED_MEMORY", None)
    out = subprocess.run([sys.executable, "-c", _CHILD], env=env, capture_output=True,
                         text=True, check=True).stdout.strip()
    if out == "not glibc":
        pytest.skip(out)
    # 10 frames touch 30 720 pages of 4 KiB; glibc's default policy faults about half of them
    # in again (15 090 in a fresh process), the kept blocks none.
    assert int(out) < 300


class _FakeLibc:
    """glibc as keep_freed_memory sees it, recording the mallopt calls instead of making them."""

    def __init__(self) -> None:
        self.calls: list[tuple[int, int]] = []
        self.gnu_get_libc_version = object()

        def mallopt(param: int, value: int) -> int:
            self.calls.append((param, value))
            return 1

        self.mallopt = mallopt


def test_both_thresholds_are_set_and_the_environment_turns_it_off(
        monkeypatch: pytest.MonkeyPatch) -> None:
    libc = _FakeLibc()
    monkeypatch.setattr(allocator.sys, "platform", "linux")
    monkeypatch.setattr(allocator.ctypes, "CDLL", lambda name: libc)
    monkeypatch.delenv(allocator.OPT_OUT, raising=False)
    assert keep_freed_memory() is True
    assert libc.calls == [(-3, allocator.MMAP_THRESHOLD), (-1, allocator.TRIM_THRESHOLD)]
    # Turned off, it does not reach the C library at all (not merely "not glibc").
    libc.calls.clear()
    monkeypatch.setenv(allocator.OPT_OUT, "0")
    assert keep_freed_memory() is False and libc.calls == []
