"""Regular pixel lattices of an organised frame: which rows and columns a frame's cloud keeps
when it is sampled on a lattice (:meth:`monoplane.geometry.cloud.PlaneCloud.from_frame` with
``grid``), for at most a given number of valid pixels.

A lattice of step ``s`` keeps the rows and columns ``⌊(i + ½) s⌋``: for a whole ``s`` every
``s``-th line from ``s // 2``, for a fractional one lines ``⌊s⌋`` and ``⌈s⌉`` apart.
"""

from __future__ import annotations

import numpy as np

from monoplane.errors import InvalidInput


def lattice_lines(size: int, step: float) -> np.ndarray:
    """Pixel rows (or columns) ``⌊(i + ½) step⌋`` of a lattice across ``size`` pixels.

    A whole ``step`` gives every ``step``-th line from ``step // 2``; a fractional one spaces
    the lines ``⌊step⌋`` and ``⌈step⌉`` apart, so that the lattice can hold as many points
    as asked for at any resolution.

    Parameters
    ----------
    size : int
        Image height (or width) in pixels.
    step : float
        Lattice step in pixels, >= 1.

    Returns
    -------
    numpy.ndarray
        (L,) int64 ascending distinct lines in ``[0, size)``.
    """
    lines = np.floor((np.arange(int(np.ceil(size / step)) + 1) + 0.5) * step).astype(np.int64)
    return lines[lines < size]


def lattice_step(valid: np.ndarray, max_points: int, *, whole: bool = False) -> float:
    """Smallest lattice step (to 0.1 %, or a whole one) that keeps at most ``max_points`` valid
    pixels.

    Parameters
    ----------
    valid : numpy.ndarray
        (H, W) bool valid pixels.
    max_points : int
        Most lattice pixels to keep, >= 3.
    whole : bool
        Only whole steps: every ``s``-th pixel of every ``s``-th row from ``s // 2``.

    Returns
    -------
    float
        Step ``s >= 1`` in pixels (a whole number with ``whole``) such that the valid pixels on
        the rows and columns :func:`lattice_lines` ``(·, s)`` number at most ``max_points``.
    """
    if max_points < 3:
        raise InvalidInput(f"max_points must be at least 3, got {max_points}")
    h, w = valid.shape

    def kept(step: float) -> int:
        return int(np.count_nonzero(valid[np.ix_(lattice_lines(h, step), lattice_lines(w, step))]))

    # The valid fraction is about the same on every lattice: start from the step it gives and
    # grow it by the excess (or by one pixel) until the lattice fits.
    step = max(1.0, float(np.sqrt(np.count_nonzero(valid) / max_points)))
    if whole:
        step = float(np.ceil(step))
    while (count := kept(step)) > max_points:
        step = step + 1.0 if whole else step * max(1.001, float(np.sqrt(count / max_points)))
    return step


def lattice_stride(valid: np.ndarray, max_points: int) -> int:
    """:func:`lattice_step` with ``whole``, as an int."""
    return int(lattice_step(valid, max_points, whole=True))
