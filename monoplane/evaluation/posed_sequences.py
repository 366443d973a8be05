"""Sparse-view registration on a posed RGB-D sequence (``monoplane eval --multiview --data``).

A sequence is a folder laid out like a Redwood-format RGB-D capture (e.g. the ICL-NUIM living
room):

* ``image/``: colour frames (``.jpg``/``.png``), sorted by name;
* ``depth/``: one depth map per image (16-bit ``.png`` divided by ``depth_scale``, or ``.npy``),
  sorted by name, 0 = no measurement;
* ``trajectory.log``: per frame, camera-to-world 4x4 in metres (Redwood ``.log``, read by
  :func:`monoplane.io.frames.read_redwood_log`); frame id ``k`` is the ``k``-th image and depth;
* ``intrinsics.json`` (optional): ``{"fx", "fy", "cx", "cy"}``, used when no intrinsics are
  given.

Protocol (see ``docs/multiview.md``, "Evaluating on a posed RGB-D sequence"):

1. **View sets from the ground truth.** A candidate pair has a relative rotation within
   ``[min_angle, max_angle]`` and a mutual overlap of at least ``min_overlap``
   (:func:`view_overlap`). ``n`` pairs are picked greedily, preferring frames not used yet and
   then frames far (in sequence order) from the used ones (:func:`select_pairs`). With
   ``views = K`` one set of K frames is chosen instead, spread by rotation over a connected
   overlap graph (:func:`select_views`), and every pair in it is scored.
2. **Splits.** ``tune`` holds the first ``ceil(N / 2)`` frames of the trajectory, ``report``
   the others; a pair or set belongs to a split when all its frames do (``all``: no limit).
3. **Modes.** ``rgbd`` gives each view its metric depth. The monocular modes corrupt it as
   a network errs, with the synthetic scenes' corruption levels (``mild``, ``strong``;
   :mod:`monoplane.synth.corrupt`): an unknown scale, a range distortion, a smooth warp,
   blurred occlusion edges and pixel noise, drawn per frame from ``(seed, frame id)`` and
   marked relative. ``mono`` also gives the network's normals: the project's normal
   estimator on the true depth, then blurred across creases, turned by a few degrees and
   noisy as the same level says; ``mono-depth`` gives the corrupted depth alone (as a
   depth-only network does). ``network`` gives no depth at all: the pipeline's cue provider
   predicts the cues from the image. Missing normals are left to the cue provider, which
   estimates them from the depth it is given (the ``given`` provider by default).
4. **The product path.** Each set runs through
   :func:`monoplane.multiview.reconstruct_multiview` with the intrinsics held fixed; a run
   that raises a :class:`~monoplane.errors.MonoplaneError` registers none of its views.
5. **Scores.** A set's poses are relative, so its first registered view is the reference and a
   set of K views has K - 1 views to register. Over every pair of views in a set: whether both
   are registered, then the rotation error and the translation-direction error of their
   relative pose (degrees), and whether it is *correct* (both below thresholds). Each view's
   registration method (``sfm``, ``origin``, ``features``, ``planes``, ...; ``none`` when left
   out) is counted as an opaque string.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from monoplane.datamodel import Frame
from monoplane.errors import InvalidInput, MonoplaneError
from monoplane.evaluation.twoview import relative_pose_error
from monoplane.io.frames import load_frame, read_depth, read_intrinsics, read_redwood_log
from monoplane.geometry.normals import normals_from_depth
from monoplane.synth.corrupt import LEVEL_PARAMS, corrupt_depth, corrupt_normals

if TYPE_CHECKING:
    from monoplane.multiview import MultiviewResult
    from monoplane.host.pipeline import Pipeline

#: What each view gets (module docstring, step 3).
MODES: tuple[str, ...] = ("rgbd", "mono", "mono-depth", "network")
#: ``--mode`` values that run several modes; ``both`` is the deprecated name of rgbd + mono.
MODE_GROUPS: dict[str, tuple[str, ...]] = {"all": ("rgbd", "mono", "mono-depth"),
                                           "both": ("rgbd", "mono")}
#: Corruption levels of the monocular modes (:data:`monoplane.synth.corrupt.LEVEL_PARAMS`).
LEVELS: tuple[str, ...] = ("mild", "strong")
#: Modes whose depth is the corrupted sensor depth.
MONOCULAR_MODES: tuple[str, ...] = ("mono", "mono-depth")
SPLITS: tuple[str, ...] = ("tune", "report", "all")
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png")
DEPTH_SUFFIXES = (".png", ".npy")
#: Pixel spacing of the overlap test's samples in the source view (80x60 at 640x480).
OVERLAP_STRIDE = 8
#: Relative depth difference within which a lifted pixel is visible in the other view.
VISIBILITY_TOLERANCE = 0.05
#: Method recorded for a view without a pose.
UNREGISTERED = "none"


@dataclass
class PosedSequence:
    """A posed RGB-D sequence on disk.

    Attributes
    ----------
    root : Path
        The folder.
    ids : numpy.ndarray
        (N,) int64 frame ids of the trajectory, in its order.
    images, depths : list of Path
        Per trajectory entry, its colour image and depth file.
    R : numpy.ndarray
        (N, 3, 3) float64 world-to-camera rotations (``x_cam = R x_world + t``, OpenCV axes).
    t : numpy.ndarray
        (N, 3) float64 world-to-camera translations, metres.
    K : numpy.ndarray
        (3, 3) float64 intrinsics in pixels, shared by all frames.
    depth_scale : float
        Divisor of the depth files' values (1000 for millimetre PNGs).
    """

    root: Path
    ids: np.ndarray
    images: list[Path]
    depths: list[Path]
    R: np.ndarray
    t: np.ndarray
    K: np.ndarray
    depth_scale: float

    def __len__(self) -> int:
        return len(self.ids)

    def position(self, frame_id: int) -> int:
        """Index into the trajectory of ``frame_id``."""
        hits = np.flatnonzero(self.ids == frame_id)
        if not hits.size:
            raise InvalidInput(f"frame {frame_id} is not in {self.root / 'trajectory.log'}")
        return int(hits[0])

    def depth(self, k: int) -> np.ndarray:
        """(H, W) float32 metric depth of trajectory entry ``k``, 0 = no measurement."""
        return read_depth(self.depths[k], self.depth_scale)


def sequence_intrinsics(data_dir: str | Path, intrinsics: str | Path | np.ndarray | None
                        ) -> np.ndarray:
    """(3, 3) intrinsics: ``intrinsics`` (``"fx,fy,cx,cy"``, a JSON file or a matrix), else
    ``data_dir/intrinsics.json``.

    Raises
    ------
    InvalidInput
        When neither is there.
    """
    if intrinsics is None:
        fallback = Path(data_dir) / "intrinsics.json"
        if not fallback.is_file():
            raise InvalidInput(f"--data {data_dir} has no intrinsics.json; pass --intrinsics "
                               "fx,fy,cx,cy or a K.json")
        return read_intrinsics(fallback)
    if isinstance(intrinsics, np.ndarray):
        K = np.asarray(intrinsics, dtype=np.float64)
        if K.shape != (3, 3):
            raise InvalidInput(f"intrinsics must be a 3x3 matrix, got shape {K.shape}")
        return K
    return read_intrinsics(intrinsics)


def _listing(folder: Path, suffixes: tuple[str, ...], what: str) -> list[Path]:
    if not folder.is_dir():
        raise InvalidInput(f"{folder} is missing: a posed sequence keeps its {what} there")
    files = sorted(f for f in folder.iterdir() if f.suffix.lower() in suffixes)
    if not files:
        raise InvalidInput(f"{folder} holds no {what} ({', '.join(suffixes)})")
    return files


def load_posed_sequence(data_dir: str | Path, intrinsics: str | Path | np.ndarray | None = None,
                        depth_scale: float = 1000.0) -> PosedSequence:
    """Read a sequence's layout and trajectory (images and depth are read when needed).

    Parameters
    ----------
    data_dir : str or Path
        Folder with ``image/``, ``depth/`` and ``trajectory.log`` (module docstring).
    intrinsics : str, Path or numpy.ndarray, optional
        See :func:`sequence_intrinsics`.
    depth_scale : float
        Divisor of the depth values (1000 for millimetres).

    Raises
    ------
    InvalidInput
        Naming the missing or inconsistent file or folder.
    """
    root = Path(data_dir)
    if not root.is_dir():
        raise InvalidInput(f"--data {root} is not a folder")
    if not depth_scale > 0:
        raise InvalidInput(f"--depth-scale must be positive, got {depth_scale}")
    K = sequence_intrinsics(root, intrinsics)
    images = _listing(root / "image", IMAGE_SUFFIXES, "colour images")
    depths = _listing(root / "depth", DEPTH_SUFFIXES, "depth maps")
    if len(images) != len(depths):
        raise InvalidInput(f"{root}: {len(images)} images but {len(depths)} depth maps")
    ids, c2w = read_redwood_log(root / "trajectory.log")
    out = ids[(ids < 0) | (ids >= len(images))]
    if out.size:
        raise InvalidInput(f"{root / 'trajectory.log'}: frame {out[0]} has no image "
                           f"({len(images)} in {root / 'image'})")
    R = np.transpose(c2w[:, :3, :3], (0, 2, 1))
    t = -np.einsum("nij,nj->ni", R, c2w[:, :3, 3])
    return PosedSequence(root=root, ids=ids, images=[images[i] for i in ids],
                         depths=[depths[i] for i in ids], R=R, t=t, K=K,
                         depth_scale=float(depth_scale))


# --------------------------------------------------------------------------------------------
# Choosing view sets from the ground truth


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


# --------------------------------------------------------------------------------------------
# Frames as the product sees them


def mode_list(mode: str) -> list[str]:
    """The modes ``--mode`` runs: one of :data:`MODES` or a group of :data:`MODE_GROUPS`.

    Raises
    ------
    InvalidInput
        On an unknown name, listing the valid ones.
    """
    if mode in MODE_GROUPS:
        return list(MODE_GROUPS[mode])
    if mode not in MODES:
        raise InvalidInput(f"unknown mode {mode!r}; choose one of {', '.join(MODES)}, all")
    return [mode]


def check_level(level: str) -> None:
    """Raise :class:`InvalidInput` unless ``level`` is one of :data:`LEVELS`."""
    if level not in LEVELS:
        raise InvalidInput(f"unknown corruption level {level!r} for a posed sequence; choose "
                           f"one of {', '.join(LEVELS)} (the sensor depth itself is --mode rgbd)")


def monocular_cues(depth: np.ndarray, K: np.ndarray, level: str, rng: np.random.Generator,
                   with_normals: bool) -> tuple[np.ndarray, np.ndarray | None, float]:
    """Cues as a monocular network might give them, from a view's sensor depth.

    The depth goes through :func:`monoplane.synth.corrupt.corrupt_depth` at ``level``. With
    ``with_normals`` the network's normals are the project's estimator
    (:func:`~monoplane.geometry.normals.normals_from_depth`, default window) on the *true*
    depth, then :func:`~monoplane.synth.corrupt.corrupt_normals`: a network's normals do not
    inherit its depth's warp, but are blurred across creases, a few degrees off and noisy.

    Parameters
    ----------
    depth : numpy.ndarray
        (H, W) metric z-depth, 0 = no measurement (stays 0, and has no normal).
    K : numpy.ndarray
        (3, 3) intrinsics in pixels.
    level : {"mild", "strong"}
        Corruption level (:data:`monoplane.synth.corrupt.LEVEL_PARAMS`).
    rng : numpy.random.Generator
        Source of every draw: the depth's first, then the normals', so a frame's depth is the
        same with and without normals.
    with_normals : bool
        Also return the network's normals.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray or None, float)
        (H, W) float32 relative depth, (H, W, 3) float32 unit normals in the camera frame
        (OpenCV axes, facing the camera, zero where there is none) or None, and the unknown
        scale drawn.
    """
    check_level(level)
    params = LEVEL_PARAMS[level]
    corrupted, scale = corrupt_depth(depth, params, rng)
    if not with_normals:
        return corrupted, None, scale
    clean = normals_from_depth(depth, K)
    normals = corrupt_normals(np.where((depth > 0)[..., None], clean, 0.0), K, params, rng)
    return corrupted, normals, scale


def sequence_frame(seq: PosedSequence, k: int, mode: str, seed: int = 0,
                   level: str = "mild") -> Frame:
    """Trajectory entry ``k`` as the ``monoplane multiview`` command line would load it.

    ``rgbd``: its metric depth; ``mono`` / ``mono-depth``: :func:`monocular_cues` at
    ``level`` with / without the network's normals, drawn from the generator seeded by
    ``(seed, frame id)`` (so a frame looks the same in every set, and has the same depth in
    both modes), marked relative; ``network``: the image alone. Normals not given are left to
    the cue provider.
    """
    if mode not in MODES:
        raise InvalidInput(f"unknown mode {mode!r}; choose one of {', '.join(MODES)}")
    # As --intrinsics text; repr() of a float reads back to the same float.
    spec = ",".join(repr(float(x)) for x in (seq.K[0, 0], seq.K[1, 1], seq.K[0, 2], seq.K[1, 2]))
    if mode == "network":
        return load_frame(seq.images[k], intrinsics=spec)
    monocular = mode in MONOCULAR_MODES
    frame = load_frame(seq.images[k], depth=seq.depths[k], intrinsics=spec,
                       depth_scale=seq.depth_scale,
                       depth_kind="relative" if monocular else "metric")
    if not monocular:
        return frame
    rng = np.random.default_rng([seed, int(seq.ids[k])])
    depth, normals, scale = monocular_cues(frame.depth, frame.K, level,  # type: ignore[arg-type]
                                           rng, with_normals=mode == "mono")
    p = LEVEL_PARAMS[level]
    notes = [*frame.notes, f"evaluation: {level} monocular-like depth (unknown scale "
                           f"{scale:.3g}, warp up to {100 * p.warp:.0f} % in log-depth, edges "
                           f"blurred, {100 * p.depth_noise:.1f} % noise)"]
    if normals is not None:
        notes.append(f"evaluation: {level} network-like normals (from the true depth, blurred, "
                     f"turned by up to {p.normal_rotation_deg:g} deg, noisy)")
    return frame.with_(depth=depth, normals=normals, notes=notes)


# --------------------------------------------------------------------------------------------
# Running and scoring one view set


def score_view_set(seq: PosedSequence, members: Sequence[int], result: MultiviewResult | None,
                   error: str | None, overlap: np.ndarray | None, angles: np.ndarray,
                   rotation_threshold: float, translation_threshold: float) -> dict[str, Any]:
    """One view set's row: registration per view and the relative pose of every pair.

    Parameters
    ----------
    seq : PosedSequence
        Ground truth.
    members : sequence of int
        Trajectory indices of the set, in the order given to the pipeline.
    result : MultiviewResult or None
        The run's output; None when it raised (``error``).
    error : str or None
        The run's error message.
    overlap : numpy.ndarray or None
        (N, N) mutual overlaps, for the pair rows (NaN where not computed).
    angles : numpy.ndarray
        (N, N) true rotation angles in degrees.
    rotation_threshold, translation_threshold : float
        A pair is correct when both errors are below these (degrees).

    Returns
    -------
    dict
        ``frames`` (ids), ``methods`` (per view, the registration method or ``"none"``),
        ``views_registered`` / ``views_to_register``, ``registered`` (every view), ``error``,
        and ``pairs``: per pair ``frames``, ``rotation_deg`` (true), ``baseline_m``,
        ``overlap``, ``registered``, ``rotation_error_deg``, ``translation_error_deg``,
        ``correct``, and the errors before the adjuster (``fused_rotation_error_deg``,
        ``fused_translation_error_deg``).
    """
    members = list(members)
    placed: dict[int, int] = {}
    methods = [UNREGISTERED] * len(members)
    if result is not None:
        for slot, v in enumerate(result.frame_indices):
            placed[v] = slot
            methods[v] = str(result.registration[slot].get("method", "sfm"))
    pairs = []
    for a in range(len(members)):
        for b in range(a + 1, len(members)):
            i, j = members[a], members[b]
            c_i, c_j = -seq.R[i].T @ seq.t[i], -seq.R[j].T @ seq.t[j]
            row: dict[str, Any] = {
                "frames": [int(seq.ids[i]), int(seq.ids[j])],
                "rotation_deg": float(angles[i, j]),
                "baseline_m": float(np.linalg.norm(c_j - c_i)),
                "overlap": float(overlap[i, j]) if overlap is not None else float("nan"),
                "registered": a in placed and b in placed,
                "rotation_error_deg": float("nan"), "translation_error_deg": float("nan"),
                "correct": False, "fused_rotation_error_deg": float("nan"),
                "fused_translation_error_deg": float("nan"),
            }
            if row["registered"]:
                truth = (seq.R[i], seq.t[i], seq.R[j], seq.t[j])
                cams = result.scene.cameras  # type: ignore[union-attr]
                rot, trans = relative_pose_error(cams[placed[a]], cams[placed[b]], *truth)
                row.update(rotation_error_deg=rot, translation_error_deg=trans,
                           correct=rot < rotation_threshold and trans < translation_threshold)
                # The poses before the adjuster: what registration alone gave.
                fused = (result.fused or result.scene).cameras  # type: ignore[union-attr]
                rot, trans = relative_pose_error(fused[placed[a]], fused[placed[b]], *truth)
                row.update(fused_rotation_error_deg=rot, fused_translation_error_deg=trans)
            pairs.append(row)
    return {
        "frames": [int(seq.ids[k]) for k in members],
        "methods": methods,
        "views_registered": max(len(placed) - 1, 0),
        "views_to_register": len(members) - 1,
        "registered": len(placed) == len(members),
        "error": error,
        "pairs": pairs,
    }


def run_view_set(seq: PosedSequence, members: Sequence[int], mode: str, pipe: Pipeline,
                 seed: int = 0, level: str = "mild"
                 ) -> tuple[MultiviewResult | None, str | None, float]:
    """Reconstruct one view set with the product's multi-view driver (one process).

    Returns
    -------
    (MultiviewResult or None, str or None, float)
        The result, or None and the one-line error when the run raised a
        :class:`~monoplane.errors.MonoplaneError`; and the run's wall seconds.
    """
    from monoplane.multiview import reconstruct_multiview

    frames = [sequence_frame(seq, k, mode, seed, level) for k in members]
    start = time.perf_counter()
    try:
        result = reconstruct_multiview(frames, pipe, workers=1)
    except MonoplaneError as exc:
        message = (str(exc).splitlines() or [type(exc).__name__])[0]
        return None, message, time.perf_counter() - start
    return result, None, time.perf_counter() - start


def summarise(sets: list[dict[str, Any]]) -> dict[str, Any]:
    """Totals of one mode over its set rows (see :func:`score_view_set`)."""
    pairs = [p for s in sets for p in s["pairs"]]
    done = [p for p in pairs if p["registered"]]

    def stats(key: str) -> dict[str, float]:
        x = [p[key] for p in done]
        if not x:
            return {"median": float("nan"), "mean": float("nan")}
        return {"median": float(np.median(x)), "mean": float(np.mean(x))}

    return {
        "views_registered": sum(s["views_registered"] for s in sets),
        "views_to_register": sum(s["views_to_register"] for s in sets),
        "sets_registered": sum(s["registered"] for s in sets),
        "sets": len(sets),
        "pairs_registered": len(done),
        "pairs_correct": sum(p["correct"] for p in pairs),
        "pairs": len(pairs),
        "rotation_error_deg": stats("rotation_error_deg"),
        "translation_error_deg": stats("translation_error_deg"),
        "fused_rotation_error_deg": stats("fused_rotation_error_deg"),
        "fused_translation_error_deg": stats("fused_translation_error_deg"),
        "methods": dict(sorted(Counter(m for s in sets for m in s["methods"]).items())),
        "failures": [f"{'-'.join(map(str, s['frames']))}: {s['error']}" for s in sets
                     if s["error"]],
    }


# --------------------------------------------------------------------------------------------
# The evaluation


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


def evaluate_posed_sequence(data_dir: str | Path,
                            intrinsics: str | Path | np.ndarray | None = None,
                            mode: str = "all", split: str = "all", n: int = 10,
                            views: int | None = None,
                            pairs: str | Sequence[tuple[int, int]] | None = None,
                            preset: str = "monoplane", overrides: list[str] | None = None,
                            depth_scale: float = 1000.0, min_angle: float = 20.0,
                            max_angle: float = 40.0, min_overlap: float = 0.4,
                            rotation_threshold: float = 5.0,
                            translation_threshold: float = 10.0, seed: int = 0,
                            level: str = "mild", progress: bool = False) -> dict[str, Any]:
    """Score sparse-view registration on a posed RGB-D sequence.

    Parameters
    ----------
    data_dir : str or Path
        The sequence folder (module docstring).
    intrinsics : str, Path or numpy.ndarray, optional
        ``"fx,fy,cx,cy"``, a JSON file or a (3, 3) matrix; default ``data_dir/intrinsics.json``.
    mode : {"rgbd", "mono", "mono-depth", "network", "all"}
        Which cues the views get (module docstring); ``all`` runs rgbd, mono and mono-depth
        (``both``, deprecated: rgbd and mono).
    split : {"tune", "report", "all"}
        Which frames the sets may use.
    n : int
        Pairs to pick (pairs mode).
    views : int, optional
        Pick one set of this many frames instead of pairs (every pair in it is scored).
    pairs : str or sequence of (int, int), optional
        Evaluate these frame-id pairs (``"i-j,k-l"``) instead of choosing.
    preset, overrides : str, list of str
        Pipeline; ``cues.plugin=given`` comes first, so overrides may replace it (``network``
        mode needs a provider that predicts depth from the image, e.g. ``cues.plugin=onnx``).
    depth_scale : float
        Divisor of the depth files' values.
    min_angle, max_angle : float
        True relative rotation of candidate pairs, degrees.
    min_overlap : float
        Mutual overlap of candidate pairs, and the link of the ``views`` overlap graph.
    rotation_threshold, translation_threshold : float
        A pair is correct when its rotation and translation-direction errors are below these
        (degrees).
    seed : int
        Seed of the monocular-like cues (with the frame id).
    level : {"mild", "strong"}
        Corruption level of the monocular modes (ignored by ``rgbd`` and ``network``).
    progress : bool
        Progress bar on stderr.

    Raises
    ------
    InvalidInput
        On a bad argument, or in ``network`` mode when the cue provider cannot give the first
        view its cues (e.g. ``given`` without depth, or a missing model file).

    Returns
    -------
    dict
        ``settings``, ``selection`` (see :func:`choose_view_sets`) and ``modes``: per mode,
        :func:`summarise`'s totals plus ``rows`` (per set: :func:`score_view_set`'s row with
        ``time_s``).
    """
    from tqdm import tqdm

    from monoplane.multiview import hold_intrinsics_fixed
    from monoplane.host.pipeline import Pipeline

    modes = mode_list(mode)
    if any(m in MONOCULAR_MODES for m in modes):
        check_level(level)
    if n < 1:
        raise InvalidInput(f"--n must be at least 1, got {n}")
    for name, value in (("--rotation-threshold", rotation_threshold),
                        ("--translation-threshold", translation_threshold)):
        if not value > 0:
            raise InvalidInput(f"{name} must be positive, got {value}")
    seq = load_posed_sequence(data_dir, intrinsics, depth_scale)
    # Build the pipeline before the costly selection so a bad --set fails at once.
    pipe = Pipeline.from_preset(preset, overrides=["cues.plugin=given", *(overrides or [])])
    fixed = hold_intrinsics_fixed(pipe)
    sets, selection, angles, overlap = choose_view_sets(seq, split, n, views, pairs, min_angle,
                                                        max_angle, min_overlap)
    out: dict[str, Any] = {
        "settings": {"data": str(seq.root), "frames": len(seq), "mode": mode, "split": split,
                     "n": n, "views": views, "preset": preset, "overrides": list(overrides or []),
                     "intrinsics": [float(seq.K[0, 0]), float(seq.K[1, 1]), float(seq.K[0, 2]),
                                    float(seq.K[1, 2])],
                     "intrinsics_fixed": fixed, "depth_scale": seq.depth_scale,
                     "min_angle": min_angle, "max_angle": max_angle, "min_overlap": min_overlap,
                     "rotation_threshold": rotation_threshold,
                     "translation_threshold": translation_threshold, "seed": seed,
                     "level": level, "modes": modes},
        "selection": {**selection, "sets": [[int(seq.ids[k]) for k in s] for s in sets]},
        "modes": {},
    }
    if "network" in modes:
        probe_network_cues(seq, sets[0][0], pipe)
    for m in modes:
        rows = []
        for members in tqdm(sets, desc=f"{m} view sets", disable=not progress):
            result, error, seconds = run_view_set(seq, members, m, pipe, seed, level)
            row = score_view_set(seq, members, result, error, overlap, angles,
                                 rotation_threshold, translation_threshold)
            row["time_s"] = seconds
            rows.append(row)
        out["modes"][m] = {**summarise(rows), "rows": rows}
    return out


def probe_network_cues(seq: PosedSequence, k: int, pipe: Pipeline) -> None:
    """Give trajectory entry ``k``, image only, its cues once, so that a cue provider which
    cannot predict them fails the evaluation at once with its own message, not every set.

    Raises
    ------
    InvalidInput
        Naming ``--mode network``, the provider and its error.
    """
    from monoplane.stages.base import CueProvider

    frame = sequence_frame(seq, k, "network")
    try:
        pipe.prepare(frame)
    except MonoplaneError as exc:
        name = pipe.stage("cues", CueProvider).name
        message = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise InvalidInput(f"--mode network: cue provider {name!r} cannot predict cues from the "
                           f"image {seq.images[k]}: {message}; choose a predicting provider with "
                           f"--set cues.plugin=...") from exc


def _deg(x: float) -> str:
    return "-" if not math.isfinite(x) else f"{x:.2f}"


def format_posed_sequence(r: dict[str, Any]) -> str:
    """Human-readable summary and per-set table of :func:`evaluate_posed_sequence` output."""
    s, sel = r["settings"], r["selection"]
    span = f", frames {sel['frames'][0]}-{sel['frames'][1]}" if "frames" in sel else ""
    lines = [f"{s['data']}: {s['frames']} frames, split {sel['split']}{span}; "
             f"{len(sel['sets'])} view sets ({sel['rule']}"
             + (f", {sel['candidates']} candidate pairs" if "candidates" in sel else "") + ")",
             f"correct pair: rotation < {s['rotation_threshold']:g} deg and translation "
             f"direction < {s['translation_threshold']:g} deg; preset {s['preset']}"
             + (f"; monocular cues at level {s['level']}, seed {s['seed']}"
                if any(m in MONOCULAR_MODES for m in s["modes"]) else "")]
    for mode, res in r["modes"].items():
        rot, trans = res["rotation_error_deg"], res["translation_error_deg"]
        methods = ", ".join(f"{k} {v}" for k, v in res["methods"].items())
        lines += [
            "",
            f"[{mode}] views registered {res['views_registered']}/{res['views_to_register']} "
            f"(beyond each set's reference), sets fully registered "
            f"{res['sets_registered']}/{res['sets']}",
            f"[{mode}] pairs registered {res['pairs_registered']}/{res['pairs']}, correct "
            f"{res['pairs_correct']}/{res['pairs']}; rotation error {_deg(rot['median'])} median"
            f" / {_deg(rot['mean'])} mean, translation direction {_deg(trans['median'])} median"
            f" / {_deg(trans['mean'])} mean (deg, registered pairs)",
            f"[{mode}] before the adjuster: rotation error "
            f"{_deg(res['fused_rotation_error_deg']['median'])} median, translation direction "
            f"{_deg(res['fused_translation_error_deg']['median'])} median (deg)",
            f"[{mode}] methods per view: {methods}",
            f"{'set':<14} {'pair':<10} {'gt rot':>6} {'base m':>7} {'overlap':>7} "
            f"{'rot err':>8} {'dir err':>8}  ok  methods",
        ]
        for row in res["rows"]:
            name = "-".join(map(str, row["frames"]))
            for k, p in enumerate(row["pairs"]):
                lines.append(
                    f"{name if k == 0 else '':<14} {'-'.join(map(str, p['frames'])):<10} "
                    f"{p['rotation_deg']:6.1f} {p['baseline_m']:7.2f} "
                    f"{_deg(p['overlap']):>7} {_deg(p['rotation_error_deg']):>8} "
                    f"{_deg(p['translation_error_deg']):>8}  {'y' if p['correct'] else '-':>2}"
                    + (f"  {' '.join(row['methods'])}" if k == 0 else ""))
            if row["error"]:
                lines.append(f"{'':<14} failed: {row['error']}")
    return "\n".join(lines)
