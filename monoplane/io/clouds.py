"""Point cloud files: PLY, PCD, XYZ (``.xyz``, ``.xyzn``, ``.xyzrgb``) and PTS, read and checked.

monoplane reads these itself instead of calling Open3D's ``read_point_cloud``. On a file that
is cut short, or whose header promises more points than it holds, Open3D (and the RPly
library inside it) prints warnings from C code, where they cannot be caught, and still
returns the points it managed to read, so a failed read cannot be told from a small cloud. Here
every file is checked against its own header before any point is used, and what is wrong is
one :class:`~monoplane.errors.InvalidInput` line that names the file.

Formats
-------
* **PLY** (``ascii``, ``binary_little_endian``, ``binary_big_endian``): the ``vertex``
  element's ``x y z``, and ``nx ny nz`` and ``red green blue`` when present (integer colours
  are divided by their type's maximum, float colours are taken as 0..1). Other elements (faces)
  are skipped; in a binary file only fixed-size elements may come before ``vertex``.
* **PCD** (``ascii``, ``binary``, ``binary_compressed``): fields ``x y z``, ``normal_x
  normal_y normal_z`` and a packed ``rgb`` or ``rgba``.
* **XYZ**: one point per line, ``x y z`` (``.xyzn``: ``x y z nx ny nz``; ``.xyzrgb``: ``x y z
  r g b`` with colours 0..1); further columns are ignored; lines starting with ``#`` are
  comments.
* **PTS**: a first line with the point count, then ``x y z``, ``x y z i``, ``x y z r g b`` or
  ``x y z i r g b`` per line (colours 0..255).

Refused, with the reason: an empty file; not the format its suffix says (no ``ply`` magic, no
PCD ``DATA`` line); a header that contradicts itself or the data (more or fewer points than
declared, rows with the wrong number of values, trailing data); binary data cut short; values
that are not numbers; no finite point at all, or fewer than 3; coordinates beyond
:data:`~monoplane.io.checks.MAX_MAGNITUDE`.

Kept: NaN and inf points (a scanner's "no return"), in input order. :func:`monoplane.detect_planes`
sets them aside, labels them 0 and says how many there were; it also drops non-finite or
out-of-range colours and normals with a note.
"""

from __future__ import annotations

import io
import re
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.io.checks import MAX_MAGNITUDE

#: File suffixes :func:`read_point_cloud` reads (lower case).
SUFFIXES = (".ply", ".pcd", ".xyz", ".xyzn", ".xyzrgb", ".pts")

#: A header must end within this many bytes; a file without a header end is not the format.
_HEADER_LIMIT = 1 << 16

_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2",
              "int16": "i2", "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4",
              "uint": "u4", "uint32": "u4", "float": "f4", "float32": "f4", "double": "f8",
              "float64": "f8"}
_PLY_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_PCD_TYPES = {("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8",
              ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8",
              ("F", 4): "f4", ("F", 8): "f8"}


@dataclass
class CloudFile:
    """The points of a cloud file, in file order.

    Attributes
    ----------
    points : numpy.ndarray
        (N, 3) float64, the file's frame and units; NaN/inf rows kept.
    normals : numpy.ndarray or None
        (N, 3) float64 as stored (not normalised), if the file has normals.
    colors : numpy.ndarray or None
        (N, 3) float64, 0..1 for well-formed files, if the file has colours.
    """

    points: np.ndarray
    normals: np.ndarray | None = None
    colors: np.ndarray | None = None

    def to_open3d(self) -> Any:  # -> open3d.geometry.PointCloud
        """The cloud as an Open3D legacy point cloud (what :func:`detect_planes` takes)."""
        import open3d as o3d

        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.points))
        if self.normals is not None:
            pcd.normals = o3d.utility.Vector3dVector(self.normals)
        if self.colors is not None:
            pcd.colors = o3d.utility.Vector3dVector(self.colors)
        return pcd


class _Bad(Exception):
    """A fault found while parsing; :func:`read_point_cloud` adds the file's name."""


def read_point_cloud(path: str | Path) -> CloudFile:
    """Read a point cloud file, checking it against its header.

    Parameters
    ----------
    path : str or Path
        ``.ply``, ``.pcd``, ``.xyz``, ``.xyzn``, ``.xyzrgb`` or ``.pts`` (see the module
        docstring).

    Returns
    -------
    CloudFile
        Points (and normals, colours) in file order.

    Raises
    ------
    InvalidInput
        One line, ``point cloud <path>: <what is wrong>``, for every fault the module docstring
        lists.
    """
    p = Path(path)
    if not p.is_file():
        raise InvalidInput(f"point cloud {p} not found")
    suffix = p.suffix.lower()
    if suffix not in SUFFIXES:
        raise InvalidInput(f"point cloud {p}: unsupported format '{p.suffix}'; use "
                           f"{', '.join(SUFFIXES)}")
    data = p.read_bytes()
    try:
        if not data.strip():
            raise _Bad("the file is empty")
        if suffix == ".ply":
            cloud = _read_ply(data)
        elif suffix == ".pcd":
            cloud = _read_pcd(data)
        elif suffix == ".pts":
            cloud = _read_pts(data)
        else:
            cloud = _read_xyz(data, suffix)
        _check_points(cloud.points)
    except _Bad as exc:
        raise InvalidInput(f"point cloud {p}: {exc}") from None
    return cloud


def _check_points(points: np.ndarray) -> None:
    if len(points) == 0:
        raise _Bad("it holds no point")
    finite = np.isfinite(points).all(axis=1)
    if finite.sum() < 3:
        raise _Bad(f"it holds {int(finite.sum())} finite point(s) of {len(points)}; a plane "
                   "needs at least 3")
    huge = finite & (np.abs(points) > MAX_MAGNITUDE).any(axis=1)
    if huge.any():
        first = int(np.argmax(huge))
        raise _Bad(f"{int(huge.sum())} point(s) have coordinates beyond ±{MAX_MAGNITUDE:.3g} "
                   f"(the first is point {first}: {points[first].tolist()})")


def _float64(values: np.ndarray) -> np.ndarray:
    """``values`` as float64. A damaged binary file can hold signalling NaNs, whose cast NumPy
    reports as an invalid operation; they become quiet NaNs here, and the non-finite points
    are counted and dropped later like any other."""
    with np.errstate(invalid="ignore"):
        return values.astype(np.float64)


def _text(data: bytes, what: str) -> str:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _Bad(f"{what} is not text: byte {exc.start} is 0x{data[exc.start]:02x}"
                   ) from None


def _rows(text: str, first_line: int, rows: int | None = None, skip: int = 0,
          comments: str | None = None) -> np.ndarray:
    """Numbers, one row per line, every row as wide as the first.

    Parameters
    ----------
    text : str
        The data lines.
    first_line : int
        Line number of ``text``'s first line in the file, for the messages.
    rows : int, optional
        Read at most this many rows.
    skip : int
        Lines to skip first.
    comments : str, optional
        Lines starting with it are skipped.

    Returns
    -------
    numpy.ndarray
        (R, C) float64; (0, 0) when there is no row.
    """
    if rows == 0:
        return np.zeros((0, 0))
    try:
        with warnings.catch_warnings():
            # No row at all is an answer here (the caller says "no point"), not a warning.
            warnings.filterwarnings("ignore", "loadtxt: input contained no data", UserWarning)
            arr = np.loadtxt(io.StringIO(text, newline=None), dtype=np.float64, ndmin=2,
                             comments=comments, skiprows=skip, max_rows=rows)
    except ValueError:
        _diagnose(text, first_line, skip, comments)
        raise _Bad(f"the data from line {first_line + skip} on are not rows of numbers"
                   ) from None
    return arr


def _diagnose(text: str, first_line: int, skip: int, comments: str | None) -> None:
    """Raise :class:`_Bad` naming the first line that is not a row like the first one."""
    width = None
    for number, line in enumerate(io.StringIO(text, newline=None), start=first_line):
        if number < first_line + skip:
            continue
        tokens = line.split()
        if not tokens or (comments and line.lstrip().startswith(comments)):
            continue
        for token in tokens:
            try:
                float(token)
            except ValueError:
                raise _Bad(f"line {number}: {token[:20]!r} is not a number") from None
        if width is None:
            width = len(tokens)
        elif len(tokens) != width:
            raise _Bad(f"line {number} has {len(tokens)} values, the lines before it "
                       f"{width}") from None


_NON_BLANK_LINE = re.compile(r"^[ \t\r\f\v]*[^\s]", re.MULTILINE)


def _count_rows(text: str) -> int:
    """Non-blank lines of ``text``."""
    return sum(1 for _ in _NON_BLANK_LINE.finditer(text))


def _colors(columns: list[np.ndarray], scale: float) -> np.ndarray:
    return _float64(np.stack(columns, axis=1)) / scale


# ---- PLY -----------------------------------------------------------------------------------


@dataclass
class _PlyElement:
    name: str
    count: int
    props: list[tuple[str, str | None]]  # (name, numpy code), None for a list property

    @property
    def fixed(self) -> bool:
        return all(code is not None for _, code in self.props)


def _ply_header(data: bytes) -> tuple[str, list[_PlyElement], int]:
    """Format, elements and the offset of the data of a PLY file."""
    if not data.startswith(b"ply"):
        raise _Bad("not a PLY file (it does not start with 'ply')")
    match = re.search(rb"(?m)^end_header[ \t]*\r?\n", data[:_HEADER_LIMIT])
    if match is None:
        raise _Bad(f"no 'end_header' line in its first {_HEADER_LIMIT} bytes")
    header = _text(data[:match.start()], "the PLY header")
    fmt = None
    elements: list[_PlyElement] = []
    for number, line in enumerate(header.splitlines()[1:], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) == 3 and words[1] in _PLY_FORMATS:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append(_PlyElement(words[1], int(words[2]), []))
        elif (words[0] == "property" and elements and len(words) == 3
              and words[1] in _PLY_TYPES):
            elements[-1].props.append((words[2], _PLY_TYPES[words[1]]))
        elif (words[0] == "property" and elements and len(words) == 5 and words[1] == "list"
              and words[2] in _PLY_TYPES and words[3] in _PLY_TYPES):
            elements[-1].props.append((words[4], None))
        else:
            raise _Bad(f"header line {number} is not valid PLY: {line.strip()[:60]!r}")
    if fmt is None:
        raise _Bad("the PLY header has no valid 'format' line")
    return fmt, elements, match.end()


def _read_ply(data: bytes) -> CloudFile:
    fmt, elements, start = _ply_header(data)
    index = next((k for k, e in enumerate(elements) if e.name == "vertex"), None)
    if index is None:
        raise _Bad("the PLY header declares no 'vertex' element")
    vertex = elements[index]
    names = [name for name, _ in vertex.props]
    if not {"x", "y", "z"} <= set(names):
        raise _Bad(f"the 'vertex' element has no x, y and z properties (it has "
                   f"{', '.join(names) or 'none'})")
    if len(set(names)) != len(names):
        raise _Bad("a property of the 'vertex' element appears twice")
    if not vertex.fixed:
        raise _Bad("the 'vertex' element has a list property; point clouds have none")
    n = vertex.count
    endian = _PLY_FORMATS[fmt]
    if endian is None:
        body = _text(data[start:], "the PLY data")
        declared = sum(e.count for e in elements)
        held = _count_rows(body)
        if held != declared:
            raise _Bad(f"the header declares {declared} data lines ({n} vertices), the file "
                       f"holds {held}")
        line0 = data[:start].count(b"\n") + 1
        skip = sum(e.count for e in elements[:index])
        arr = _rows(body, line0, rows=n, skip=skip)
        if arr.shape != (n, len(names)) and n:
            raise _Bad(f"vertex lines have {arr.shape[1]} values, the header declares "
                       f"{len(names)} properties")
        columns = {name: arr[:, k] if n else np.zeros(0) for k, name in enumerate(names)}
    else:
        before = elements[:index]
        if not all(e.fixed for e in before):
            raise _Bad("an element with list properties comes before 'vertex' in a binary "
                       "PLY, which monoplane does not read")
        offset = start + sum(e.count * _ply_dtype(e, endian).itemsize for e in before)
        dtype = _ply_dtype(vertex, endian)
        need = n * dtype.itemsize
        have = len(data) - offset
        if have < need:
            raise _Bad(f"binary data cut short: the header declares {n} vertices "
                       f"({need} bytes), the file holds {max(have, 0)} bytes of them")
        after = elements[index + 1:]
        if all(e.fixed for e in after):
            rest = sum(e.count * _ply_dtype(e, endian).itemsize for e in after)
            if have != need + rest:
                problem = "cut short" if have < need + rest else "longer than its header says"
                raise _Bad(f"binary data {problem}: its elements from 'vertex' on take "
                           f"{need + rest} bytes, the file holds {have}")
        table = np.frombuffer(data, dtype, n, offset)
        columns = {name: table[f"p{k}"] for k, name in enumerate(names)}
    points = _float64(np.stack([columns[c] for c in "xyz"], axis=1))
    normals = None
    if {"nx", "ny", "nz"} <= set(names):
        normals = _float64(np.stack([columns[c] for c in ("nx", "ny", "nz")], axis=1))
    colors = None
    rgb = ("red", "green", "blue")
    if set(rgb) <= set(names):
        code = str(dict(vertex.props)["red"])
        scale = 1.0 if code[0] == "f" else float(np.iinfo(code).max)
        colors = _colors([columns[c] for c in rgb], scale)
    return CloudFile(points, normals, colors)


def _ply_dtype(element: _PlyElement, endian: str) -> np.dtype:
    """Record type of a fixed-size element's rows; field ``p<i>`` is its i-th property."""
    return np.dtype([(f"p{i}", endian + str(code)) for i, (_, code) in enumerate(element.props)])


# ---- PCD -----------------------------------------------------------------------------------


def _read_pcd(data: bytes) -> CloudFile:
    match = re.search(rb"(?m)^DATA[ \t]+(\S+)[ \t]*\r?\n", data[:_HEADER_LIMIT])
    if match is None:
        raise _Bad(f"not a PCD file: no 'DATA' line in its first {_HEADER_LIMIT} bytes")
    header = _text(data[:match.start()], "the PCD header")
    mode = match.group(1).decode("latin-1")
    fields: dict[str, list[str]] = {}
    for number, line in enumerate(header.splitlines(), start=1):
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        key = words[0].upper()
        if key not in ("VERSION", "FIELDS", "SIZE", "TYPE", "COUNT", "WIDTH", "HEIGHT",
                       "VIEWPOINT", "POINTS"):
            raise _Bad(f"header line {number} is not valid PCD: {line.strip()[:60]!r}")
        fields[key] = words[1:]
    names = fields.get("FIELDS", [])
    sizes, types = fields.get("SIZE", []), fields.get("TYPE", [])
    counts = fields.get("COUNT", ["1"] * len(names))
    if not names or not (len(names) == len(sizes) == len(types) == len(counts)):
        raise _Bad(f"FIELDS, SIZE, TYPE and COUNT must list the same number of entries, got "
                   f"{len(names)}, {len(sizes)}, {len(types)} and {len(counts)}")
    try:
        codes = [_PCD_TYPES[(t.upper(), int(s))] for t, s in zip(types, sizes, strict=True)]
        counts_i = [int(c) for c in counts]
        width = int(_one(fields, "WIDTH"))
        height = int(fields.get("HEIGHT", ["1"])[0])
        n = int(fields["POINTS"][0]) if "POINTS" in fields else width * height
    except (KeyError, ValueError):
        raise _Bad("SIZE/TYPE pairs must be I or U with 1, 2, 4 or 8 bytes or F with 4 or 8, "
                   "and COUNT, WIDTH, HEIGHT and POINTS whole numbers") from None
    if min(counts_i) < 1 or min(width, height, n) < 0:
        raise _Bad("COUNT must be positive, WIDTH, HEIGHT and POINTS not negative")
    if width * height != n:
        raise _Bad(f"WIDTH x HEIGHT = {width} x {height} = {width * height}, but POINTS = {n}")
    for axis in "xyz":
        if axis not in names or counts_i[names.index(axis)] != 1:
            raise _Bad(f"the PCD FIELDS have no single '{axis}' (they are {' '.join(names)})")
    body = data[match.end():]
    columns: dict[str, np.ndarray] = {}
    if mode == "ascii":
        text = _text(body, "the PCD data")
        held = _count_rows(text)
        if held != n:
            raise _Bad(f"POINTS declares {n} points, the file holds {held} data lines")
        arr = _rows(text, header.count("\n") + 2, rows=n)
        if n and arr.shape[1] != sum(counts_i):
            raise _Bad(f"data lines have {arr.shape[1]} values, FIELDS and COUNT declare "
                       f"{sum(counts_i)}")
        k = 0
        for name, code, count in zip(names, codes, counts_i, strict=True):
            col = arr[:, k:k + count] if n else np.zeros((0, count))
            # A packed colour is written as the number whose bits hold it.
            columns.setdefault(name, col.astype(code) if name in ("rgb", "rgba") else col)
            k += count
    elif mode in ("binary", "binary_compressed"):
        dtypes = [np.dtype((f"<{c}", (count,))) for c, count in zip(codes, counts_i,
                                                                    strict=True)]
        row = sum(d.itemsize for d in dtypes)
        if mode == "binary":
            if len(body) != n * row:
                problem = "cut short" if len(body) < n * row else "longer than its header says"
                raise _Bad(f"binary data {problem}: POINTS {n} x {row} bytes = {n * row}, "
                           f"the file holds {len(body)}")
            table = np.frombuffer(body, np.dtype([(f"f{i}", d) for i, d in enumerate(dtypes)]),
                                  n)
            parts = [table[f"f{i}"] for i in range(len(dtypes))]
        else:
            raw = _pcd_decompress(body, n * row)
            parts, offset = [], 0
            for d in dtypes:  # binary_compressed stores each field for all points in turn
                parts.append(np.frombuffer(raw, d.base, n * d.shape[0], offset)
                             .reshape(n, d.shape[0]))
                offset += n * d.itemsize
        for name, part in zip(names, parts, strict=True):
            columns.setdefault(name, np.asarray(part).reshape(n, -1))
    else:
        raise _Bad(f"unknown PCD DATA kind {mode[:20]!r}; use ascii, binary or "
                   "binary_compressed")
    points = _float64(np.hstack([columns[a] for a in "xyz"]))
    normals = None
    if all(f"normal_{a}" in columns and columns[f"normal_{a}"].shape[1] == 1 for a in "xyz"):
        normals = _float64(np.hstack([columns[f"normal_{a}"] for a in "xyz"]))
    colors = None
    packed = columns.get("rgb", columns.get("rgba"))
    if packed is not None and packed.shape[1] == 1 and packed.dtype.itemsize == 4:
        bits = packed[:, 0].view(np.uint32)
        colors = _colors([(bits >> s) & 0xFF for s in (16, 8, 0)], 255.0)
    return CloudFile(points, normals, colors)


def _one(fields: dict[str, list[str]], key: str) -> str:
    values = fields.get(key, [])
    if len(values) != 1:
        raise ValueError(key)
    return values[0]


def _pcd_decompress(body: bytes, size: int) -> bytes:
    """The LZF-compressed data of a ``binary_compressed`` PCD, of ``size`` bytes unpacked."""
    if len(body) < 8:
        raise _Bad("binary_compressed data cut short: no sizes")
    packed, unpacked = struct.unpack("<II", body[:8])
    if unpacked != size:
        raise _Bad(f"binary_compressed data unpack to {unpacked} bytes, POINTS and the fields "
                   f"need {size}")
    if len(body) - 8 < packed:
        raise _Bad(f"binary_compressed data cut short: {packed} compressed bytes declared, "
                   f"{len(body) - 8} held")
    raw = _lzf_decompress(body[8:8 + packed], size)
    if raw is None:
        raise _Bad("binary_compressed data are corrupt (they do not unpack to the declared "
                   "size)")
    return raw


def _lzf_decompress(src: bytes, size: int) -> bytes | None:
    """LZF (liblzf's format, as PCL writes it) into exactly ``size`` bytes, or None.

    Each control byte is a literal run (``c < 32``: the next ``c + 1`` bytes) or a back
    reference (length ``c >> 5``, extended by the next byte when 7, plus 2; distance from the
    low 5 bits and the next byte, plus 1). Every run and reference is bounds-checked.
    """
    out = bytearray(size)
    i = o = 0
    end = len(src)
    while i < end:
        ctrl = src[i]
        i += 1
        if ctrl < 32:
            run = ctrl + 1
            if i + run > end or o + run > size:
                return None
            out[o:o + run] = src[i:i + run]
            i += run
            o += run
            continue
        length = ctrl >> 5
        if length == 7:
            if i >= end:
                return None
            length += src[i]
            i += 1
        length += 2
        if i >= end:
            return None
        ref = o - ((ctrl & 0x1F) << 8) - src[i] - 1
        i += 1
        if ref < 0 or o + length > size:
            return None
        period = o - ref  # a reference may overlap what it writes: repeat its period
        chunk = out[ref:o] if period < length else out[ref:ref + length]
        out[o:o + length] = (chunk * (length // len(chunk) + 1))[:length]
        o += length
    return bytes(out) if o == size else None


# ---- XYZ, PTS ------------------------------------------------------------------------------


def _read_xyz(data: bytes, suffix: str) -> CloudFile:
    need = 3 if suffix == ".xyz" else 6
    arr = _rows(_text(data, "the file"), 1, comments="#")
    if arr.size and arr.shape[1] < need:
        raise _Bad(f"lines have {arr.shape[1]} values; {suffix} needs {need} "
                   f"({'x y z' if need == 3 else 'x y z ' + suffix[4:]})")
    if not arr.size:
        return CloudFile(np.zeros((0, 3)))
    extra = arr[:, 3:6] if need == 6 else None
    return CloudFile(arr[:, :3].copy(), extra if suffix == ".xyzn" else None,
                     extra if suffix == ".xyzrgb" else None)


def _read_pts(data: bytes) -> CloudFile:
    text = _text(data, "the file")
    lines = io.StringIO(text, newline=None)
    first, number = lines.readline(), 1
    while not first.strip():  # the file is not blank: read_point_cloud checked
        first, number = lines.readline(), number + 1
    try:
        n = int(first)
    except ValueError:
        raise _Bad(f"line {number} must be the point count of a PTS file, got "
                   f"{first.strip()[:20]!r}") from None
    rest = lines.read()
    held = _count_rows(rest)
    if held != n:
        raise _Bad(f"line {number} declares {n} points, the file holds {held} point lines")
    arr = _rows(rest, number + 1)
    if not arr.size:
        return CloudFile(np.zeros((0, 3)))
    if arr.shape[1] not in (3, 4, 6, 7):
        raise _Bad(f"point lines have {arr.shape[1]} values; PTS lines have 3 (x y z), 4 (and "
                   "intensity), 6 (and r g b) or 7")
    colors = arr[:, -3:] / 255.0 if arr.shape[1] >= 6 else None
    return CloudFile(arr[:, :3].copy(), None, colors)
