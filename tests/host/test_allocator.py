"""The allocator policy of a process that runs frame after frame (monoplane.host.allocator)."""

from __future__ import annotations

import resource
import sys

import numpy as np
import pytest

from monoplane.host.allocator import keep_freed_memory


def _frame() -> float:
    """Arrays of a few MiB allocated and freed as a frame's are: one freed before the next,
    larger one is allocated, so the default policy unmaps or trims what the next one needs."""
    a = np.ones(2**19)  # 4 MiB
    b = np.ones(2**18)  # 2 MiB
    del a
    c = np.ones(3 * 2**18)  # 6 MiB
    return float(b.sum() + c.sum())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc only")
def test_freed_blocks_are_reused_without_faulting_their_pages_in_again() -> None:
    if not keep_freed_memory():
        pytest.skip("not glibc")
    _frame()  # the heap grows to the frame's size once
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(10):
        _frame()
    # 10 frames touch 30 720 pages of 4 KiB; glibc's default policy faults about half of them
    # in again (15 090 in a fresh process), the kept blocks none.
    assert resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before < 300


def test_the_environment_turns_it_off(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MONOPLANE_KEEP_FREED_MEMORY", "0")
    assert keep_freed_memory() is False
