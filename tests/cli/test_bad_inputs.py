"""Damaged input files through the command line: one line naming the file and the fault, exit
status 2, nothing on stdout, no third-party output on either stream (captured at the file
descriptors, where Open3D, RPly and libpng would print), no numpy warning and no output folder.
A file that still holds usable points runs and says what it dropped.

The cases are the rows of the bad-input tables in docs/clouds.md and docs/batch.md; a test
checks that each message is there.
"""

from __future__ import annotations

import io
import json
import struct
import warnings
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import open3d as o3d
import pytest

from monoplane.cli import main
from monoplane.synth.batchset import write_frame_folder
from monoplane.testing import box_frame

DOCS = Path(__file__).parents[2] / "docs"


@dataclass(frozen=True)
class Case:
    """One damaged file: how to make it, and what the command says.

    ``make(folder)`` writes the damaged file into ``folder`` (which holds a good frame's
    files, for ``run`` cases) and returns the command's arguments before ``--out`` and the
    damaged file. ``message`` is the fault's part of the error line; when the file ``runs``,
    it is the note the command prints, or with ``printed=False`` what the docs say happens.
    """

    id: str
    make: Callable[[Path], tuple[list[str], Path]]
    message: str
    runs: bool = False
    printed: bool = True


def _box_points() -> np.ndarray:
    frame, _ = box_frame(64, 48)
    points = frame.points().reshape(-1, 3).astype(np.float64)
    return points[np.random.default_rng(0).permutation(len(points))]


POINTS = _box_points()


def _o3d(path: Path, points: np.ndarray = POINTS, **kwargs) -> Path:
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    assert o3d.io.write_point_cloud(str(path), pcd, **kwargs)
    return path


def _ply_header(n: int, fmt: str = "ascii") -> bytes:
    return (f"ply\nformat {fmt} 1.0\nelement vertex {n}\nproperty double x\n"
            "property double y\nproperty double z\nend_header\n").encode()


def _binary_ply(points: np.ndarray, declared: int | None = None) -> bytes:
    n = len(points) if declared is None else declared
    return _ply_header(n, "binary_little_endian") + points.astype("<f8").tobytes()


def _ascii_rows(points: np.ndarray) -> bytes:
    return "".join(f"{x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in points).encode()


def _pcd_ascii(rows: str, points: int, fields: str = "x y z") -> bytes:
    k = len(fields.split())
    return (f"# .PCD v0.7\nVERSION 0.7\nFIELDS {fields}\nSIZE {' '.join(['4'] * k)}\n"
            f"TYPE {' '.join(['F'] * k)}\nCOUNT {' '.join(['1'] * k)}\nWIDTH {points}\n"
            f"HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {points}\nDATA ascii\n{rows}").encode()


def _write(name: str, data: bytes | Callable[[Path], bytes]
           ) -> Callable[[Path], tuple[list[str], Path]]:
    """A cloud case: write ``data`` (or what it makes from a scratch folder) as ``name``."""
    def make(folder: Path) -> tuple[list[str], Path]:
        path = folder / name
        path.write_bytes(data(folder) if callable(data) else data)
        return ["cloud", str(path)], path
    return make


def _cut(name: str, fraction: float, **kwargs) -> Callable[[Path], bytes]:
    def make(folder: Path) -> bytes:
        data = _o3d(folder / f"whole_{name}", **kwargs).read_bytes()
        return data[:int(len(data) * fraction)]
    return make


def _flip_lzf(folder: Path) -> bytes:
    data = bytearray(_o3d(folder / "whole.pcd", compressed=True).read_bytes())
    start = data.index(b"DATA binary_compressed\n") + len("DATA binary_compressed\n") + 8
    data[start] = 0x20  # the first token: a back reference, to before the output's start
    return bytes(data)


def _with(points: np.ndarray, rows: slice, value: float) -> np.ndarray:
    out = points.copy()
    out[rows] = value
    return out


RANDOM = np.random.default_rng(7).integers(0, 256, 4096, dtype=np.uint8).tobytes()

CLOUD_CASES = [
    Case("ply-empty", _write("c.ply", b""), "the file is empty"),
    Case("ply-random-bytes", _write("c.ply", RANDOM), "not a PLY file"),
    Case("ply-lying-header-ascii",
         _write("c.ply", _ply_header(1000) + _ascii_rows(POINTS[:10])),
         "the header declares 1000 data lines (1000 vertices), the file holds 10"),
    Case("ply-lying-header-binary", _write("c.ply", _binary_ply(POINTS[:10], 1000)),
         "binary data cut short: the header declares 1000 vertices (24000 bytes), "
         "the file holds 240 bytes of them"),
    Case("ply-truncated-binary", _write("c.ply", _cut("c.ply", 1 / 3)),
         "binary data cut short"),
    Case("ply-trailing-bytes", _write("c.ply", _binary_ply(POINTS) + b"\0" * 24),
         "binary data longer than its header says"),
    Case("ply-bad-header-line",
         _write("c.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty double\n"
                         b"end_header\n"), "header line 4 is not valid PLY"),
    Case("ply-absurd-magnitude",
         _write("c.ply", _binary_ply(_with(POINTS, slice(5, 8), 1e300))),
         "3 point(s) have coordinates beyond ±3.4e+38"),
    Case("ply-nan-points", _write("c.ply", _binary_ply(_with(POINTS, slice(0, 40), np.nan))),
         "40 NaN/inf points left unlabelled", runs=True),
    Case("ply-all-nan", _write("c.ply", _binary_ply(_with(POINTS, slice(None), np.nan))),
         f"it holds 0 finite point(s) of {len(POINTS)}; a plane needs at least 3"),
    Case("pcd-random-bytes", _write("c.pcd", RANDOM), "not a PCD file: no 'DATA' line"),
    Case("pcd-wrong-field-count",
         _write("c.pcd", _pcd_ascii(_ascii_rows(POINTS[:20]).decode()
                                    + "1 2 3 4\n" + _ascii_rows(POINTS[21:30]).decode(), 30)),
         "line 32 has 4 values, the lines before it 3"),
    Case("pcd-lying-points",
         _write("c.pcd", _pcd_ascii(_ascii_rows(POINTS[:10]).decode(), 1000)),
         "POINTS declares 1000 points, the file holds 10 data lines"),
    Case("pcd-width-height",
         _write("c.pcd", _pcd_ascii(_ascii_rows(POINTS[:10]).decode(), 10).replace(
             b"WIDTH 10", b"WIDTH 7")), "WIDTH x HEIGHT = 7 x 1 = 7, but POINTS = 10"),
    Case("pcd-truncated-binary", _write("c.pcd", _cut("c.pcd", 0.5)), "binary data cut short"),
    Case("pcd-truncated-compressed", _write("c.pcd", _cut("c.pcd", 0.5, compressed=True)),
         "binary_compressed data cut short"),
    Case("pcd-corrupt-compressed", _write("c.pcd", _flip_lzf),
         "binary_compressed data are corrupt"),
    Case("xyz-random-bytes", _write("c.xyz", RANDOM), "the file is not text"),
    Case("xyz-not-numbers", _write("c.xyz", b"1 2 3\n4 5 6\n7 eight 9\n"),
         "line 3: 'eight' is not a number"),
    Case("xyz-absurd-magnitude", _write("c.xyz", _ascii_rows(POINTS[:99]) + b"1e300 0 0\n"),
         "1 point(s) have coordinates beyond ±3.4e+38"),
    Case("xyz-inf-points", _write("c.xyz", b"inf 0 0\n-inf 1 1\n" + _ascii_rows(POINTS)),
         "2 NaN/inf points left unlabelled", runs=True),
    Case("xyzrgb-colours-0-255",
         _write("c.xyzrgb", "".join(f"{x} {y} {z} 200 100 50\n" for x, y, z in POINTS)
                .encode()), "colours outside [0, 1] or not finite: colour term dropped",
         runs=True),
    Case("pts-empty", _write("c.pts", b"\n\n"), "the file is empty"),
    Case("pts-lying-count", _write("c.pts", b"1000\n" + _ascii_rows(POINTS[:10])),
         "line 1 declares 1000 points, the file holds 10 point lines"),
    Case("pts-no-count", _write("c.pts", _ascii_rows(POINTS[:10])),
         "line 1 must be the point count of a PTS file"),
    Case("xyz-one-point-repeated", _write("c.xyz", b"1 2 3\n" * 50),
         "the cloud has 1 distinct finite point(s); a plane needs at least 3"),
    # The remaining formats of each kind of damage (issue 27: every reader, every case).
    Case("pcd-empty", _write("c.pcd", b""), "the file is empty"),
    Case("xyz-empty", _write("c.xyz", b""), "the file is empty"),
    Case("pts-random-bytes", _write("c.pts", RANDOM), "the file is not text"),
    Case("pcd-absurd-magnitude",
         _write("c.pcd", _pcd_ascii(_ascii_rows(_with(POINTS[:100], slice(5, 7), 1e300))
                                    .decode(), 100)),
         "2 point(s) have coordinates beyond ±3.4e+38"),
    Case("pts-absurd-magnitude",
         _write("c.pts", b"100\n" + _ascii_rows(_with(POINTS[:100], slice(9, 10), 1e300))),
         "1 point(s) have coordinates beyond ±3.4e+38"),
    Case("pcd-nan-points",
         _write("c.pcd", _pcd_ascii(_ascii_rows(_with(POINTS, slice(0, 30), np.nan)).decode(),
                                    len(POINTS))),
         "30 NaN/inf points left unlabelled", runs=True),
    Case("pts-inf-points",
         _write("c.pts", f"{len(POINTS)}\n".encode()
                + _ascii_rows(_with(POINTS, slice(0, 3), np.inf))),
         "3 NaN/inf points left unlabelled", runs=True),
]


def _frame_file(name: str, flag: str, data: Callable[[Path], bytes],
                extra: tuple[str, ...] = ()) -> Callable[[Path], tuple[list[str], Path]]:
    """A ``run`` case: the good frame with its ``flag`` file replaced by ``data``."""
    def make(folder: Path) -> tuple[list[str], Path]:
        path = folder / name
        path.write_bytes(data(folder))
        files = {"--depth": folder / "depth.npy", "--normals": folder / "normals.npy",
                 "--intrinsics": folder / "intrinsics.json", flag: path}
        return ["run", str(folder / "rgb.png"), *(a for k, v in files.items()
                                                   for a in (k, str(v))), *extra], path
    return make


def _npy(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=True)
    return buf.getvalue()


def _depth(folder: Path) -> np.ndarray:
    return np.load(folder / "depth.npy")


def _png(array: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", array)
    assert ok
    return data.tobytes()


def _png_depth(folder: Path) -> bytes:
    return _png((_depth(folder) * 1000).astype(np.uint16))


def _flip_byte(data: bytes, at: int) -> bytes:
    return data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1:]


def _npz(folder: Path) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, depth=_depth(folder))
    return buf.getvalue()


def _lying_png(folder: Path) -> bytes:
    """A depth PNG whose IHDR (CRC recomputed) says twice the width its image data hold."""
    data = bytearray(_png_depth(folder))
    width = struct.unpack(">I", data[16:20])[0]
    data[16:20] = struct.pack(">I", 2 * width)
    data[29:33] = struct.pack(">I", zlib.crc32(bytes(data[12:29])))
    return bytes(data)


def _lying_npy(array: np.ndarray) -> bytes:
    """``array`` as ``.npy`` whose header declares half its rows."""
    data = _npy(array)
    old = repr(array.shape).encode()
    new = repr((array.shape[0] // 2, *array.shape[1:])).encode()
    return data.replace(old, new.ljust(len(old)), 1)


def _empty_or_random(prefix: str, name: str, flag: str, not_a: str,
                     empty: str = "the file is empty", extra: tuple[str, ...] = ()
                     ) -> list[Case]:
    """An empty file and one of random bytes as the frame's ``flag`` file (cases
    ``prefix-empty``, ``prefix-random-bytes``): what every reader is given; ``not_a`` is what
    random bytes are reported as."""
    return [Case(f"{prefix}-empty", _frame_file(name, flag, lambda f: b"", extra), empty),
            Case(f"{prefix}-random-bytes", _frame_file(name, flag, lambda f: RANDOM, extra),
                 not_a)]


def _npy_damage(cue: str, shape: tuple[int, ...], dtype: str) -> list[Case]:
    """The damage a depth or normals ``.npy`` file takes alike: empty, random bytes (see
    :func:`_empty_or_random`), truncated to 3000 bytes, a header declaring half the rows.
    ``shape`` and ``dtype`` are the good file's (``cue``.npy of the frame folder), which the
    messages state."""
    name, flag = f"{cue[0]}.npy", f"--{cue}"
    size = int(np.prod(shape)) * np.dtype(dtype).itemsize
    half = (shape[0] // 2, *shape[1:])

    def good(folder: Path) -> np.ndarray:
        return np.load(folder / f"{cue}.npy")

    return [
        *_empty_or_random(f"{cue}-npy", name, flag,
                          "not an .npy file (it does not start with numpy's magic string)"),
        Case(f"{cue}-npy-truncated", _frame_file(name, flag, lambda f: _npy(good(f))[:3000]),
             f"the file is truncated: its header declares {shape} {dtype} ({size} bytes), the "
             "file holds 2872"),
        Case(f"{cue}-npy-lying-header",
             _frame_file(name, flag, lambda f: _lying_npy(good(f))),
             f"the data do not match the header: its header declares {half} {dtype} "
             f"({size // 2} bytes), the file holds {size}"),
    ]


def _intrinsics(values: dict) -> Callable[[Path], bytes]:
    return lambda folder: json.dumps(values).encode()


FRAME_CASES = [
    *_npy_damage("depth", (48, 64), "float32"),
    Case("depth-npy-damaged-header",
         _frame_file("d.npy", "--depth", lambda f: _npy(_depth(f)).replace(b"'descr'",
                                                                             b"'d#scr'")),
         "damaged .npy header"),
    Case("depth-npy-pickled-objects",
         _frame_file("d.npy", "--depth", lambda f: _npy(np.array([{"a": 1}], dtype=object))),
         "must hold a real-valued numeric array, got object"),
    Case("depth-npz-archive", _frame_file("d.npy", "--depth", _npz),
         "it is an .npz archive, not an .npy array"),
    Case("depth-npy-nan",
         _frame_file("d.npy", "--depth", lambda f: _npy(_with(_depth(f), slice(0, 2), np.nan))),
         "128 pixels are NaN or inf; mark invalid pixels with 0 or pass --nan-as-invalid"),
    Case("depth-npy-absurd-magnitude",
         _frame_file("d.npy", "--depth",
                     lambda f: _npy(_with(_depth(f).astype(np.float64), slice(0, 1), 1e300))),
         "has values beyond 3.4e+38 (up to 1e+300)"),
    *_empty_or_random("depth-png", "d.png", "--depth", "not a PNG file (no PNG signature)",
                      extra=("--depth-scale", "1000")),
    Case("depth-png-truncated",
         _frame_file("d.png", "--depth", lambda f: _png_depth(f)[:-100],
                     ("--depth-scale", "1000")), "the file is truncated"),
    Case("depth-png-corrupt",
         _frame_file("d.png", "--depth", lambda f: _flip_byte(_png_depth(f), 60),
                     ("--depth-scale", "1000")), "fails its CRC check"),
    Case("depth-png-8-bit",
         _frame_file("d.png", "--depth", lambda f: _png(np.full((48, 64), 9, np.uint8)),
                     ("--depth-scale", "1000")), "must be single-channel 16-bit"),
    Case("depth-scale-tiny",
         _frame_file("d.png", "--depth", _png_depth, ("--depth-scale", "1e-300")),
         "has values beyond 3.4e+38 (with --depth-scale 1e-300)"),
    Case("normals-npy-nan",
         _frame_file("n.npy", "--normals",
                     lambda f: _npy(np.full((48, 64, 3), np.nan))), "contain NaN or inf"),
    Case("normals-npy-absurd-magnitude",
         _frame_file("n.npy", "--normals", lambda f: _npy(
             np.load(f / "normals.npy").astype(np.float64) * 1e300)),
         "normalised to unit length like any other normal", runs=True, printed=False),
    Case("normals-png-truncated",
         _frame_file("n.png", "--normals", lambda f: _png(np.full((48, 64, 3), 128,
                                                                  np.uint8))[:40]),
         "the file is truncated"),
    *_empty_or_random("intrinsics", "k.json", "--intrinsics", "is not valid JSON",
                      empty="is empty"),
    Case("intrinsics-missing-key",
         _frame_file("k.json", "--intrinsics", _intrinsics({"fx": 50, "cx": 32, "cy": 24})),
         "lacks fy"),
    Case("intrinsics-nan",
         _frame_file("k.json", "--intrinsics", lambda f: b'{"fx": NaN, "fy": 50, "cx": 32, '
                                                         b'"cy": 24}'),
         "focal lengths must be positive, 0.1 to 1e+08 pixels, got fx=nan"),
    Case("intrinsics-absurd-focal",
         _frame_file("k.json", "--intrinsics",
                     _intrinsics({"fx": 1e300, "fy": 1e300, "cx": 32, "cy": 24})),
         "focal lengths must be positive, 0.1 to 1e+08 pixels, got fx=1e+300"),
    Case("intrinsics-absurd-principal-point",
         _frame_file("k.json", "--intrinsics",
                     _intrinsics({"fx": 50, "fy": 50, "cx": 1e300, "cy": 24})),
         "the principal point must be within ±1e+08 pixels"),
    # The remaining readers of each kind of damage (issue 27: every reader, every case).
    Case("depth-png-lying-header", _frame_file("d.png", "--depth", _lying_png,
                                               ("--depth-scale", "1000")),
         "the file is corrupt: its image data inflate to 6192 bytes, 128x48 needs 12336"),
    *_npy_damage("normals", (48, 64, 3), "float16"),
    *_empty_or_random("normals-png", "n.png", "--normals", "not a PNG file (no PNG signature)"),
    Case("intrinsics-truncated",
         _frame_file("k.json", "--intrinsics", lambda f: b'{"fx": 50, "fy": 5'),
         "is not valid JSON: Expecting ',' delimiter"),
]


@pytest.fixture(scope="module")
def frame_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_frame_folder(tmp_path_factory.mktemp("frame"), n=1, width=64, height=48)[0]


def _check(case: Case, folder: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
           ) -> None:
    args, bad = case.make(folder)
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a numpy RuntimeWarning would become an internal error
        code = main([*args, "--out", str(out)])
    captured = capfd.readouterr()
    if case.runs:
        assert code == 0, captured.err
        assert case.message in captured.out or not case.printed, captured.out
        assert out.is_dir()
        return
    assert code == 2, captured
    assert captured.out == ""
    err = captured.err
    assert err.count("\n") == 1 and err.startswith("monoplane: error: "), err
    assert case.message in err and str(bad) in err, err
    assert not out.exists()


@pytest.mark.parametrize("case", CLOUD_CASES, ids=[c.id for c in CLOUD_CASES])
def test_cloud_file(case: Case, tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    _check(case, tmp_path, tmp_path, capfd)


@pytest.mark.parametrize("case", FRAME_CASES, ids=[c.id for c in FRAME_CASES])
def test_frame_file(case: Case, frame_folder: Path, tmp_path: Path,
                    capfd: pytest.CaptureFixture[str]) -> None:
    work = tmp_path / "frame"
    work.mkdir()
    for f in frame_folder.iterdir():
        (work / f.name).write_bytes(f.read_bytes())
    _check(case, work, tmp_path, capfd)


@pytest.mark.parametrize("doc, cases", [("clouds.md", CLOUD_CASES), ("batch.md", FRAME_CASES)])
def test_docs_list_every_case(doc: str, cases: list[Case]) -> None:
    text = (DOCS / doc).read_text()
    missing = [c.id for c in cases if f"`{c.id}`" not in text or c.message not in text]
    assert not missing, f"docs/{doc} lacks these bad-input cases or their messages: {missing}"


def test_lzf_case_really_is_compressed_pcd(tmp_path: Path) -> None:
    """The corrupt-compressed case flips bytes inside LZF data, not in the header."""
    data = _flip_lzf(tmp_path)
    start = data.index(b"DATA binary_compressed\n") + len("DATA binary_compressed\n")
    packed, unpacked = struct.unpack("<II", data[start:start + 8])
    assert unpacked == 12 * len(POINTS) and 50 < packed < len(data)
