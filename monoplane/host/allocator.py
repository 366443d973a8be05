"""The C allocator's policy for a process that runs frame after frame.

Each frame allocates and frees tens of megabytes of arrays of about the same sizes (graph-cut
networks, label images, mean-field buffers, the cloud). By default glibc's ``malloc`` hands
large freed blocks back to the system: a block above its mmap threshold is unmapped when it is
freed, and the top of the heap is trimmed once more than its trim threshold lies free there.
The next frame's arrays then fault their pages in afresh: about 9 600 page faults and 20-30 ms
of system time a 640x480 frame under the ``range`` preset, an eighth of its CPU time
(docs/evaluation.md, "The `range` preset, eighth round").

:func:`keep_freed_memory` raises both thresholds, so freed blocks stay in the process and the
next frame reuses them (about 20 page faults a frame). The labels do not change; the price is
that the process keeps its peak memory until it exits instead of returning part of it between
frames. The command line calls it in its processes (the command's own, ``monoplane bench``'s
isolated child and the workers of ``batch``); a program that embeds monoplane may call it for
the same gain. ``MONOPLANE_KEEP_FREED_MEMORY=0`` in the environment turns it off.
"""

from __future__ import annotations

import ctypes
import os
import sys

#: Environment variable that turns :func:`keep_freed_memory` off when set to ``0``.
OPT_OUT = "MONOPLANE_KEEP_FREED_MEMORY"

#: ``mallopt`` parameters of glibc's ``malloc.h``.
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3

#: Blocks up to this size come from the heap, not from their own mapping: above every array
#: of a 640x480 frame (the largest, its (H, W, 3) float64 points and normals, are 7 MiB), and
#: the largest value glibc accepts on every 64-bit build.
MMAP_THRESHOLD = 32 * 2**20

#: Free memory at the top of the heap is given back to the system only above this.
TRIM_THRESHOLD = 64 * 2**20


def keep_freed_memory() -> bool:
    """Keep freed memory in the process for reuse (module docstring), under glibc.

    Returns
    -------
    bool
        True when glibc accepted both settings; False elsewhere (other C libraries, other
        systems) and with ``MONOPLANE_KEEP_FREED_MEMORY=0``, where nothing changes.
    """
    if not sys.platform.startswith("linux") or os.environ.get(OPT_OUT) == "0":
        return False
    try:
        libc = ctypes.CDLL(None)
        libc.gnu_get_libc_version  # noqa: B018  (only glibc has it)
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
