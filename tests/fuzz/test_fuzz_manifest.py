"""The batch manifest parser on arbitrary ``.jsonl`` and ``.csv`` input: a valid list of frame
specs, or one :class:`InvalidInput` line naming the manifest, never another exception."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from monoplane.batch.specs import read_frames
from monoplane.errors import InvalidInput

COLUMNS = ["name", "image", "depth", "normals", "intrinsics", "depth_scale", "extra", ""]
#: Files that exist beside the manifest, so that some rows are valid.
FILES = ["rgb.png", "depth.npy", "normals.npy", "K.json", "missing.png", "../rgb.png", "/abs"]

_VALUES = st.one_of(st.sampled_from(FILES), st.text(max_size=10), st.integers(-3, 5000),
                    st.floats(allow_nan=True), st.none(), st.booleans())
_ROWS = st.lists(st.dictionaries(st.sampled_from(COLUMNS), _VALUES, max_size=6), max_size=4)


def _write_files(folder: Path) -> None:
    (folder / "rgb.png").write_bytes(b"\x89PNG not really")
    np.save(folder / "depth.npy", np.ones((4, 4), np.float32))
    np.save(folder / "normals.npy", np.zeros((4, 4, 3), np.float32))
    (folder / "K.json").write_text('{"fx": 1, "fy": 1, "cx": 1, "cy": 1}')


def _check(path: Path) -> None:
    try:
        specs = read_frames(path)
    except InvalidInput as exc:
        msg = str(exc)
        assert msg and "\n" not in msg and path.name in msg, msg
        return
    names = [s.name for s in specs]
    assert len(names) == len(set(names))
    for spec in specs:
        assert spec.image is not None or spec.depth is not None


def test_jsonl_manifest(tmp_path_factory, fuzz) -> None:
    folder = tmp_path_factory.mktemp("jsonl")
    _write_files(folder)

    @fuzz
    @given(_ROWS, st.booleans())
    def check(rows: list[dict], garbage_line: bool) -> None:
        lines = [json.dumps(r) for r in rows] + (["{not json"] if garbage_line else [])
        path = folder / "frames.jsonl"
        path.write_text("\n".join(lines) + "\n")
        _check(path)

    check()


def test_csv_manifest(tmp_path_factory, fuzz) -> None:
    folder = tmp_path_factory.mktemp("csv")
    _write_files(folder)

    @fuzz
    @given(st.lists(st.sampled_from(COLUMNS), min_size=1, max_size=6, unique=True),
           st.lists(st.lists(_VALUES.map(lambda v: "" if v is None else str(v)), max_size=7),
                    max_size=4))
    def check(header: list[str], rows: list[list[str]]) -> None:
        text = "\n".join(",".join(cells) for cells in [header, *rows]) + "\n"
        path = folder / "frames.csv"
        path.write_text(text)
        _check(path)

    check()


def test_binary_garbage(tmp_path_factory, fuzz) -> None:
    folder = tmp_path_factory.mktemp("bin")

    @fuzz
    @given(st.binary(max_size=200), st.sampled_from([".jsonl", ".csv"]))
    def check(data: bytes, suffix: str) -> None:
        path = folder / f"frames{suffix}"
        path.write_bytes(data)
        _check(path)

    check()
