"""Choosing the view sets of a posed sequence from its ground truth (step 1 and 2 of the
protocol in :mod:`monoplane.evaluation.posed_sequences`).

A candidate pair has a relative rotation within ``[min_angle, max_angle]`` and a mutual overlap
of at least ``min_overlap`` (:func:`view_overlap`); pairs are spread greedily over the sequence
(:func:`select_pairs`), or one set of K frames is spread by rotation over a connected overlap
graph (:func:`select_views`). Splits: ``tune`` holds the first ``ceil(N / 2)`` frames,
``report`` the others (:func:`split_positions`).

Frames: cameras world-to-camera ``x_cam = R x_world + t`` (OpenCV axes), metres.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.evaluation.posed_frames import PosedSequence

SPLITS: tuple[str, ...] = ("tune", "report", "all")
#: Pixel spacing of the overlap test's samples in the source view (80x60 at 640x480).
OVERLAP_STRIDE = 8
#: Relative depth difference within which a lifted pixel is visible in the other view.
VISIBILITY_TOLERANCE = 0.05


def rotation_angles(R: np.ndarray) -> np.ndarray:
    """Pairwise relative rotation angles.

    Parameters
    ----------
    R : numpy.ndarray
        (N, 3, 3) rotations.

    Returns
    -------
    numpy.ndarray
        (N, N) float64 angle of ``R_j R_iᵀ`` in degrees.
    """
    # trace(R_j R_iᵀ) is the elementwise product summed.
    cos = (np.einsum("aij,bij->ab", R, R) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def view_overlap(depth_i: np.ndarray, depth_j: np.ndarray, K: np.ndarray, R_i: np.ndarray,
                 t_i: np.ndarray, R_j: np.ndarray, t_j: np.ndarray,
                 stride: int = OVERLAP_STRIDE,
                 tolerance: float = VISIBILITY_TOLERANCE) -> float:
    """Share of view i's measured surface that view j sees.

    View i's valid-depth pixels, on a grid of every ``stride``-th row and column, are lifted
    with their depth, moved into camera j and projected. One is visible in j when it lands
    in front of camera j, inside image j, on a pixel (the nearest) with valid depth that
    agrees with its own depth within ``tolerance`` (relative), i.e. when nothing hides it.

    Parameters
    ----------
    depth_i, depth_j : numpy.ndarray
        (H, W) metric z-depths, 0 = no measurement.
    K : numpy.ndarray
        (3, 3) intrinsics shared by both views.
    R_i, t_i, R_j, t_j : numpy.ndarray
        (3, 3) and (3,) world-to-camera poses (OpenCV axes), in the depths' unit.
    stride : int
        Spacing of the sampled pixels of view i.
    tolerance : float
        Relative depth agreement for visibility.

    Returns
    -------
    float
        Visible samples over valid samples of view i, in [0, 1] (0 without valid samples).
    """
    z = depth_i[stride // 2::stride, stride // 2::stride]
    valid = z > 0
    if not valid.any():
        return 0.0
    v, u = np.nonzero(valid)
    # Rays of the sampled pixels only: all of them cost more than the test itself.
    pix = np.stack([u * stride + stride // 2, v * stride + stride // 2, np.ones_like(u)], axis=1)
    rays = pix @ np.linalg.inv(K).T
    R_ij = R_j @ R_i.T
    X = (rays * z[valid, None]) @ R_ij.T + (t_j - R_ij @ t_i)
    front = X[:, 2] > 1e-9
    X = X[front]
    uv = X @ K.T
    u = np.rint(uv[:, 0] / uv[:, 2])
    v = np.rint(uv[:, 1] / uv[:, 2])
    hj, wj = depth_j.shape
    inside = (u >= 0) & (u < wj) & (v >= 0) & (v < hj)
    seen = depth_j[v[inside].astype(np.int64), u[inside].astype(np.int64)]
    agree = (seen > 0) & (np.abs(X[inside, 2] - seen) <= tolerance * seen)
    return float(agree.sum() / valid.sum())


def split_positions(n_frames: int, split: str) -> range:
    """Trajectory indices a split may use: ``tune`` the first ``ceil(N / 2)``, ``report`` the
    rest, ``all`` every one."""
    half = (n_frames + 1) // 2
    if split == "tune":
        return range(0, half)
    if split == "report":
        return range(half, n_frames)
    if split == "all":
        return range(0, n_frames)
    raise InvalidInput(f"unknown split {split!r}; choose one of {', '.join(SPLITS)}")


def select_pairs(candidates: Sequence[tuple[int, int]], n: int) -> list[tuple[int, int]]:
    """Pick ``n`` pairs spread over the sequence, deterministically.

    Greedy: each step takes the candidate with the most frames not used yet, then the one
    whose most used frame was used least, then the one whose frames lie farthest (in sequence
    order) from the used frames, then the first in ``(i, j)`` order.

    Parameters
    ----------
    candidates : sequence of (int, int)
        Pairs of trajectory indices.
    n : int
        How many to pick (fewer when there are fewer candidates).

    Returns
    -------
    list of (int, int)
        In the order picked.
    """
    remaining = sorted({(min(p), max(p)) for p in candidates})
    used: Counter[int] = Counter()
    chosen: list[tuple[int, int]] = []
    while remaining and len(chosen) < n:
        def key(pair: tuple[int, int]) -> tuple[int, int, float, tuple[int, int]]:
            new = sum(f not in used for f in pair)
            gap = min((abs(f - g) for f in pair for g in used), default=math.inf)
            return (-new, max(used[f] for f in pair), -gap, pair)

        best = min(remaining, key=key)
        remaining.remove(best)
        chosen.append(best)
        used.update(best)
    return chosen


def select_views(positions: Sequence[int], k: int, angles: np.ndarray, overlap: np.ndarray,
                 centres: np.ndarray, min_overlap: float) -> list[int]:
    """Pick ``k`` frames spread by rotation whose overlap graph is connected.

    From every start frame, frames are added greedily: among the frames that overlap an
    already chosen one by at least ``min_overlap``, the one whose smallest rotation to the
    chosen frames is largest (ties: the larger smallest camera-centre distance, then the first).
    The set kept is the one with the largest smallest pairwise rotation (ties: centre distance,
    then the earliest start).

    Parameters
    ----------
    positions : sequence of int
        Trajectory indices allowed.
    k : int
        Frames to pick (at least 2).
    angles : numpy.ndarray
        (N, N) pairwise rotation angles in degrees (:func:`rotation_angles`).
    overlap : numpy.ndarray
        (N, N) mutual overlaps (only the entries among ``positions`` are read).
    centres : numpy.ndarray
        (N, 3) camera centres in the world frame.
    min_overlap : float
        Overlap that links two frames.

    Returns
    -------
    list of int
        Sorted trajectory indices.

    Raises
    ------
    InvalidInput
        When no start frame reaches ``k`` connected frames.
    """
    pos = np.asarray(positions, dtype=np.int64)
    dist = np.linalg.norm(centres[:, None] - centres[None], axis=-1)
    best: tuple[float, float] | None = None
    best_set: list[int] = []
    for start in pos:
        chosen = [int(start)]
        while len(chosen) < k:
            held = np.array(chosen)
            rest = pos[~np.isin(pos, held)]
            linked = rest[(overlap[np.ix_(rest, held)] >= min_overlap).any(axis=1)]
            if not linked.size:
                break
            spread = angles[np.ix_(linked, held)].min(axis=1)
            gap = dist[np.ix_(linked, held)].min(axis=1)
            # lexsort's last key is the primary one; ties go to the first frame.
            chosen.append(int(linked[np.lexsort((linked, -gap, -spread))[0]]))
        if len(chosen) < k:
            continue
        sub = np.ix_(chosen, chosen)
        off = ~np.eye(k, dtype=bool)
        score = (float(angles[sub][off].min()), float(dist[sub][off].min()))
        if best is None or score > best:
            best, best_set = score, sorted(chosen)
    if best is None:
        raise InvalidInput(f"no {k} frames of the split form a connected overlap graph "
                           f"(overlap >= {min_overlap}); lower --min-overlap or --views")
    return best_set


def parse_pairs(spec: str | Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """Frame-id pairs from ``"i-j,k-l"`` (or pairs already parsed).

    Raises
    ------
    InvalidInput
        Naming ``--pairs`` when the text is malformed or a pair repeats a frame.
    """
    if not isinstance(spec, str):
        pairs = [(int(a), int(b)) for a, b in spec]
    else:
        pairs = []
        for item in spec.split(","):
            parts = item.strip().split("-")
            try:
                if len(parts) != 2:
                    raise ValueError
                pairs.append((int(parts[0]), int(parts[1])))
            except ValueError:
                raise InvalidInput(f"--pairs {spec!r}: expected frame-id pairs like 3-40,12-60"
                                   ) from None
    for a, b in pairs:
        if a == b:
            raise InvalidInput(f"--pairs: pair {a}-{b} uses one frame twice")
    if not pairs:
        raise InvalidInput("--pairs: no pair given")
    return pairs


def _mutual_overlaps(seq: PosedSequence, pairs: Sequence[tuple[int, int]],
                     depths: dict[int, np.ndarray], overlap: np.ndarray) -> None:
    """Fill ``overlap[i, j]`` and ``overlap[j, i]`` with the smaller of the two directions."""
    for i, j in pairs:
        for k in (i, j):
            if k not in depths:
                depths[k] = seq.depth(k)
        o = min(view_overlap(depths[i], depths[j], seq.K, seq.R[i], seq.t[i], seq.R[j],
                             seq.t[j]),
                view_overlap(depths[j], depths[i], seq.K, seq.R[j], seq.t[j], seq.R[i],
                             seq.t[i]))
        overlap[i, j] = overlap[j, i] = o


def choose_view_sets(seq: PosedSequence, split: str = "all", n: int = 10,
                     views: int | None = None, pairs: str | Sequence[tuple[int, int]] | None = None,
                     min_angle: float = 20.0, max_angle: float = 40.0,
                     min_overlap: float = 0.4) -> tuple[list[list[int]], dict[str, Any],
                                                        np.ndarray, np.ndarray]:
    """The view sets to evaluate, chosen from the ground truth (module docstring).

    Returns
    -------
    sets : list of list of int
        Trajectory indices of each set.
    selection : dict
        How they were chosen: ``split`` (``"given"`` for given pairs), ``frames`` (first and
        last id the split allows), ``candidates`` (pairs passing both filters; pairs mode),
        ``rule``.
    angles : numpy.ndarray
        (N, N) true rotation angles, degrees.
    overlap : numpy.ndarray
        (N, N) mutual overlaps, NaN where not computed.
    """
    n_frames = len(seq)
    allowed = split_positions(n_frames, split)
    angles = rotation_angles(seq.R)
    overlap = np.full((n_frames, n_frames), np.nan)
    np.fill_diagonal(overlap, 1.0)
    depths: dict[int, np.ndarray] = {}
    if pairs is not None:
        chosen = [(seq.position(a), seq.position(b)) for a, b in parse_pairs(pairs)]
        _mutual_overlaps(seq, chosen, depths, overlap)
        return [list(p) for p in chosen], {"split": "given", "rule": "given pairs"}, angles, \
            overlap
    selection: dict[str, Any] = {"split": split}
    if len(allowed):
        selection["frames"] = [int(seq.ids[allowed[0]]), int(seq.ids[allowed[-1]])]
    if views is not None:
        if views < 2:
            raise InvalidInput(f"--views must be at least 2, got {views}")
        pos = list(allowed)
        if len(pos) < views:
            raise InvalidInput(f"split {split!r} has {len(pos)} frames, fewer than --views "
                               f"{views}")
        _mutual_overlaps(seq, [(i, j) for i in pos for j in pos if i < j], depths, overlap)
        centres = -np.einsum("nji,nj->ni", seq.R, seq.t)
        members = select_views(pos, views, angles, overlap, centres, min_overlap)
        selection["rule"] = (f"{views} frames spread by rotation, connected by overlap >= "
                             f"{min_overlap}")
        return [members], selection, angles, overlap
    if not 0 <= min_angle <= max_angle:
        raise InvalidInput(f"need 0 <= --min-angle <= --max-angle, got {min_angle}, {max_angle}")
    by_angle = [(i, j) for i in allowed for j in allowed
                if i < j and min_angle <= angles[i, j] <= max_angle]
    _mutual_overlaps(seq, by_angle, depths, overlap)
    candidates = [(i, j) for i, j in by_angle if overlap[i, j] >= min_overlap]
    selection.update(candidates=len(candidates),
                     rule=f"rotation {min_angle:g}-{max_angle:g} deg, overlap >= "
                          f"{min_overlap:g}, spread greedily")
    if not candidates:
        raise InvalidInput(f"no pair of split {split!r} has a rotation of {min_angle:g}-"
                           f"{max_angle:g} degrees and an overlap of at least {min_overlap:g}")
    return [list(p) for p in select_pairs(candidates, n)], selection, angles, overlap
