"""Intrinsics for images that come without calibration, and the note that says so.

Whoever builds a :class:`~monoplane.datamodel.Frame` without known intrinsics (file readers, the
Python API) calls :func:`assume_intrinsics` and puts the returned note in ``frame.notes``. Cue
providers recognise that note with :func:`intrinsics_assumed` and may replace the guess with a
better one (a network profile's field of view) via :func:`reassume_intrinsics`. Notes end up in
``planes.json``, so every result says which intrinsics it rests on.
"""

from __future__ import annotations

import numpy as np

from monoplane.datamodel import Frame, default_intrinsics

#: Every note about assumed intrinsics starts with this (``monoplane.io.frames.load_frame`` too).
ASSUMED_INTRINSICS_NOTE = "intrinsics not given"
#: Field of view used when nothing better is known (see ``monoplane.datamodel.default_intrinsics``).
DEFAULT_HFOV_DEG = 60.0


def assume_intrinsics(width: int, height: int, hfov_deg: float = DEFAULT_HFOV_DEG,
                      source: str = "monoplane default") -> tuple[np.ndarray, str]:
    """Intrinsics for an uncalibrated image, and the note to record with them.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    hfov_deg : float
        Horizontal field of view in degrees.
    source : str
        Where the field of view comes from, for the note.

    Returns
    -------
    K : numpy.ndarray
        (3, 3) float64 centred pinhole with square pixels.
    note : str
        ``"intrinsics not given: assumed ..."``, for ``Frame.notes``.
    """
    K = default_intrinsics(width, height, hfov_deg)
    note = (f"{ASSUMED_INTRINSICS_NOTE}: assumed a {hfov_deg:g}° horizontal field of view "
            f"({source}), fx = fy = {K[0, 0]:.1f} px, principal point at the image centre")
    return K, note


def intrinsics_assumed(frame: Frame) -> bool:
    """True when the frame's intrinsics were guessed rather than given."""
    return any(n.startswith(ASSUMED_INTRINSICS_NOTE) for n in frame.notes)


def reassume_intrinsics(frame: Frame, hfov_deg: float, source: str) -> Frame:
    """Replace guessed intrinsics by a centred pinhole with another field of view.

    Frames whose intrinsics were given are returned unchanged.

    Parameters
    ----------
    frame : Frame
        The frame.
    hfov_deg : float
        New horizontal field of view in degrees.
    source : str
        Where it comes from (e.g. ``"profile omnidata"``), for the note.
    """
    if not intrinsics_assumed(frame):
        return frame
    K, note = assume_intrinsics(frame.width, frame.height, hfov_deg, source)
    notes = [n for n in frame.notes if not n.startswith(ASSUMED_INTRINSICS_NOTE)] + [note]
    return frame.with_(K=K, notes=notes)
