"""What ``monoplane bench`` is asked for, read from its option text, and a saved run rendered
again: the scene-complexity ranges, the batch worker counts, and a ``--json`` file's table."""

from __future__ import annotations

import json
from pathlib import Path

from monoplane.batch.throughput import BatchBenchResult, format_batch_bench
from monoplane.errors import InvalidInput
from monoplane.evaluation.bench import COMPLEXITY_LEVELS, BenchResult, format_bench
from monoplane.host.pool import default_workers


def parse_worker_counts(text: str | None) -> list[int]:
    """``"1,2"`` as worker counts to compare, the first being the reference; None gives 1 and
    the number of cores (:func:`monoplane.host.pool.default_workers`)."""
    if text is None:
        return list(dict.fromkeys([1, default_workers()]))
    try:
        counts = [int(v) for v in text.split(",")]
    except ValueError:
        counts = []
    if not counts or min(counts) < 1:
        raise InvalidInput(f"--workers must be comma-separated counts of at least 1, e.g. 1,2; "
                           f"got {text!r}")
    return counts


def parse_object_ranges(text: str | None, complexity: bool) -> list[tuple[int, int]] | None:
    """``--objects`` (``"1-2,4-6,8-12"``; a single number is a range of one) or
    ``--complexity`` (:data:`~monoplane.evaluation.bench.COMPLEXITY_LEVELS`) as (min, max)
    objects per scene; None for the usual scenes."""
    if text is None:
        return list(COMPLEXITY_LEVELS) if complexity else None
    if complexity:
        raise InvalidInput("give either --complexity or --objects, not both")
    ranges = []
    for part in text.split(","):
        lo, _, hi = part.strip().partition("-")
        try:
            span = (int(lo), int(hi or lo))
        except ValueError:
            span = (-1, -1)
        if not 0 <= span[0] <= span[1]:
            raise InvalidInput(f"--objects takes ranges like 1-2,4-6,8-12 (min <= max, both "
                               f">= 0); got {part.strip()!r}")
        ranges.append(span)
    return ranges


def saved_bench_table(path: str | Path, markdown: bool = False) -> str:
    """The table of a saved ``monoplane bench --json`` run (frame bench or ``--batch``), as the
    run printed it.

    Raises
    ------
    monoplane.errors.InvalidInput
        Naming ``path`` when it cannot be read or is no such file.
    """
    try:
        data = json.loads(Path(path).read_text())
        if data.get("kind") == "batch":
            return format_batch_bench(BatchBenchResult.from_dict(data["result"]), markdown)
        return format_bench([BenchResult.from_dict(r) for r in data["results"]], markdown)
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise InvalidInput(f"{path}: not a 'monoplane bench --json' file ({exc})") from exc
