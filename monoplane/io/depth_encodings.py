"""How RGB-D datasets store depth in 16-bit images, and how to turn it into metres.

Encodings (the names of ``--depth-encoding`` and of a manifest's ``depth_encoding`` column)
    * ``scaled``: depth times a constant; divided by ``depth_scale`` (1000 for millimetres).
      The only encoding of float ``.npy`` depth, and the default.
    * ``tum``: metres times 5000 (the TUM RGB-D benchmark), i.e. ``scaled`` with 5000.
    * ``sun-rotated``: millimetres whose 16 bits are rotated left by 3 (SUN RGB-D's PNGs);
      rotating right by 3, ``(d >> 3) | (d << 13)``, gives the millimetres back.
    * ``kinect-disparity``: the Kinect v1's raw 11-bit disparity ``d`` (0-2047, 2047 = no
      reading), metres = 351.3 / (1092.5 - d), the conversion of the NYU Depth v2 toolbox;
      ``d >= 1092.5`` has no positive depth and is invalid. NYU's raw ``.pgm`` files store
      the values little-endian although PGM is big-endian, so a reader sees them byte-swapped:
      when a raster's values exceed 11 bits but its byte-swapped values do not, it is read
      swapped (a disparity stored the right way round never exceeds 2047; one read swapped
      does, unless every low byte is 0-7).

Every decoder returns metres with 0 for invalid pixels (the convention of
:func:`monoplane.io.frames.read_depth`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from monoplane.errors import InvalidInput

#: Kinect v1 disparity to metres: z = A / (B - d) (NYU Depth v2 toolbox).
KINECT_DISPARITY_A = 351.3
KINECT_DISPARITY_B = 1092.5
#: The Kinect v1 reports disparity in 11 bits.
KINECT_DISPARITY_MAX = 2047


def _tum(raw: np.ndarray) -> np.ndarray:
    return raw / 5000.0


def _sun_rotated(raw: np.ndarray) -> np.ndarray:
    mm = (raw >> 3) | (raw << 13)  # uint16 arithmetic: the shifted-out bits wrap around
    return mm / 1000.0


def _kinect_disparity(raw: np.ndarray) -> np.ndarray:
    d = raw
    if d.max(initial=0) > KINECT_DISPARITY_MAX:
        swapped = d.byteswap()
        if swapped.max(initial=0) > KINECT_DISPARITY_MAX:
            raise ValueError(f"values up to {int(d.max())} are not 11-bit Kinect disparity "
                             f"(0-{KINECT_DISPARITY_MAX}), in either byte order")
        d = swapped
    gap = KINECT_DISPARITY_B - d.astype(np.float64)
    return np.where(gap > 0, KINECT_DISPARITY_A / np.where(gap > 0, gap, 1.0), 0.0)


#: Named encodings of 16-bit depth: name -> decoder from (H, W) uint16 to metres. ``scaled``
#: has no entry: it divides by the caller's ``depth_scale`` (see :func:`decode_depth`).
_DECODERS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "tum": _tum,
    "sun-rotated": _sun_rotated,
    "kinect-disparity": _kinect_disparity,
}
#: Every encoding name, the default first.
DEPTH_ENCODINGS: tuple[str, ...] = ("scaled", *_DECODERS)


def check_depth_encoding(encoding: str, depth_scale: float | None, where: str) -> None:
    """Raise one line naming ``where`` when ``encoding`` is unknown, or when a depth scale is
    given with an encoding that fixes its own units.

    Parameters
    ----------
    encoding : str
        One of :data:`DEPTH_ENCODINGS`.
    depth_scale : float or None
        The divisor asked for alongside (only ``scaled`` takes one).
    where : str
        What to name in the message, e.g. ``"--depth-encoding"`` or a manifest row.
    """
    if encoding not in DEPTH_ENCODINGS:
        raise InvalidInput(f"{where}: unknown depth encoding {encoding!r}; valid encodings: "
                           f"{', '.join(DEPTH_ENCODINGS)}")
    if encoding != "scaled" and depth_scale is not None:
        raise InvalidInput(f"{where}: a depth scale ({depth_scale:g}) applies to the "
                           f"'scaled' encoding only; '{encoding}' gives metres by itself")


def decode_depth(raw: np.ndarray, encoding: str, where: str) -> np.ndarray:
    """Metres from a 16-bit depth raster in a named encoding (not ``scaled``).

    Parameters
    ----------
    raw : numpy.ndarray
        (H, W) uint16, as stored in the file.
    encoding : str
        One of :data:`DEPTH_ENCODINGS` other than ``"scaled"`` (module docstring).
    where : str
        The file, for the message of a raster that is not in that encoding.

    Returns
    -------
    numpy.ndarray
        (H, W) float64 z-depth in metres; 0 = invalid.

    Raises
    ------
    InvalidInput
        An unknown encoding, a raster that is not uint16, or values the encoding cannot hold.
    """
    if encoding not in _DECODERS:
        raise InvalidInput(f"{where}: no decoder for depth encoding {encoding!r}; decoders: "
                           f"{', '.join(_DECODERS)} ('scaled' divides by a depth scale)")
    if raw.dtype != np.uint16:
        raise InvalidInput(f"{where}: depth encoding '{encoding}' reads 16-bit integers, "
                           f"got {raw.dtype}")
    try:
        return _DECODERS[encoding](raw)
    except ValueError as exc:
        raise InvalidInput(f"{where}: {exc}") from None
