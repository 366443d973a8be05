"""File checks that let the array readers fail with one line instead of a library's advice.

numpy and OpenCV decode what they are given and complain in their own words, or on the
terminal: ``np.load`` on random bytes suggests ``allow_pickle``, and libpng prints ``libpng
error: IDAT: incorrect data check`` on stderr, where no ``try`` can catch it, before OpenCV
returns ``None``. So a file is checked here first, and only a file that passes is decoded:

* :func:`load_npy`: the ``NUMPY`` magic, a header numpy can parse, a numeric dtype, and exactly
  as many data bytes as the header's shape and dtype need (a truncated file, or one whose header
  promises another shape, is refused before anything is allocated);
* :func:`read_png`: the PNG signature, every chunk whole with a matching CRC, a valid ``IHDR``,
  and image data that inflates to exactly the size ``IHDR`` declares, with a valid filter byte
  on every row. Only the critical chunks (``IHDR``, ``PLTE``, ``IDAT``, ``IEND``) are passed on
  to OpenCV, so an ancillary chunk (a colour profile, text) cannot make libpng warn either.

Every message names the file and says what is wrong with it.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import cv2
import numpy as np

from monoplane.errors import InvalidInput

#: Largest magnitude of a coordinate or depth value, in the file's own unit: float32's range.
#: Far beyond any real data, and the limit below which the pipeline's float32 arrays hold it.
MAX_MAGNITUDE = float(np.finfo(np.float32).max)

_NPY_MAGIC = b"\x93NUMPY"
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: Allowed bit depths of each PNG colour type (channels, depths).
_PNG_COLOR_TYPES = {0: (1, (1, 2, 4, 8, 16)), 2: (3, (8, 16)), 3: (1, (1, 2, 4, 8)),
                    4: (2, (8, 16)), 6: (4, (8, 16))}
#: Adam7 passes: first column, first row, column step, row step.
_ADAM7 = ((0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2),
          (0, 1, 1, 2))
#: Pixels a PNG may declare (16384 x 16384): above it, a lying header could make the decoder
#: allocate gigabytes before it finds the data missing.
_PNG_MAX_PIXELS = 1 << 28


def _first_line(exc: BaseException) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]


def load_npy(path: Path, what: str) -> np.ndarray:
    """Read a ``.npy`` file holding a real-valued numeric array, after checking it is whole.

    Parameters
    ----------
    path : Path
        The file.
    what : str
        What the file is (``"depth"``, ``"normals"``), for the messages.

    Returns
    -------
    numpy.ndarray
        The array, of an integer or floating dtype, any shape.

    Raises
    ------
    InvalidInput
        One line naming the file: empty, not a ``.npy`` file (an ``.npz`` archive is named as
        such), an unreadable header, a dtype that is not integer or floating (objects, strings,
        booleans, complex, records), or fewer or more data bytes than the header declares.
    """
    size = path.stat().st_size
    with open(path, "rb") as fh:
        start = fh.read(len(_NPY_MAGIC))
        if not start:
            raise InvalidInput(f"cannot read {what} {path}: the file is empty")
        if start.startswith(b"PK"):
            raise InvalidInput(f"cannot read {what} {path}: it is an .npz archive, not an .npy "
                               "array; save the array alone with numpy.save")
        if start != _NPY_MAGIC:
            raise InvalidInput(f"cannot read {what} {path}: not an .npy file (it does not start "
                               "with numpy's magic string)")
        fh.seek(0)
        try:
            version = np.lib.format.read_magic(fh)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
            elif version == (2, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
            else:
                raise ValueError(f"unsupported .npy format version {version[0]}.{version[1]}")
        except Exception as exc:  # a damaged header surfaces as ValueError, SyntaxError…
            raise InvalidInput(f"cannot read {what} {path}: damaged .npy header: "
                               f"{_first_line(exc)}") from None
        if dtype.hasobject or dtype.kind not in "iuf":
            raise InvalidInput(f"{what} {path} must hold a real-valued numeric array, "
                               f"got {dtype}")
        need = int(np.prod(shape, dtype=object)) * dtype.itemsize  # Python int: no overflow
        have = size - fh.tell()
        if have != need:
            declared = f"its header declares {shape} {dtype} ({need} bytes)"
            if have < need:
                raise InvalidInput(f"cannot read {what} {path}: the file is truncated: "
                                   f"{declared}, the file holds {have}")
            raise InvalidInput(f"cannot read {what} {path}: the data do not match the header: "
                               f"{declared}, the file holds {have}")
        fh.seek(0)
        return np.lib.format.read_array(fh, allow_pickle=False)


def _png_raw_size(width: int, height: int, channels: int, depth: int, interlace: int) -> list:
    """(row count, bytes per row including the filter byte) of each pass of the image data."""
    def rows(w: int, h: int) -> tuple[int, int]:
        return (h, 1 + (w * channels * depth + 7) // 8) if w and h else (0, 0)

    if not interlace:
        return [rows(width, height)]
    return [rows(max(0, (width - x0 + dx - 1) // dx), max(0, (height - y0 + dy - 1) // dy))
            for x0, y0, dx, dy in _ADAM7]


def read_png(path: Path, what: str) -> np.ndarray:
    """Decode a PNG with OpenCV (``IMREAD_UNCHANGED``) once its structure has been checked.

    Parameters
    ----------
    path, what : Path, str
        As for :func:`load_npy` (``what``: ``"depth PNG"``, ``"image"``).

    Returns
    -------
    numpy.ndarray
        (H, W) or (H, W, C) uint8 or uint16, channels in OpenCV's BGR(A) order.

    Raises
    ------
    InvalidInput
        One line naming the file and the fault: empty, not a PNG, a chunk cut short or with a
        wrong CRC, a missing or invalid ``IHDR``, an unknown critical chunk, no ``IEND``,
        image data that does not inflate or inflates to another size than ``IHDR`` declares,
        or a row with an invalid filter type.
    """
    def bad(problem: str) -> InvalidInput:
        return InvalidInput(f"cannot read {what} {path}: {problem}")

    data = path.read_bytes()
    if not data:
        raise bad("the file is empty")
    if not data.startswith(_PNG_SIGNATURE):
        raise bad("not a PNG file (no PNG signature)")
    pos = len(_PNG_SIGNATURE)
    header = None
    kept = [_PNG_SIGNATURE]
    idat = []
    while True:
        if pos + 8 > len(data):
            raise bad(f"the file is truncated: it ends at byte {len(data)} without an IEND "
                      "chunk")
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        name = kind.decode("latin-1")
        end = pos + 12 + length
        if end > len(data):
            raise bad(f"the file is truncated: chunk {name!r} at byte {pos} declares {length} "
                      "bytes, the file ends first")
        body = data[pos + 8:pos + 8 + length]
        (crc,) = struct.unpack(">I", data[end - 4:end])
        if zlib.crc32(kind + body) != crc:
            raise bad(f"the file is corrupt: chunk {name!r} at byte {pos} fails its CRC check")
        if header is None:
            if kind != b"IHDR" or length != 13:
                raise bad(f"the file is corrupt: its first chunk is {name!r}, not a 13-byte "
                          "IHDR")
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind[:1].isupper() and kind not in (b"PLTE", b"IEND"):
            raise bad(f"unknown critical chunk {name!r}")
        if kind in (b"IHDR", b"PLTE", b"IDAT", b"IEND"):
            kept.append(data[pos:end])
        pos = end
        if kind == b"IEND":
            break
    width, height, depth, color, compression, filtering, interlace = header
    channels, depths = _PNG_COLOR_TYPES.get(color, (0, ()))
    if (not width or not height or depth not in depths or compression or filtering
            or interlace > 1):
        raise bad(f"invalid IHDR: {width}x{height}, bit depth {depth}, colour type {color}, "
                  f"compression {compression}, filter {filtering}, interlace {interlace}")
    if width * height > _PNG_MAX_PIXELS:
        raise bad(f"its header declares {width}x{height} pixels, more than {_PNG_MAX_PIXELS}")
    if color == 3 and not any(c[4:8] == b"PLTE" for c in kept):
        raise bad("a palette PNG without a PLTE chunk")
    passes = _png_raw_size(width, height, channels, depth, interlace)
    need = sum(r * b for r, b in passes)
    inflate = zlib.decompressobj()
    try:
        raw = inflate.decompress(b"".join(idat), need + 1)  # +1: sees too much, bounded
    except zlib.error as exc:
        raise bad(f"the file is corrupt: its image data do not inflate ({exc})") from None
    if len(raw) != need or not inflate.eof:
        raise bad(f"the file is corrupt: its image data inflate to {len(raw)}"
                  f"{'' if inflate.eof else '+'} bytes, {width}x{height} needs {need}")
    offset = 0
    for count, row in passes:  # each row starts with its filter type byte
        filters = np.frombuffer(raw, np.uint8, count * row, offset)[::row]
        if np.any(filters > 4):
            raise bad(f"the file is corrupt: a row has filter type {int(filters.max())} "
                      "(0-4 exist)")
        offset += count * row
    image = cv2.imdecode(np.frombuffer(b"".join(kept), np.uint8), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise bad("OpenCV cannot decode it")
    return image
