"""The frames of ``monoplane bench --data``: a user's own frames instead of synthetic ones.

Layouts read
    * what ``monoplane batch`` reads (:func:`monoplane.batch.specs.read_frames`): a folder of
      frame folders (``rgb.png``, ``depth.png`` / ``depth.npy``, ``normals.npy``,
      ``intrinsics.json``) or a ``.jsonl`` / ``.csv`` manifest;
    * a sequence folder laid out like a Redwood-format RGB-D capture (the ICL-NUIM living
      room): ``depth/`` with one depth map per frame, sorted by name, and optionally
      ``image/`` with as many colour images and ``intrinsics.json``. No trajectory is needed.

Depth encodings
    ``depth_encoding`` says how every frame's 16-bit depth holds its values (``scaled`` by
    ``depth_scale``, ``tum``, ``sun-rotated``, ``kinect-disparity``;
    :mod:`monoplane.io.depth_encodings`). Frames of several datasets, each in its own
    encoding (e.g. one TUM, one SUN RGB-D and one NYU frame in one folder), are listed in a
    manifest whose ``depth_encoding`` column names each row's.

Depth-only
    With ``depth_only`` the colour images are not read, so the pipeline sees what a range
    sensor gives: depth alone, normals left to the cue stage (estimated from the depth). This
    is the frame the issue of camera-rate RGB-D is about.

Choosing frames
    ``frames`` caps the count: that many frames spread evenly over the listing (first and
    last included), so a 105-frame sequence is sampled over the whole trajectory.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from monoplane.batch.specs import read_frames
from monoplane.datamodel import Frame
from monoplane.errors import InvalidInput

_DEPTH_SUFFIXES = (".png", ".npy")
_IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
#: A frame's files: name, image, depth, normals, intrinsics.
_Row = tuple[str, str | None, str | None, str | None, str | None]


@dataclass(frozen=True)
class DataSource:
    """Where ``monoplane bench --data`` reads its frames, and how (picklable for the child
    process that runs the bench).

    Attributes
    ----------
    path : str
        Folder of frame folders, manifest, or sequence folder (module docstring).
    depth_scale : float or None
        Divisor of 16-bit PNG depth (1000 for millimetres, 5000 for TUM); a manifest's
        ``depth_scale`` column wins for its rows.
    intrinsics : str or None
        ``"fx,fy,cx,cy"`` or a JSON file for every frame; else each frame's own (a frame
        folder's or the sequence's ``intrinsics.json``, a manifest's column), else a 60 degree
        field of view is assumed.
    depth_only : bool
        Do not read colour images (module docstring).
    frames : int or None
        At most this many frames, spread evenly; None: all.
    depth_encoding : str
        How 16-bit depth holds its values (module docstring); a manifest's
        ``depth_encoding`` column wins for its rows.
    """

    path: str
    depth_scale: float | None = None
    intrinsics: str | None = None
    depth_only: bool = False
    frames: int | None = None
    depth_encoding: str = "scaled"


def _spread(n: int, count: int | None) -> list[int]:
    """Indices of at most ``count`` of ``n`` items, spread evenly, first and last included."""
    if count is None or count >= n:
        return list(range(n))
    return sorted({int(round(i)) for i in np.linspace(0, n - 1, count)})


def _sorted_files(folder: Path, suffixes: tuple[str, ...]) -> list[Path]:
    return sorted(f for f in folder.iterdir() if f.is_file() and f.suffix.lower() in suffixes)


def _sequence(root: Path, source: DataSource) -> list[_Row]:
    """(name, image, depth, normals, intrinsics) of a sequence folder's frames."""
    depths = _sorted_files(root / "depth", _DEPTH_SUFFIXES)
    if not depths:
        raise InvalidInput(f"--data {root}: depth/ holds no depth map "
                           f"({', '.join(_DEPTH_SUFFIXES)})")
    images: list[Path | None] = [None] * len(depths)
    if (root / "image").is_dir() and not source.depth_only:
        found = _sorted_files(root / "image", _IMAGE_SUFFIXES)
        if len(found) != len(depths):
            raise InvalidInput(f"--data {root}: {len(found)} images in image/ but "
                               f"{len(depths)} depth maps in depth/")
        images = list(found)
    own = root / "intrinsics.json"
    intr = str(own) if own.is_file() else None
    return [(d.stem, None if i is None else str(i), str(d), None, intr)
            for i, d in zip(images, depths, strict=True)]


def load_data_frames(source: DataSource) -> list[Frame]:
    """Read the frames of ``source`` (see the module docstring).

    Returns
    -------
    list of Frame
        In listing order, each named after its frame folder, manifest row or depth file.

    Raises
    ------
    InvalidInput
        One line naming the folder, file or argument: a missing folder, an empty listing, a
        depth PNG without a scale or encoding, a bad encoding, unreadable files.
    """
    from monoplane.io.frames import load_frame  # loads OpenCV

    if source.frames is not None and source.frames < 1:
        raise InvalidInput(f"--frames must be at least 1, got {source.frames}")
    root = Path(source.path)
    if root.is_dir() and (root / "depth").is_dir():
        rows = _sequence(root, source)
        scales = [source.depth_scale] * len(rows)
        kinds = ["metric"] * len(rows)
        encodings = [source.depth_encoding] * len(rows)
    else:
        specs = read_frames(root, depth_scale=source.depth_scale,
                            depth_encoding=source.depth_encoding)
        rows = [(s.name, s.image, s.depth, s.normals, s.intrinsics) for s in specs]
        scales = [s.depth_scale for s in specs]
        kinds = [s.depth_kind for s in specs]
        encodings = [s.depth_encoding for s in specs]
        if source.depth_only:
            missing = next((s.name for s in specs if s.depth is None), None)
            if missing is not None:
                raise InvalidInput(f"--depth-only: frame {missing!r} of {root} has no depth")
            rows = [(name, None, depth, None, intr) for name, _, depth, _, intr in rows]
    frames = []
    for i in _spread(len(rows), source.frames):
        name, image, depth, normals, intr = rows[i]
        frame = load_frame(image, depth=depth, normals=normals,
                           intrinsics=source.intrinsics or intr,
                           depth_scale=scales[i], depth_kind=kinds[i],
                           depth_encoding=encodings[i])
        frames.append(frame.with_(name=name))
    return frames
