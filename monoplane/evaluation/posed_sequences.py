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
   estimates them from the depth it is given (by default the provider that serves given
   depth, :data:`monoplane.host.config.GIVEN_CUES_PROVIDER`).
4. **The product path.** Each set runs through
   :func:`monoplane.multiview.reconstruct_multiview` with the intrinsics held fixed; a run
   that raises a :class:`~monoplane.errors.MonoplaneError` registers none of its views.
5. **Scores.** A set's poses are relative, so its first registered view is the reference and a
   set of K views has K - 1 views to register. Over every pair of views in a set: whether both
   are registered, then the rotation error and the translation-direction error of their
   relative pose (degrees), and whether it is *correct* (both below thresholds). Each view's
   registration method (``sfm``, ``origin``, ``features``, ``planes``, ...; ``none`` when left
   out) is counted as an opaque string.

The sequence and its frames are read by :mod:`~monoplane.evaluation.posed_frames`, the view
sets chosen by :mod:`~monoplane.evaluation.view_sets`; this module runs and scores them (and
re-exports their public names, which it used to define).
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from monoplane.contracts import CueProvider
from monoplane.errors import InvalidInput, MonoplaneError
from monoplane.evaluation.posed_frames import (
    DEPTH_SUFFIXES,
    IMAGE_SUFFIXES,
    LEVELS,
    MODE_GROUPS,
    MODES,
    MONOCULAR_MODES,
    PosedSequence,
    check_level,
    load_posed_sequence,
    mode_list,
    monocular_cues,
    sequence_frame,
    sequence_intrinsics,
)
from monoplane.evaluation.twoview import relative_pose_error
from monoplane.evaluation.view_sets import (
    OVERLAP_STRIDE,
    SPLITS,
    VISIBILITY_TOLERANCE,
    choose_view_sets,
    parse_pairs,
    rotation_angles,
    select_pairs,
    select_views,
    split_positions,
    view_overlap,
)
from monoplane.host.config import given_cues_overrides
from monoplane.host.pipeline import Pipeline
from monoplane.multiview import hold_intrinsics_fixed, reconstruct_multiview

if TYPE_CHECKING:
    from monoplane.host.pipeline import Pipeline
    from monoplane.multiview import MultiviewResult

__all__ = [
    "DEPTH_SUFFIXES", "IMAGE_SUFFIXES", "LEVELS", "MODES", "MODE_GROUPS", "MONOCULAR_MODES",
    "OVERLAP_STRIDE", "SPLITS", "UNREGISTERED", "VISIBILITY_TOLERANCE", "PosedSequence",
    "check_level", "choose_view_sets", "evaluate_posed_sequence", "format_posed_sequence",
    "load_posed_sequence", "mode_list", "monocular_cues", "parse_pairs", "probe_network_cues",
    "rotation_angles", "run_view_set", "score_view_set", "select_pairs", "select_views",
    "sequence_frame", "sequence_intrinsics", "split_positions", "summarise", "view_overlap",
]

#: Method recorded for a view without a pose.
UNREGISTERED = "none"


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
                            level: str = "mild", progress: bool = False,
                            depth_encoding: str = "scaled") -> dict[str, Any]:
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
        Pipeline; the cue provider that serves given depth comes first
        (:func:`monoplane.host.config.given_cues_overrides`), so overrides may replace it
        (``network`` mode needs one that predicts depth from the image, e.g.
        ``cues.plugin=onnx``).
    depth_scale : float
        Divisor of the depth files' values in the ``scaled`` encoding.
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
    depth_encoding : str
        How the depth files hold depth: ``"scaled"`` (divided by ``depth_scale``) or a
        dataset's own encoding (:mod:`monoplane.io.depth_encodings`).

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
    modes = _checked_modes(mode, level, n, rotation_threshold, translation_threshold)
    seq = load_posed_sequence(data_dir, intrinsics, depth_scale, depth_encoding)
    # Build the pipeline before the costly selection so a bad --set fails at once.
    pipe = Pipeline.from_preset(preset, overrides=given_cues_overrides(overrides))
    fixed = hold_intrinsics_fixed(pipe)
    sets, selection, angles, overlap = choose_view_sets(seq, split, n, views, pairs, min_angle,
                                                        max_angle, min_overlap)
    out: dict[str, Any] = {
        "settings": {"data": str(seq.root), "frames": len(seq), "mode": mode, "split": split,
                     "n": n, "views": views, "preset": preset, "overrides": list(overrides or []),
                     "intrinsics": [float(seq.K[0, 0]), float(seq.K[1, 1]), float(seq.K[0, 2]),
                                    float(seq.K[1, 2])],
                     "intrinsics_fixed": fixed, "depth_scale": seq.depth_scale,
                     "depth_encoding": seq.depth_encoding,
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
        rows = _mode_rows(seq, sets, m, pipe, seed, level, overlap, angles,
                          (rotation_threshold, translation_threshold), progress)
        out["modes"][m] = {**summarise(rows), "rows": rows}
    return out


def _mode_rows(seq: PosedSequence, sets: list[list[int]], mode: str, pipe: Pipeline, seed: int,
               level: str, overlap: np.ndarray, angles: np.ndarray,
               thresholds: tuple[float, float], progress: bool) -> list[dict[str, Any]]:
    """Run and score every view set in one mode: :func:`score_view_set`'s rows, each with
    its run's ``time_s``; ``thresholds`` are the rotation and translation thresholds."""
    from tqdm import tqdm

    rows = []
    for members in tqdm(sets, desc=f"{mode} view sets", disable=not progress):
        result, error, seconds = run_view_set(seq, members, mode, pipe, seed, level)
        row = score_view_set(seq, members, result, error, overlap, angles, *thresholds)
        row["time_s"] = seconds
        rows.append(row)
    return rows


def _checked_modes(mode: str, level: str, n: int, rotation_threshold: float,
                   translation_threshold: float) -> list[str]:
    """The modes ``mode`` runs (:func:`mode_list`), once the arguments of
    :func:`evaluate_posed_sequence` that need no data are checked.

    Raises
    ------
    InvalidInput
        Naming the bad option.
    """
    modes = mode_list(mode)
    if any(m in MONOCULAR_MODES for m in modes):
        check_level(level)
    if n < 1:
        raise InvalidInput(f"--n must be at least 1, got {n}")
    for name, value in (("--rotation-threshold", rotation_threshold),
                        ("--translation-threshold", translation_threshold)):
        if not value > 0:
            raise InvalidInput(f"{name} must be positive, got {value}")
    return modes


def probe_network_cues(seq: PosedSequence, k: int, pipe: Pipeline) -> None:
    """Give trajectory entry ``k``, image only, its cues once, so that a cue provider which
    cannot predict them fails the evaluation at once with its own message, not every set.

    Raises
    ------
    InvalidInput
        Naming ``--mode network``, the provider and its error.
    """
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
