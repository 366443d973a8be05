"""Cues that come with the input: the check every frame with depth and normals goes through.

A frame that already carries depth and normals needs no cue provider (see
:meth:`monoplane.contracts.CueProvider.needs_cues`); the pipeline still orients its normals
towards the camera and blanks them where depth is invalid, which is all :func:`use_given_cues`
does.
"""

from __future__ import annotations

import numpy as np

from monoplane.datamodel import Frame
from monoplane.errors import InvalidInput
from monoplane.jit import kernel


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
    k_inv = np.linalg.inv(frame.K).astype(np.float32)
    normals, flipped = _orient_and_blank(frame.normals, frame.depth, k_inv)
    if flipped:
        notes.append(f"normals: {flipped} given normals pointed away from the camera and were "
                     f"flipped")
    return frame.with_(normals=normals, notes=notes)


@kernel
def _orient_and_blank(normals: np.ndarray, depth: np.ndarray, k_inv: np.ndarray
                      ) -> tuple[np.ndarray, int]:
    """:func:`~monoplane.cues.transforms.face_camera` of (H, W, 3) float32 ``normals``
    with the (3, 3) float32 ``k_inv``, then zero where the (H, W) float32 ``depth`` is not
    positive, in one pass (the same float32 operations in the same order, so the same bits).
    Also returns how many normals the orientation flipped."""
    h, w = depth.shape
    out = np.zeros((h, w, 3), dtype=np.float32)
    flipped = 0
    for v in range(h):
        fv = np.float32(v)
        for u in range(w):
            fu = np.float32(u)
            dot = normals[v, u, 0] * (k_inv[0, 0] * fu + k_inv[0, 1] * fv + k_inv[0, 2])
            dot += normals[v, u, 1] * (k_inv[1, 0] * fu + k_inv[1, 1] * fv + k_inv[1, 2])
            dot += normals[v, u, 2] * (k_inv[2, 0] * fu + k_inv[2, 1] * fv + k_inv[2, 2])
            sign = np.float32(-1.0) if dot > 0 else np.float32(1.0)
            changed = False
            for c in range(3):
                value = sign * normals[v, u, c]
                changed = changed or value != normals[v, u, c]
                if depth[v, u] > 0:
                    out[v, u, c] = value
            if changed:
                flipped += 1
    return out, flipped
