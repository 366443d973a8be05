"""What ``monoplane models`` prints comes from :mod:`monoplane.models.listing`: the table and
its rows, the fetch lines, and the profile a name stands for."""

from __future__ import annotations

from pathlib import Path

import pytest

from monoplane.errors import ConfigError, InvalidInput
from monoplane.models import CATALOGUE, FetchResult, model_path
from monoplane.models.listing import (
    cache_status,
    catalogue_rows,
    catalogue_table,
    fetch_summary,
    profile_named,
    unpinned_note,
)


@pytest.fixture(autouse=True)
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = tmp_path / "cache"
    monkeypatch.setenv("MONOPLANE_CACHE", str(root))
    return root


def test_a_wrong_size_copy_is_listed_as_broken_not_an_error(cache: Path) -> None:
    record = CATALOGUE["depth-anything-v2-small"]
    assert cache_status(record) == "-"
    model_path(record).parent.mkdir(parents=True)
    model_path(record).write_bytes(b"short")
    assert cache_status(record) == "broken"
    row = next(r for r in catalogue_rows() if r["name"] == record.name)
    assert row["cached"] is False and row["path"] == str(model_path(record))


def test_the_table_aligns_its_columns_and_marks_unpinned_revisions(cache: Path) -> None:
    lines = catalogue_table().splitlines()
    header, rows = lines[0], lines[1:1 + len(CATALOGUE)]
    assert header.split() == ["name", "task", "licence", "size", "profile", "cached", "source"]
    source_column = header.index("source")
    assert all(row[source_column - 2:source_column] == "  " for row in rows)
    moge = next(r for r in rows if r.startswith("moge-2-vits-normal "))
    assert "@main (unpinned):model.onnx" in moge and " 141 MB " in moge
    assert f"cache: {cache}" in lines


def test_fetch_lines_say_what_happened_and_whether_the_hash_is_pinned() -> None:
    full, prefix = CATALOGUE["depth-anything-v2-small"], CATALOGUE["metric3d-v2-small"]
    done = FetchResult(Path("/c/m.onnx"), "ab" * 32, downloaded=False)
    assert fetch_summary(full, done) == (
        f"depth-anything-v2-small: already cached, verified -> /c/m.onnx\n"
        f"sha256 {'ab' * 32} (matches the catalogue)")
    assert fetch_summary(prefix, done).endswith("(not fully pinned in the catalogue: pin it)")
    assert unpinned_note(full) is None
    assert "follows the branch 'main'" in unpinned_note(CATALOGUE["moge-2-vits-normal"])


def test_a_name_stands_for_a_builtin_a_catalogue_or_a_file_profile(tmp_path: Path) -> None:
    assert profile_named("omnidata").name == "omnidata"
    assert profile_named("depth-anything-v2-small").name == "depth-anything-v2"
    with pytest.raises(InvalidInput, match="xfeat is a features model"):
        profile_named("xfeat")
    with pytest.raises(ConfigError, match="unknown cue profile 'nothing'"):
        profile_named("nothing")
    with pytest.raises(ConfigError):
        profile_named(str(tmp_path / "missing.toml"))
