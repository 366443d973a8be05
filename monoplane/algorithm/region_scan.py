"""One compiled scan of the connected pieces of a refined label map, for the region clean-up.

:func:`monoplane.algorithm.regions.clean_regions` needs four things of the pieces: their point
moments (:class:`~monoplane.algorithm.region_moments.RegionMoments`), their areas, the scene
radius of the pixels it fits, and which pieces touch. Each used to be its own pass over the
image, with its own int64 copy of the labels or boolean mask (five passes, about 5 ms at
640x480). :func:`scan_pieces` reads the image twice: once for the two means the sums are
centred on, once for everything else. Every sum runs in the raster order and float64
precision of the passes it replaces, so the results are the same bits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.algorithm.region_moments import RegionMoments
from monoplane.errors import InvalidInput
from monoplane.jit import kernel


@dataclass(frozen=True)
class PieceScan:
    """What :func:`scan_pieces` reads off the pieces of a label map.

    Attributes
    ----------
    moments : RegionMoments
        Moments of pieces 1..R over their valid points (``RegionMoments.of(points, valid,
        pieces, R)``).
    area : numpy.ndarray
        (R,) int64 pixels of each piece, valid or not.
    radius : float
        :func:`~monoplane.algorithm.region_moments.scene_radius` of the valid points, depth
        units.
    touching : numpy.ndarray or None
        (E, 2) int64 sorted, distinct pairs of touching pieces ``0 < a < b``, as
        :func:`~monoplane.algorithm.regions.region_adjacency` gives them; None when not asked
        for.
    """

    moments: RegionMoments
    area: np.ndarray
    radius: float
    touching: np.ndarray | None


def scan_pieces(points: np.ndarray, valid: np.ndarray, pieces: np.ndarray, num: int,
                connectivity: int | None = None) -> PieceScan:
    """Moments, areas, scene radius and (optionally) adjacency of a map of pieces.

    Parameters
    ----------
    points : numpy.ndarray
        (H, W, 3) camera-frame points (OpenCV axes), depth units.
    valid : numpy.ndarray
        (H, W) bool, the pixels whose points count (moments and radius).
    pieces : numpy.ndarray
        (H, W) int32 labels 0..``num`` (0: no piece), e.g. from
        :func:`~monoplane.geometry.components.label_regions`.
    num : int
        Number of pieces R (at least the largest label).
    connectivity : {4, 8}, optional
        Pixel neighbourhood of the adjacency; None skips it.

    Returns
    -------
    PieceScan
    """
    lab = np.ascontiguousarray(pieces, dtype=np.int32)
    if lab.size and (lab.min() < 0 or lab.max() > num):
        raise InvalidInput(f"pieces must lie in 0..{num}")
    count, total, outer, area, radius, centre, touch = _scan(
        np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3),
        np.ascontiguousarray(valid, dtype=np.bool_).ravel(), lab, int(num),
        connectivity is not None, connectivity == 8)
    touching = None
    if connectivity is not None:
        touching = np.argwhere(np.triu(touch, 1)).astype(np.int64)
    return PieceScan(RegionMoments(count, total, outer, centre), area, float(radius), touching)


@kernel
def _scan(points: np.ndarray, valid: np.ndarray, pieces: np.ndarray, num: int, adjacency: bool,
          diagonal: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float,
                                   np.ndarray, np.ndarray]:
    """:func:`scan_pieces` on (H W, 3) float64 ``points``, (H W,) bool ``valid`` and the
    (H, W) int32 ``pieces``: count (R,), total (R, 3), outer (R, 3, 3), area (R,), radius,
    the moments' centre (3,) and the (R+1, R+1) bool touch matrix (4- or 8-neighbours with
    ``diagonal``; (1, 1) without ``adjacency``).

    First pass: the mean of the valid points (the radius' centre) and of the valid points of
    a piece (the moments' centre), each summed row after row and divided once, as
    ``_mean_where`` does. Second pass, run after run of one piece along each row: the sums
    of ``_moments`` (a run's sums are held in registers, taken from the arrays and written
    back, so they are added in raster order as there), the squared distances of
    ``_radius``, the areas of ``numpy.bincount`` and the pairs of ``_touching`` (a run
    touches what lies next to it and below it, the pairs being a set).
    """
    h, w = pieces.shape
    m0 = m1 = m2 = 0.0
    c0 = c1 = c2 = 0.0
    n_valid = 0
    n_fit = 0
    for y in range(h):
        for x in range(w):
            i = y * w + x
            if valid[i]:
                m0 += points[i, 0]
                m1 += points[i, 1]
                m2 += points[i, 2]
                n_valid += 1
                if pieces[y, x] > 0:
                    c0 += points[i, 0]
                    c1 += points[i, 1]
                    c2 += points[i, 2]
                    n_fit += 1
    if n_valid > 0:
        m0, m1, m2 = m0 / n_valid, m1 / n_valid, m2 / n_valid
    if n_fit > 0:
        c0, c1, c2 = c0 / n_fit, c1 / n_fit, c2 / n_fit
    count = np.zeros(num + 1, dtype=np.int64)
    area = np.zeros(num + 1, dtype=np.int64)
    total = np.zeros((num + 1, 3))
    outer = np.zeros((num + 1, 3, 3))
    touch = np.zeros((num + 1, num + 1) if adjacency else (1, 1), dtype=np.bool_)
    best = 0.0
    for y in range(h):
        x = 0
        while x < w:
            lab = pieces[y, x]
            end = x + 1
            while end < w and pieces[y, end] == lab:
                end += 1
            area[lab] += end - x
            n = count[lab]
            t0, t1, t2 = total[lab, 0], total[lab, 1], total[lab, 2]
            o00, o01, o02 = outer[lab, 0, 0], outer[lab, 0, 1], outer[lab, 0, 2]
            o11, o12, o22 = outer[lab, 1, 1], outer[lab, 1, 2], outer[lab, 2, 2]
            for k in range(y * w + x, y * w + end):
                if not valid[k]:
                    continue
                p0, p1, p2 = points[k, 0], points[k, 1], points[k, 2]
                d2 = 0.0
                d2 += (p0 - m0) ** 2
                d2 += (p1 - m1) ** 2
                d2 += (p2 - m2) ** 2
                best = max(best, d2)
                if lab > 0:
                    x0, x1, x2 = p0 - c0, p1 - c1, p2 - c2
                    n += 1
                    t0 += x0
                    o00 += x0 * x0
                    o01 += x0 * x1
                    o02 += x0 * x2
                    t1 += x1
                    o11 += x1 * x1
                    o12 += x1 * x2
                    t2 += x2
                    o22 += x2 * x2
            if lab > 0:
                count[lab] = n
                total[lab, 0], total[lab, 1], total[lab, 2] = t0, t1, t2
                outer[lab, 0, 0], outer[lab, 0, 1], outer[lab, 0, 2] = o00, o01, o02
                outer[lab, 1, 1], outer[lab, 1, 2], outer[lab, 2, 2] = o11, o12, o22
                if adjacency:
                    lo, hi = (max(x - 1, 0), min(end + 1, w)) if diagonal else (x, end)
                    for other in pieces[y, end:min(end + 1, w)]:
                        if other > 0:  # the next run is another piece
                            touch[lab, other] = True
                            touch[other, lab] = True
                    if y + 1 < h:
                        for other in pieces[y + 1, lo:hi]:
                            if other > 0 and other != lab:
                                touch[lab, other] = True
                                touch[other, lab] = True
            x = end
    for lab in range(num + 1):
        for a in range(3):
            for b in range(a):
                outer[lab, a, b] = outer[lab, b, a]
    centre = np.empty(3)
    centre[0], centre[1], centre[2] = c0, c1, c2
    return count[1:], total[1:], outer[1:], area[1:], np.sqrt(best), centre, touch
