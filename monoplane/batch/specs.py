"""What a batch runs on: frame specs from a folder of frame folders or from a manifest.

A frame folder (the layout of ``data_samples/room_000``) holds ``rgb.png`` or ``rgb.jpg``,
and optionally ``depth.npy`` or ``depth.png``, ``normals.npy`` and ``intrinsics.json``.

A manifest is a ``.jsonl`` (one JSON object a line) or ``.csv`` (with a header row) file with
the columns :data:`MANIFEST_COLUMNS`. Paths are relative to the manifest's folder (absolute
paths are kept). Only ``image`` is required as a column; an empty ``image`` means a
depth-only frame, which then needs ``depth``. ``intrinsics`` is a JSON file or
``"fx,fy,cx,cy"``. ``depth_encoding`` names how a row's 16-bit depth holds its values
(:mod:`monoplane.io.depth_encodings`), so one manifest can list frames of several datasets.

Every problem is reported as one :class:`~monoplane.errors.InvalidInput` line naming the file
and the row (1-based line number in the file).
"""

from __future__ import annotations

import csv
import io
import json
import re
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from monoplane.errors import InvalidInput
from monoplane.io.depth_encodings import check_depth_encoding

MANIFEST_COLUMNS = ("name", "image", "depth", "normals", "intrinsics", "depth_scale",
                    "depth_encoding")
#: Names the batch output folder uses itself, so no frame may take them.
RESERVED_NAMES = ("summary.json", "index.html", "index_files")
_SAFE_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.+=@,-]*$")


@dataclass(frozen=True)
class FrameSpec:
    """One frame of a batch: where its files are and how to read them.

    Attributes
    ----------
    name : str
        Output sub-folder name (unique within the batch).
    image : str or None
        Absolute path of the colour image; None for a depth-only frame.
    depth, normals : str or None
        Absolute paths of cue files (see :func:`monoplane.io.frames.load_frame`).
    intrinsics : str or None
        Absolute path of a JSON file, or ``"fx,fy,cx,cy"``; None = assumed 60 degree FOV.
    depth_scale : float or None
        Divisor of 16-bit PNG depth (1000 for millimetres, 5000 for TUM).
    depth_kind : {"metric", "relative"}
        Whether the depth has a true scale.
    nan_as_invalid : bool
        Accept NaN/inf depth as invalid pixels.
    depth_encoding : str
        How 16-bit depth holds its values: ``"scaled"`` (by ``depth_scale``) or a dataset's
        own (:mod:`monoplane.io.depth_encodings`).
    """

    name: str
    image: str | None = None
    depth: str | None = None
    normals: str | None = None
    intrinsics: str | None = None
    depth_scale: float | None = None
    depth_kind: str = "metric"
    nan_as_invalid: bool = False
    depth_encoding: str = "scaled"


def absolute_paths(spec: FrameSpec) -> FrameSpec:
    """The spec with its file paths made absolute (relative to the working directory)."""
    def absolute(value: str | None) -> str | None:
        return None if value is None else str(Path(value).expanduser().absolute())

    intr = spec.intrinsics
    if intr is not None and (intr.lower().endswith(".json") or Path(intr).is_file()):
        intr = absolute(intr)
    return replace(spec, image=absolute(spec.image), depth=absolute(spec.depth),
                   normals=absolute(spec.normals), intrinsics=intr)


def check_name(name: str, where: str) -> str:
    """Return ``name`` if it can be an output folder name, else raise naming ``where``."""
    if not _SAFE_NAME.match(name) or name in RESERVED_NAMES:
        raise InvalidInput(f"{where}: frame name {name!r} cannot be an output folder name "
                           "(use letters, digits and _ . + = @ , -, not starting with . or -)")
    return name


def _first(folder: Path, names: tuple[str, ...]) -> str | None:
    for n in names:
        if (folder / n).is_file():
            return str((folder / n).resolve())
    return None


def frames_from_folder(root: Path, depth_scale: float | None = None,
                       depth_kind: str = "metric", nan_as_invalid: bool = False,
                       notes: list[str] | None = None,
                       depth_encoding: str = "scaled") -> list[FrameSpec]:
    """One spec per sub-folder of ``root`` that holds a colour image or a depth map.

    Sub-folders are taken in name order. Hidden ones (``.name``) and those with neither
    ``rgb.*`` nor ``depth.*`` (e.g. a multi-view scene beside the frames) are not frames; the
    latter are named in ``notes`` when a list is given.

    Raises
    ------
    InvalidInput
        If ``root`` has no frame sub-folder.
    """
    subs = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))
    specs = []
    ignored = []
    for sub in subs:
        image = _first(sub, ("rgb.png", "rgb.jpg", "rgb.jpeg"))
        depth = _first(sub, ("depth.npy", "depth.png"))
        if image is None and depth is None:
            ignored.append(sub.name)
            continue
        specs.append(FrameSpec(
            name=check_name(sub.name, str(sub)), image=image, depth=depth,
            normals=_first(sub, ("normals.npy", "normals.png")),
            intrinsics=_first(sub, ("intrinsics.json",)),
            depth_scale=depth_scale, depth_kind=depth_kind, nan_as_invalid=nan_as_invalid,
            depth_encoding=depth_encoding))
    if not specs:
        raise InvalidInput(f"{root}: no frame sub-folders (expected e.g. "
                           f"{root / 'room_000' / 'rgb.png'})")
    if ignored and notes is not None:
        notes.append(f"ignored {len(ignored)} sub-folder(s) of {root} without rgb.* or "
                     f"depth.*: {', '.join(ignored)}")
    return specs


def _manifest_text(path: Path) -> str:
    """The manifest's text; one line naming the file when it is not UTF-8 text."""
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise InvalidInput(f"{path}: not UTF-8 text (byte {exc.start})") from None


def _rows_jsonl(path: Path) -> list[tuple[int, dict[str, Any]]]:
    rows = []
    for lineno, line in enumerate(_manifest_text(path).splitlines(), start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError as exc:
            raise InvalidInput(f"{path}, row {lineno}: not valid JSON ({exc.msg})") from None
        if not isinstance(row, dict):
            raise InvalidInput(f"{path}, row {lineno}: expected a JSON object with columns "
                               f"{', '.join(MANIFEST_COLUMNS)}")
        rows.append((lineno, row))
    return rows


def _rows_csv(path: Path) -> list[tuple[int, dict[str, Any]]]:
    with io.StringIO(_manifest_text(path), newline="") as fh:
        reader = csv.DictReader(fh)
        header = reader.fieldnames or []
        if "image" not in header:
            raise InvalidInput(f"{path}, row 1: the header lacks the required column 'image' "
                               f"(columns: {', '.join(MANIFEST_COLUMNS)})")
        rows = []
        for row in reader:
            if None in row:
                raise InvalidInput(f"{path}, row {reader.line_num}: more values than columns")
            if not any((v or "").strip() for v in row.values()):
                continue
            rows.append((reader.line_num, row))
    return rows


def _path(value: Any, base: Path, where: str, column: str) -> str | None:
    if value is None:
        return None
    if not isinstance(value, str):
        raise InvalidInput(f"{where}: column '{column}' must be a path string, got {value!r}")
    value = value.strip()
    if not value:
        return None
    p = Path(value).expanduser()
    p = p if p.is_absolute() else base / p
    if not p.is_file():
        raise InvalidInput(f"{where}: {column} file not found: {p}")
    return str(p.resolve())


def frames_from_manifest(path: Path, depth_scale: float | None = None,
                         depth_kind: str = "metric", nan_as_invalid: bool = False,
                         depth_encoding: str = "scaled") -> list[FrameSpec]:
    """Frame specs from a ``.jsonl`` or ``.csv`` manifest (see the module docstring).

    Parameters
    ----------
    path : pathlib.Path
        The manifest; relative paths in it are relative to its folder.
    depth_scale : float, optional
        Default for ``scaled`` rows without a ``depth_scale``.
    depth_kind, nan_as_invalid
        As in :class:`FrameSpec`, for every row.
    depth_encoding : str
        Default for rows without a ``depth_encoding``; a row's encoding other than
        ``scaled`` drops the default ``depth_scale`` (it gives metres by itself).

    Raises
    ------
    InvalidInput
        One line naming the file and row: an unknown or missing column, a file that does not
        exist, a bad ``depth_scale`` or ``depth_encoding``, a row with neither image nor
        depth, a duplicate name.
    """
    suffix = path.suffix.lower()
    if suffix == ".jsonl":
        rows = _rows_jsonl(path)
    elif suffix == ".csv":
        rows = _rows_csv(path)
    else:
        raise InvalidInput(f"{path}: a manifest must be .jsonl or .csv")
    if not rows:
        raise InvalidInput(f"{path}: the manifest lists no frame")
    base = path.parent
    specs: list[FrameSpec] = []
    seen: dict[str, int] = {}
    for lineno, row in rows:
        where = f"{path}, row {lineno}"
        unknown = sorted(set(row) - set(MANIFEST_COLUMNS))
        if unknown:
            raise InvalidInput(f"{where}: unknown column {', '.join(map(repr, unknown))}; "
                               f"valid columns: {', '.join(MANIFEST_COLUMNS)}")
        if "image" not in row:
            raise InvalidInput(f"{where}: missing column 'image' (leave it empty for a "
                               "depth-only frame)")
        image = _path(row.get("image"), base, where, "image")
        depth = _path(row.get("depth"), base, where, "depth")
        normals = _path(row.get("normals"), base, where, "normals")
        intr = row.get("intrinsics")
        if isinstance(intr, str) and intr.strip() and len(intr.split(",")) != 4:
            intr = _path(intr, base, where, "intrinsics")
        elif isinstance(intr, str):
            intr = intr.strip() or None
        elif intr is not None:
            raise InvalidInput(f"{where}: column 'intrinsics' must be a JSON file or "
                               f"'fx,fy,cx,cy', got {intr!r}")
        encoding = _row_encoding(row.get("depth_encoding"), depth_encoding, where)
        scale_raw = row.get("depth_scale")
        scale = depth_scale if encoding == "scaled" else None
        if scale_raw is not None and str(scale_raw).strip():
            try:
                scale = float(scale_raw)
            except ValueError:
                raise InvalidInput(f"{where}: depth_scale must be a number, "
                                   f"got {scale_raw!r}") from None
            if not scale > 0:
                raise InvalidInput(f"{where}: depth_scale must be positive, got {scale}")
            check_depth_encoding(encoding, scale, where)
        if image is None and depth is None:
            raise InvalidInput(f"{where}: a depth-only row (empty image) needs a depth file")
        name = row.get("name")
        name = str(name).strip() if name is not None and str(name).strip() else None
        if name is None:
            name = Path(image or depth).stem  # type: ignore[arg-type]
        check_name(name, where)
        if name in seen:
            raise InvalidInput(f"{where}: frame name {name!r} is already used on row "
                               f"{seen[name]}; give each row a unique 'name'")
        seen[name] = lineno
        specs.append(FrameSpec(name=name, image=image, depth=depth, normals=normals,
                               intrinsics=intr, depth_scale=scale, depth_kind=depth_kind,
                               nan_as_invalid=nan_as_invalid, depth_encoding=encoding))
    return specs


def _row_encoding(value: Any, default: str, where: str) -> str:
    """A row's ``depth_encoding`` (``default`` when empty), checked against the valid ones."""
    if value is None or (isinstance(value, str) and not value.strip()):
        return default
    if not isinstance(value, str):
        raise InvalidInput(f"{where}: column 'depth_encoding' must be a name, got {value!r}")
    encoding = value.strip()
    check_depth_encoding(encoding, None, f"{where}: column 'depth_encoding'")
    return encoding


def read_frames(source: str | Path, depth_scale: float | None = None,
                depth_kind: str = "metric", nan_as_invalid: bool = False,
                notes: list[str] | None = None,
                depth_encoding: str = "scaled") -> list[FrameSpec]:
    """Frame specs from a folder of frame folders or a ``.jsonl``/``.csv`` manifest.

    Parameters
    ----------
    source : path
        Folder or manifest.
    depth_scale, depth_kind, nan_as_invalid, depth_encoding
        Defaults for every frame (see :class:`FrameSpec`).
    notes : list of str, optional
        Receives remarks for the user (e.g. sub-folders that are not frames).

    Raises
    ------
    InvalidInput
        If ``source`` does not exist or is neither a folder nor a manifest, or as
        :func:`frames_from_folder` and :func:`frames_from_manifest`.
    """
    check_depth_encoding(depth_encoding, depth_scale, "--depth-encoding")
    p = Path(source)
    if p.is_dir():
        return frames_from_folder(p, depth_scale, depth_kind, nan_as_invalid, notes,
                                  depth_encoding)
    if p.is_file():
        return frames_from_manifest(p, depth_scale, depth_kind, nan_as_invalid,
                                    depth_encoding)
    raise InvalidInput(f"batch input not found: {p} (give a folder of frame folders or a "
                       ".jsonl/.csv manifest)")
