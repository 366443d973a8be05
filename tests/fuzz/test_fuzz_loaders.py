"""Depth, normals and intrinsics loaders on arbitrary files: a valid result or one-line error,
with no numpy warning and nothing printed by numpy, OpenCV or libpng."""

from __future__ import annotations

import contextlib
import io
import json
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TypeVar

import cv2
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from monoplane.errors import InvalidInput
from monoplane.io.frames import read_depth, read_intrinsics, read_normals

_DTYPES = st.sampled_from(["float32", "float64", "float16", "int16", "uint16", "int64", "uint8",
                           "bool", "complex64", "U3", "O"])
_SHAPES = hnp.array_shapes(min_dims=0, max_dims=4, min_side=0, max_side=5)


def _one_line_error(exc: InvalidInput, path: Path | str) -> None:
    msg = str(exc)
    assert msg and "\n" not in msg and str(path) in msg, msg


@st.composite
def npy_bytes(draw: st.DrawFn) -> bytes:
    """An ``.npy`` file: a random array, possibly truncated or with a garbled header."""
    dtype = draw(_DTYPES)
    shape = draw(_SHAPES)
    if dtype == "O":
        arr = np.empty(shape, dtype=object)
    elif dtype == "U3":
        arr = np.full(shape, "ab")
    else:
        arr = draw(hnp.arrays(dtype, shape))
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=True)
    data = buf.getvalue()
    cut = draw(st.one_of(st.none(), st.integers(0, len(data))))
    if cut is not None:
        data = data[:cut]
    if draw(st.booleans()):
        pos = draw(st.integers(0, max(len(data) - 1, 0)))
        data = data[:pos] + draw(st.binary(max_size=8)) + data[pos + 1:]
    return data


@st.composite
def png_bytes(draw: st.DrawFn) -> bytes:
    """A PNG of random type and channel count, possibly truncated, or random bytes."""
    if draw(st.booleans()):
        return draw(st.binary(max_size=64))
    dtype = draw(st.sampled_from(["uint8", "uint16"]))
    channels = draw(st.sampled_from([1, 3, 4]))
    h, w = draw(st.integers(1, 6)), draw(st.integers(1, 6))
    shape = (h, w) if channels == 1 else (h, w, channels)
    arr = draw(hnp.arrays(dtype, shape))
    ok, enc = cv2.imencode(".png", arr)
    assert ok
    data = enc.tobytes()
    cut = draw(st.one_of(st.none(), st.integers(0, len(data))))
    return data if cut is None else data[:cut]


#: (suffix, content) of a depth or normals file.
_CUE_FILES = st.one_of(npy_bytes().map(lambda b: (".npy", b)),
                       png_bytes().map(lambda b: (".png", b)))


@contextlib.contextmanager
def _silent(capfd: pytest.CaptureFixture[str]) -> Iterator[None]:
    """No numpy warning inside, and nothing printed (by libpng, say) at the file descriptors."""
    capfd.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield
    assert capfd.readouterr() == ("", "")


T = TypeVar("T")


def _load(capfd: pytest.CaptureFixture[str], read: Callable[..., T], path: Path, *args: object,
          unnamed: str | None = None) -> T | None:
    """``read(path, *args)`` under :func:`_silent`: its result, or ``None`` once its
    :class:`InvalidInput` is checked to be one line naming ``path`` (a message holding
    ``unnamed`` is about an argument, not the file, and need not name it)."""
    try:
        with _silent(capfd):
            return read(path, *args)
    except InvalidInput as exc:
        _one_line_error(exc, "" if unnamed and unnamed in str(exc) else path)
        return None


def test_depth_loader(fuzz, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    @fuzz
    @given(_CUE_FILES,
           st.sampled_from([None, 1000.0, 0.0, -1.0, float("nan"), 1e-300]), st.booleans())
    def check(file: tuple[str, bytes], scale: float | None, nan_ok: bool) -> None:
        path = tmp_path / f"depth{file[0]}"
        path.write_bytes(file[1])
        depth = _load(capfd, read_depth, path, scale, nan_ok, unnamed="depth-scale")
        if depth is None:
            return
        assert depth.dtype == np.float32 and depth.ndim == 2
        assert np.all(np.isfinite(depth)) and np.all(depth >= 0) and np.any(depth > 0)

    check()


def test_normals_loader(fuzz, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    @fuzz
    @given(_CUE_FILES)
    def check(file: tuple[str, bytes]) -> None:
        path = tmp_path / f"normals{file[0]}"
        path.write_bytes(file[1])
        normals = _load(capfd, read_normals, path)
        if normals is None:
            return
        assert normals.dtype == np.float32 and normals.ndim == 3 and normals.shape[2] == 3
        norm = np.linalg.norm(normals, axis=-1)
        assert np.all((np.abs(norm - 1) < 1e-3) | (norm == 0))

    check()


_NUMBERISH = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-10, 10**6),
                       st.text(max_size=6), st.none(), st.booleans(), st.lists(st.integers(),
                                                                               max_size=2))


def _check_K(K: np.ndarray) -> None:
    assert K.shape == (3, 3) and np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0


def test_intrinsics_string(fuzz) -> None:
    @fuzz
    @given(st.one_of(st.text(max_size=40),
                     st.lists(_NUMBERISH.map(str), min_size=3, max_size=5).map(",".join)))
    def check(spec: str) -> None:
        if "\x00" in spec or spec.lower().endswith(".json") or Path(spec).exists():
            return  # would name a file; files are fuzzed below
        try:
            K = read_intrinsics(spec)
        except InvalidInput as exc:
            msg = str(exc)
            assert msg and "\n" not in msg
            return
        _check_K(K)

    check()


def test_intrinsics_json(fuzz, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    keys = st.sampled_from(["fx", "fy", "cx", "cy", "f", "width"])
    document = st.one_of(
        st.dictionaries(keys, _NUMBERISH, max_size=6).map(json.dumps),
        st.lists(_NUMBERISH, max_size=4).map(json.dumps),
        st.text(max_size=30),
    )

    @fuzz
    @given(document)
    def check(text: str) -> None:
        path = tmp_path / "intrinsics.json"
        path.write_text(text, errors="surrogatepass")
        K = _load(capfd, read_intrinsics, path)
        if K is not None:
            _check_K(K)

    check()
