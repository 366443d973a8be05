"""Cues that come with the input: the check every frame with depth and normals goes through.

A frame that already carries depth and normals needs no cue provider (see
:meth:`monoplane.stages.base.CueProvider.needs_cues`); the pipeline still orients its normals
towards the camera and blanks them where depth is invalid, which is all :func:`use_given_cues`
does.
"""

from __future__ import annotations

import numpy as np

from monoplane.cues.transforms import orient_normals
from monoplane.datamodel import Frame
from monoplane.errors import InvalidInput


def use_given_cues(frame: Frame) -> Frame:
    """Accept a frame's own depth and normals.

    Parameters
    ----------
    frame : Frame
        With ``depth`` (H, W) and ``normals`` (H, W, 3) in the camera frame (OpenCV axes).

    Returns
    -------
    Frame
        Normals flipped where they pointed away from the camera (noted in ``notes``) and zero
        where depth is invalid.
    """
    if frame.depth is None or frame.normals is None:
        raise InvalidInput(f"{frame.name}: given cues need both a depth map and normals")
    notes = list(frame.notes)
    normals = orient_normals(frame.normals, frame.K)
    flipped = int(np.sum(np.any(normals != frame.normals, axis=-1)))
    if flipped:
        notes.append(f"normals: {flipped} given normals pointed away from the camera and were "
                     f"flipped")
    normals = np.where((frame.depth > 0)[..., None], normals, 0).astype(np.float32)
    return frame.with_(normals=normals, notes=notes)
