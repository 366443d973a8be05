"""Reading inputs (the on-disk contract of the command line and API).

Inputs
------
* Image: anything OpenCV reads (8- or 16-bit, grey or colour; alpha is dropped).
* Depth: ``.npy`` float in any unit, or a 16-bit PNG divided by ``depth_scale`` (1000 for mm,
  5000 for TUM). 0 marks invalid pixels; NaN/inf are rejected unless ``nan_as_invalid``.
  16-bit depth in a dataset's own encoding (TUM, SUN RGB-D's rotated bits, NYU's raw Kinect
  disparity ``.pgm``) is read with ``depth_encoding`` (:mod:`monoplane.io.depth_encodings`).
* Normals: ``.npy`` (H, W, 3) camera frame, or an 8-bit PNG storing ``(n + 1) / 2 * 255`` with
  R, G, B = x, y, z.
* Intrinsics: ``"fx,fy,cx,cy"`` or a JSON file ``{"fx":…, "fy":…, "cx":…, "cy":…}``.

Outputs are written by :func:`monoplane.export.save` (one module per format in
:mod:`monoplane.export`). The writers that lived here (:func:`save_reconstruction`,
:func:`write_reconstruction_files`, ``planes_document``, ``atomic_output_dir``,
``check_output_dir``, ``write_*_ply``) still work until 0.3.0, with a ``DeprecationWarning``
naming their replacement.
"""

from __future__ import annotations

import importlib
import json
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from monoplane.cues.intrinsics import assume_intrinsics
from monoplane.datamodel import Frame, Reconstruction, intrinsics_matrix
from monoplane.errors import InvalidInput
from monoplane.export.saving import save, select_exporters, write_outputs
from monoplane.io.checks import MAX_MAGNITUDE, load_npy, read_png
from monoplane.io.depth_encodings import check_depth_encoding, decode_depth

#: Accepted pinhole intrinsics, in pixels. A focal length below 0.1 px is a field of view of
#: nearly 180 degrees on any image; no sensor is near 1e8 px wide. Beyond these bounds a value
#: is a damaged file or a unit mistake, and ray directions would over- or underflow.
FOCAL_RANGE_PX = (0.1, 1e8)
MAX_PRINCIPAL_POINT_PX = 1e8


def _require_file(path: str | Path, what: str) -> Path:
    p = Path(path)
    if not p.exists():
        raise InvalidInput(f"{what} file not found: {p}")
    if not p.is_file():
        raise InvalidInput(f"{what} path is not a file: {p}")
    return p


def read_image(path: str | Path) -> np.ndarray:
    """Read an image as RGB.

    Returns
    -------
    numpy.ndarray
        (H, W, 3) uint8 RGB. 16-bit images are scaled to 8 bits; grey images are replicated.
    """
    p = _require_file(path, "image")
    img = _read_raster(p, "image")
    if img is None or img.size == 0:
        raise InvalidInput(f"cannot read image {p}: not an image format OpenCV understands")
    if img.dtype == np.uint16:
        img = (img / 257.0).round().astype(np.uint8)
    elif img.dtype != np.uint8:
        raise InvalidInput(f"image {p} has unsupported pixel type {img.dtype}")
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    else:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return np.ascontiguousarray(img)


def _read_raster(p: Path, what: str) -> np.ndarray | None:
    """A PNG checked before decoding (:func:`monoplane.io.checks.read_png`), any other format
    through OpenCV as it is; None when OpenCV cannot read it."""
    if p.suffix.lower() == ".png":
        return read_png(p, what)
    return cv2.imread(str(p), cv2.IMREAD_UNCHANGED)


def read_depth(path: str | Path, depth_scale: float | None = None,
               nan_as_invalid: bool = False, depth_encoding: str = "scaled") -> np.ndarray:
    """Read a depth map.

    Parameters
    ----------
    path : str or Path
        ``.npy`` (float, any unit) or a 16-bit image (``.png``, or any format OpenCV reads as
        16-bit single-channel, e.g. ``.pgm``).
    depth_scale : float, optional
        Divisor for 16-bit values (1000 for millimetres, 5000 for TUM) in the ``scaled``
        encoding. Required for 16-bit images there, ignored for ``.npy`` unless given (then
        the array is divided by it too).
    nan_as_invalid : bool
        Treat NaN/inf as invalid pixels (0) instead of rejecting the file.
    depth_encoding : str
        How the 16-bit values hold depth: ``"scaled"`` (divided by ``depth_scale``), or a
        dataset's own encoding giving metres (``"tum"``, ``"sun-rotated"``,
        ``"kinect-disparity"``; :mod:`monoplane.io.depth_encodings`), which then needs a
        16-bit image or a uint16 ``.npy`` and no ``depth_scale``.

    Returns
    -------
    numpy.ndarray
        (H, W) float32 z-depth; 0 = invalid.
    """
    check_depth_encoding(depth_encoding, depth_scale, "--depth-encoding")
    p = _require_file(path, "depth")
    if p.suffix.lower() == ".npy":
        depth = load_npy(p, "depth")
        if depth_encoding != "scaled":
            depth = decode_depth(depth, depth_encoding, f"depth {p}")
        depth = depth.astype(np.float64)
    else:
        raw = _read_raster(p, "depth PNG")
        if raw is None:
            raise InvalidInput(f"cannot read depth {p}: use .npy or a 16-bit PNG")
        if raw.dtype != np.uint16 or raw.ndim != 2:
            raise InvalidInput(f"depth image {p} must be single-channel 16-bit, "
                               f"got {raw.dtype} with shape {raw.shape}")
        if depth_encoding != "scaled":
            depth = decode_depth(raw, depth_encoding, f"depth {p}")
        elif depth_scale is None:
            raise InvalidInput(f"depth image {p} needs --depth-scale (1000 for mm) or "
                               "--depth-encoding (e.g. tum)")
        else:
            depth = raw.astype(np.float64)
    if depth_scale is not None and not 0 < depth_scale < np.inf:
        raise InvalidInput(f"--depth-scale must be a positive finite number, got {depth_scale}")
    if depth.ndim == 3 and depth.shape[2] == 1:
        depth = depth[..., 0]
    if depth.ndim != 2:
        raise InvalidInput(f"depth {p} must have shape (H, W), got {depth.shape}")
    bad = ~np.isfinite(depth)
    if bad.any():
        if not nan_as_invalid:
            raise InvalidInput(f"depth {p}: {int(bad.sum())} pixels are NaN or inf; mark invalid "
                               "pixels with 0 or pass --nan-as-invalid")
        depth[bad] = 0.0
    if np.any(depth < 0):
        raise InvalidInput(f"depth {p} has negative values")
    # Checked before dividing by the scale, so that the division itself cannot overflow.
    largest = float(depth.max(initial=0.0))
    if largest > MAX_MAGNITUDE * (depth_scale or 1.0):
        scaled = f" (with --depth-scale {depth_scale:g})" if depth_scale is not None else ""
        raise InvalidInput(f"depth {p} has values beyond {MAX_MAGNITUDE:.3g}{scaled} (up to "
                           f"{largest:.3g}); store it in a larger unit (e.g. metres)")
    if depth_scale is not None:
        depth = depth / depth_scale
    depth = depth.astype(np.float32)  # values below float32's range become 0 (invalid)
    if np.any(depth > 0):
        return depth
    raise InvalidInput(f"depth {p} has no valid pixel (all zero, NaN or inf)")


def read_normals(path: str | Path) -> np.ndarray:
    """Read a normal map (camera frame, OpenCV axes).

    Returns
    -------
    numpy.ndarray
        (H, W, 3) float32 unit normals; all-zero where the input was zero-length.
    """
    p = _require_file(path, "normals")
    if p.suffix.lower() == ".npy":
        n = load_npy(p, "normals").astype(np.float64)
        if n.ndim != 3 or n.shape[2] != 3:
            raise InvalidInput(f"normals {p} must have shape (H, W, 3), got {n.shape}")
        if not np.all(np.isfinite(n)):
            raise InvalidInput(f"normals {p} contain NaN or inf")
    else:
        raw = _read_raster(p, "normals PNG")
        if raw is None or raw.ndim != 3 or raw.shape[2] < 3 or raw.dtype != np.uint8:
            raise InvalidInput(f"normals PNG {p} must be 8-bit RGB storing (n+1)/2*255")
        rgb = cv2.cvtColor(raw[..., :3], cv2.COLOR_BGR2RGB).astype(np.float64)
        n = rgb / 255.0 * 2.0 - 1.0
        n[np.all(raw[..., :3] == 0, axis=-1)] = 0.0
    # Divided by the largest component first: squaring a component near 1e300 would overflow.
    big = np.abs(n).max(axis=-1, keepdims=True)
    n = n / np.where(big > 0, big, 1.0)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)  # 1..sqrt(3), or 0 for a zero vector
    out = np.where(big * norm > 1e-6, n / np.where(norm > 0, norm, 1.0), 0.0)
    return out.astype(np.float32)


def read_intrinsics(spec: str | Path) -> np.ndarray:
    """Parse intrinsics from ``"fx,fy,cx,cy"`` or a JSON file.

    Returns
    -------
    numpy.ndarray
        (3, 3) float64 K.
    """
    text = str(spec)
    if text.lower().endswith(".json") or Path(text).is_file():
        p = _require_file(text, "intrinsics")
        try:
            data = json.loads(p.read_bytes())
        except (json.JSONDecodeError, UnicodeDecodeError, RecursionError) as exc:
            reason = "is empty" if not p.stat().st_size else f"is not valid JSON: {exc}"
            raise InvalidInput(f"intrinsics {p} {reason}") from None
        keys = ("fx", "fy", "cx", "cy")
        missing = [k for k in keys if not isinstance(data, dict) or k not in data]
        if missing:
            raise InvalidInput(f"intrinsics {p} lacks {', '.join(missing)}; expected "
                               '{"fx": …, "fy": …, "cx": …, "cy": …}')
        values = [data[k] for k in ("fx", "fy", "cx", "cy")]
        where = f"intrinsics {p}"
    else:
        parts = text.split(",")
        where = f"--intrinsics {text!r}"
        if len(parts) != 4:
            raise InvalidInput(f"{where} must be fx,fy,cx,cy or a JSON file")
        values = parts
    try:
        fx, fy, cx, cy = (float(v) for v in values)
    except (TypeError, ValueError, OverflowError):
        raise InvalidInput(f"{where}: fx, fy, cx, cy must be numbers") from None
    low, high = FOCAL_RANGE_PX
    if not (low <= fx <= high and low <= fy <= high):
        raise InvalidInput(f"{where}: focal lengths must be positive, {low:g} to {high:g} "
                           f"pixels, got fx={fx:g}, fy={fy:g}")
    if not (abs(cx) <= MAX_PRINCIPAL_POINT_PX and abs(cy) <= MAX_PRINCIPAL_POINT_PX):
        raise InvalidInput(f"{where}: the principal point must be within "
                           f"±{MAX_PRINCIPAL_POINT_PX:g} pixels, got cx={cx:g}, cy={cy:g}")
    return intrinsics_matrix(fx, fy, cx, cy)


def read_redwood_log(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read a camera trajectory in the Redwood ``.log`` format.

    Each entry is a header line of three integers, the first being the frame id (``"i i i+1"``
    in a trajectory), then four lines of a 4x4 camera-to-world matrix. Blank lines are
    ignored.

    Parameters
    ----------
    path : str or Path
        The ``.log`` file.

    Returns
    -------
    ids : numpy.ndarray
        (N,) int64 frame ids, in file order.
    poses : numpy.ndarray
        (N, 4, 4) float64 camera-to-world matrices (``x_world = M @ [x_cam, 1]``), in the
        file's units (metres for Redwood and ICL-NUIM) and camera axes (OpenCV for both).

    Raises
    ------
    InvalidInput
        One line naming the file and line: a malformed header or row, a bottom row other than
        ``0 0 0 1``, a rotation block that is not a rotation, duplicate ids, or no entry.
    """
    p = _require_file(path, "trajectory")
    try:
        text = p.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InvalidInput(f"cannot read trajectory {p}: {exc}") from None
    lines = [(k + 1, line.split()) for k, line in enumerate(text.splitlines()) if line.strip()]
    if not lines:
        raise InvalidInput(f"trajectory {p} has no entry")
    if len(lines) % 5:
        raise InvalidInput(f"trajectory {p}: {len(lines)} non-blank lines is not a whole number "
                           "of entries (a header line and 4 matrix rows each)")
    ids, poses = [], []
    for k in range(0, len(lines), 5):
        number, header = lines[k]
        try:
            numbers = [int(v) for v in header]
        except ValueError:
            numbers = []
        if len(numbers) != 3:
            raise InvalidInput(f"trajectory {p}, line {number}: expected a header of three "
                               f"integers, got {' '.join(header)!r}")
        ids.append(numbers[0])
        rows = []
        for number, row in lines[k + 1:k + 5]:
            try:
                values = [float(v) for v in row]
            except ValueError:
                values = []
            if len(values) != 4 or not np.all(np.isfinite(values)):
                raise InvalidInput(f"trajectory {p}, line {number}: expected 4 finite numbers, "
                                   f"got {' '.join(row)!r}")
            rows.append(values)
        M = np.array(rows)
        if not np.allclose(M[3], [0, 0, 0, 1], atol=1e-6):
            raise InvalidInput(f"trajectory {p}, line {number}: the bottom row of frame "
                               f"{ids[-1]}'s matrix must be 0 0 0 1")
        R = M[:3, :3]
        # Redwood logs print 8 decimals: a rotation there is orthonormal to about 1e-7 only.
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
            raise InvalidInput(f"trajectory {p}, line {lines[k + 1][0]}: frame {ids[-1]}'s "
                               "matrix has no rotation in its upper-left 3x3 block")
        poses.append(M)
    unique, counts = np.unique(ids, return_counts=True)
    if (counts > 1).any():
        dup = unique[counts > 1]
        raise InvalidInput(f"trajectory {p}: frame ids appear twice: "
                           f"{', '.join(map(str, dup[:5]))}")
    return np.array(ids, dtype=np.int64), np.array(poses)


def load_frame(image: str | Path | None = None, depth: str | Path | None = None,
               normals: str | Path | None = None, intrinsics: str | Path | None = None,
               depth_scale: float | None = None, nan_as_invalid: bool = False,
               depth_kind: str = "metric", depth_units: str | None = None,
               depth_encoding: str = "scaled") -> Frame:
    """Build a :class:`Frame` from files.

    Parameters
    ----------
    image : path, optional
        Colour image; may be omitted for depth-only input (then ``depth`` is required).
    depth, normals : path, optional
        Cue files (see :func:`read_depth`, :func:`read_normals`).
    intrinsics : str or path, optional
        ``"fx,fy,cx,cy"`` or JSON; without it a 60° horizontal field of view is assumed and
        noted in ``frame.notes``.
    depth_scale : float, optional
        Divisor for 16-bit depth images in the ``scaled`` encoding.
    nan_as_invalid : bool
        Accept NaN/inf in depth as invalid pixels.
    depth_kind : {"metric", "relative"}
        Whether the given depth has a true scale.
    depth_units : str, optional
        Unit label for outputs; ``"m"`` when a depth scale or a named encoding is given, else
        ``"input"``.
    depth_encoding : str
        How 16-bit depth holds its values (see :func:`read_depth`); default ``"scaled"``.
    """
    if image is None and depth is None:
        raise InvalidInput("give an image, a depth map, or both")
    rgb = read_image(image) if image is not None else None
    d = (read_depth(depth, depth_scale, nan_as_invalid, depth_encoding) if depth is not None
         else None)
    n = read_normals(normals) if normals is not None else None
    shape = rgb.shape[:2] if rgb is not None else d.shape  # type: ignore[union-attr]
    notes: list[str] = []
    if intrinsics is not None:
        K = read_intrinsics(intrinsics)
    else:
        K, note = assume_intrinsics(shape[1], shape[0])
        notes.append(note)
    name = Path(image if image is not None else depth).stem  # type: ignore[arg-type]
    if depth_units is None:
        depth_units = "m" if depth_scale is not None or depth_encoding != "scaled" else "input"
    if depth_kind == "relative":
        depth_units = "relative"
    return Frame(rgb=rgb, K=K, depth=d, normals=n, depth_kind=depth_kind,  # type: ignore[arg-type]
                 depth_units=depth_units, name=name, notes=notes)


def write_reconstruction_files(rec: Reconstruction, folder: Path) -> None:
    """Deprecated: :func:`monoplane.export.saving.write_outputs` (the default formats)."""
    _deprecated("write_reconstruction_files", "monoplane.export.saving.write_outputs")
    write_outputs(rec, Path(folder), select_exporters("frame"))


def save_reconstruction(rec: Reconstruction, out_dir: str | Path, overwrite: bool = False,
                        also: Callable[[Path], object] | None = None) -> Path:
    """Deprecated: :func:`monoplane.export.save`, which writes the same folder."""
    _deprecated("save_reconstruction", "monoplane.export.save")
    return save(rec, out_dir, overwrite, also=also)


def _deprecated(old: str, new: str) -> None:
    warnings.warn(f"monoplane.io.frames.{old} is deprecated; use {new} (the old name goes in "
                  "0.3.0)", DeprecationWarning, stacklevel=3)


#: Writers that moved to :mod:`monoplane.export`: old name -> (module, name).
_MOVED = {
    "atomic_output_dir": ("monoplane.export.files", "atomic_output_dir"),
    "check_output_dir": ("monoplane.export.files", "check_output_dir"),
    "write_ascii_ply": ("monoplane.export.files", "write_ascii_ply"),
    "write_plane_mesh_ply": ("monoplane.export.files", "write_plane_mesh_ply"),
    "write_points_ply": ("monoplane.export.files", "write_points_ply"),
    "planes_document": ("monoplane.export.labels", "planes_document"),
}


def __getattr__(name: str) -> Any:
    if name not in _MOVED:
        raise AttributeError(f"module 'monoplane.io.frames' has no attribute {name!r}")
    module, new = _MOVED[name]
    _deprecated(name, f"{module}.{new}")
    return getattr(importlib.import_module(module), new)
