"""``monoplane bench``'s option text read by the library: worker counts, object ranges and a
saved run."""

from __future__ import annotations

from pathlib import Path

import pytest

from monoplane.batch import default_workers
from monoplane.errors import InvalidInput
from monoplane.evaluation.bench_options import (
    parse_object_ranges,
    parse_worker_counts,
    saved_bench_table,
)


def test_worker_counts_keep_their_order_and_default_to_one_and_all_cores() -> None:
    assert parse_worker_counts("2,1,4") == [2, 1, 4]
    assert parse_worker_counts(None) == list(dict.fromkeys([1, default_workers()]))
    for bad in ("", "0,2", "two"):
        with pytest.raises(InvalidInput, match="--workers must be comma-separated counts"):
            parse_worker_counts(bad)


def test_object_ranges_accept_single_counts_and_refuse_reversed_ones() -> None:
    assert parse_object_ranges("4, 1-2", False) == [(4, 4), (1, 2)]
    with pytest.raises(InvalidInput, match="got '5-2'"):
        parse_object_ranges("1-2,5-2", False)


def test_a_file_that_is_no_saved_run_is_named(tmp_path: Path) -> None:
    path = tmp_path / "other.json"
    path.write_text('{"rows": []}')
    with pytest.raises(InvalidInput, match=f"{path}: not a 'monoplane bench --json' file"):
        saved_bench_table(path)
    with pytest.raises(InvalidInput, match="missing.json: not a"):
        saved_bench_table(tmp_path / "missing.json")
