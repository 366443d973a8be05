"""The catalogue as ``monoplane models`` shows it: the table, its JSON rows, what a fetch did,
and the profile a name stands for."""

from __future__ import annotations

from typing import Any

from monoplane.cues.profile_files import get_profile, is_profile_file, load_profile_file
from monoplane.cues.profiles import OnnxProfile
from monoplane.errors import InvalidInput
from monoplane.models.cache import FetchResult, cache_dir, cached_model, model_path
from monoplane.models.catalogue import CATALOGUE, ModelRecord


def cache_status(record: ModelRecord) -> str:
    """``"cached"``, ``"-"`` (not downloaded) or ``"broken"`` (a wrong-size copy: the listing
    says so rather than failing)."""
    try:
        return "cached" if cached_model(record.name) is not None else "-"
    except InvalidInput:
        return "broken"


def _size(record: ModelRecord) -> str:
    return "?" if record.size is None else f"{record.size / 1e6:.0f} MB"


def _records() -> list[ModelRecord]:
    return [CATALOGUE[n] for n in sorted(CATALOGUE)]


def catalogue_rows() -> list[dict[str, Any]]:
    """Every record by name, JSON-ready (:meth:`ModelRecord.to_dict`), with ``cached`` (bool)
    and ``path`` (where the cache keeps it)."""
    return [{**r.to_dict(), "cached": cache_status(r) == "cached", "path": str(model_path(r))}
            for r in _records()]


def catalogue_table() -> str:
    """The catalogue as aligned columns (name, task, licence, size, profile, cache status,
    source at its revision), then the cache folder and each record's summary and licence."""
    records = _records()
    table = [("name", "task", "licence", "size", "profile", "cached", "source")]
    for r in records:
        rev = r.revision[:10] if r.pinned else f"{r.revision} (unpinned)"
        table.append((r.name, r.task, r.licence.split(" ")[0], _size(r), r.profile,
                      cache_status(r), f"{r.repo}@{rev}:{r.filename}"))
    widths = [max(len(row[i]) for row in table) for i in range(len(table[0]) - 1)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row[:-1], widths, strict=False)) + "  "
             + row[-1] for row in table]
    lines.append(f"\ncache: {cache_dir()}")
    lines += [f"  {r.name}: {r.summary}; licence {r.licence}" for r in records]
    return "\n".join(lines)


def unpinned_note(record: ModelRecord) -> str | None:
    """The note that a record follows a branch (no commit pinned), or None when pinned."""
    if record.pinned:
        return None
    return (f"{record.name} follows the branch {record.revision!r} (no commit hash pinned); "
            "the size and hash checks guard against a changed file")


def fetch_summary(record: ModelRecord, result: FetchResult) -> str:
    """Two lines: whether ``record`` was downloaded or already cached, where it is, and its
    SHA-256, said to match the catalogue or to need pinning there."""
    verb = "downloaded" if result.downloaded else "already cached"
    pinned = "matches the catalogue" if record.sha256 and len(record.sha256) == 64 else (
        "not fully pinned in the catalogue: pin it")
    return (f"{record.name}: {verb}, verified -> {result.path}\n"
            f"sha256 {result.sha256} ({pinned})")


def profile_named(name: str) -> OnnxProfile:
    """The profile ``name`` stands for: a profile file's (checked), a catalogue entry's, or a
    built-in one.

    Raises
    ------
    monoplane.errors.InvalidInput
        ``name`` is a features model, which has no profile.
    monoplane.errors.ConfigError
        An unknown name (listing the built-in profiles) or a bad profile file.
    """
    if is_profile_file(name):
        return load_profile_file(name).profile
    if name in CATALOGUE:
        record = CATALOGUE[name]
        if record.task == "features":
            raise InvalidInput(f"{name} is a features model (the '{record.profile}' features "
                               "stage runs it); only depth and normals models have a profile")
        return get_profile(record.profile)
    return get_profile(name)
