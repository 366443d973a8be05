"""One Rerun recording of a whole batch (``monoplane batch --rerun FILE.rrd``).

Frames run in worker processes (or on other machines), and a recording is one stream, so the
recording is made afterwards, in this process, from what every frame folder holds
(``labels.png``, ``planes.json``) and the frame's input files (image, depth). Frames that an
earlier run completed are included too. Frame ``i`` of the batch, in input order, is logged at
step ``i`` of the timeline ``frame``, with the entities of a single view (see
:mod:`monoplane.export.rerun_log`); scrubbing the timeline walks through the batch.

A frame whose depth a monocular network predicted has no depth file, and that prediction is
not stored, so such a frame has its image, labels and plane meshes in the recording but no
depth and no points.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from monoplane.batch.frame import FrameResult, one_line
from monoplane.batch.specs import FrameSpec, read_frames
from monoplane.datamodel import Reconstruction
from monoplane.errors import InvalidInput
from monoplane.export.rerun_log import log_reconstruction, recording_file, require_rerun
from monoplane.io.frames import load_frame

#: Timeline of a batch recording; its steps are frame indices in input order.
TIMELINE = "frame"


def load_frame_output(folder: Path, spec: FrameSpec) -> Reconstruction:
    """Rebuild a frame's reconstruction from its output folder and its input files.

    Parameters
    ----------
    folder : pathlib.Path
        The frame's output folder (``labels.png``, ``planes.json``).
    spec : FrameSpec
        The frame's inputs; the intrinsics come from ``planes.json`` (they may have been
        assumed), normals are not read.

    Returns
    -------
    Reconstruction
        Labels, planes (camera frame) and the frame's image and depth.

    Raises
    ------
    InvalidInput
        A file is missing or unreadable.
    """
    try:
        doc = json.loads((folder / "planes.json").read_text())
        k = doc["intrinsics"]
        params = np.array([[*p["normal"], p["offset"]] for p in doc["planes"]],
                          dtype=np.float64).reshape(-1, 4)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InvalidInput(f"cannot read {folder / 'planes.json'}: {exc}") from None
    labels = cv2.imread(str(folder / "labels.png"), cv2.IMREAD_UNCHANGED)
    if labels is None or labels.ndim != 2:
        raise InvalidInput(f"cannot read {folder / 'labels.png'} as a label map")
    frame = load_frame(spec.image, depth=spec.depth,
                       intrinsics=f"{k['fx']},{k['fy']},{k['cx']},{k['cy']}",
                       depth_scale=spec.depth_scale, nan_as_invalid=spec.nan_as_invalid,
                       depth_kind=spec.depth_kind, depth_encoding=spec.depth_encoding)
    return Reconstruction(frame=frame.with_(name=spec.name), labels=labels.astype(np.int32),
                          planes=params)


def write_batch_recording(path: str | Path, out: str | Path, specs: Sequence[FrameSpec],
                          frames: Sequence[FrameResult]) -> list[str]:
    """Write one ``.rrd`` of every finished frame of a batch (atomically).

    Parameters
    ----------
    path : str or Path
        The ``.rrd`` file.
    out : str or Path
        The batch output folder.
    specs : sequence of FrameSpec
        Every frame of the batch, in input order (their positions are the timeline steps).
    frames : sequence of FrameResult
        The batch's outcome (``BatchSummary.frames``); failed frames are left out.

    Returns
    -------
    list of str
        ``"name: reason"`` of each finished frame that could not be reloaded (and is therefore
        missing from the recording).
    """
    rr = require_rerun()
    done = {f.name for f in frames if f.status in ("ok", "skipped")}
    missing = []
    with recording_file(path) as stream:
        for i, spec in enumerate(specs):
            if spec.name not in done:
                continue
            try:
                rec = load_frame_output(Path(out) / spec.name, spec)
            except Exception as exc:  # a moved input: record it, log the other frames
                missing.append(f"{spec.name}: {one_line(exc)}")
                continue
            stream.set_time(TIMELINE, sequence=i)
            log_reconstruction(rr, stream, rec)
    return missing


def record_batch(path: str | Path, source: str | Path, out: str | Path,
                 frames: Sequence[FrameResult], **reading: Any) -> list[str]:
    """:func:`write_batch_recording` of the batch that read ``source`` (a folder of frame
    folders or a manifest, read again with :func:`~monoplane.batch.specs.read_frames` and the
    same ``reading`` keywords: ``depth_scale``, ``depth_kind``, ``nan_as_invalid``,
    ``depth_encoding``) into
    ``out``; returns the frames missing from it, as ``"name: reason"``."""
    return write_batch_recording(path, out, read_frames(source, **reading), frames)
