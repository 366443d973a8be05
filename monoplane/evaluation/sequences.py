"""N-view evaluation on synthetic walk-throughs and stars (``eval --multiview --views N``).

For each sequence (:func:`monoplane.synth.sequence.generate_sequence`) it reports

* **registration**: views registered (by SfM or the fallback) out of N;
* **pose error over all pairs** of registered views: rotation angle of ``R_pred R_gtᵀ`` and
  translation-direction angle, degrees (:func:`~monoplane.evaluation.twoview.
  relative_pose_error`);
* **global planes** with any pixel, against the distinct true planes of the sequence and the
  distinct true planes *seen*: those covering at least ``ransac.min_support`` of the pixels
  (the area rule below) in at least one registered view (:func:`true_planes_seen`); and the
  **curved global planes**, those whose pixels lie mostly on non-planar ground truth
  (curved objects, label 0; :func:`curved_global_planes`);
* **cross-view consistency**: over the ground-truth planes seen in two or more registered
  views, the share whose views all give it the same global id. A view's id for a true plane is
  the global id covering most of its true mask. A view *sees* a true plane when the plane
  covers at least the single-view stage's smallest plane (``ransac.min_support`` of the
  pixels, the paper's 300 px at 256x192) and the majority of its mask is planar: a sliver
  smaller than that cannot be a plane of its own in that view, so it would only measure the
  detector's size threshold, and a missed plane is the single-view recall's business, not
  fusion's. ``consistency_all`` counts every view with a planar majority, however small the
  plane's area in it;
* **plane parameter error after similarity alignment**: the predicted world is mapped onto the
  true one by the similarity ``x_gt = s A x_pred + b`` fitted to the cameras (``A`` the
  rotation average of ``R_gt,kᵀ R_pred,k``, then ``s`` and ``b`` by least squares on the camera
  centres); each global plane is compared with the true plane it overlaps most (normal angle in
  degrees, offset difference in metres), before and after the adjuster.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from monoplane.datamodel import Scene
from monoplane.errors import InvalidInput, MonoplaneError
from monoplane.evaluation.twoview import relative_pose_error

if TYPE_CHECKING:
    from monoplane.multiview import MultiviewResult


def similarity_to_truth(R_pred: np.ndarray, c_pred: np.ndarray, R_gt: np.ndarray,
                        c_gt: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Similarity ``x_gt = s A x_pred + b`` aligning predicted cameras with the true ones.

    Parameters
    ----------
    R_pred, R_gt : numpy.ndarray
        (V, 3, 3) world-to-camera rotations.
    c_pred, c_gt : numpy.ndarray
        (V, 3) camera centres.

    Returns
    -------
    (float, numpy.ndarray, numpy.ndarray)
        ``s``, ``A`` (3, 3) and ``b`` (3,).
    """
    M = sum(rg.T @ rp for rg, rp in zip(R_gt, R_pred, strict=True))
    U, _, Vt = np.linalg.svd(M)
    A = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    p = (c_pred - c_pred.mean(0)) @ A.T
    g = c_gt - c_gt.mean(0)
    s = float((p * g).sum() / max((p * p).sum(), 1e-12))
    b = c_gt.mean(0) - s * A @ c_pred.mean(0)
    return s, A, b


def plane_errors(scene: Scene, views: list[Any], gt_planes: np.ndarray,
                 gt_links: list[dict[int, int]]) -> tuple[list[float], list[float]]:
    """Normal (deg) and offset (m) error of each global plane against its true plane."""
    R_pred = np.stack([c.R for c in scene.cameras])
    c_pred = np.stack([c.center for c in scene.cameras])
    R_gt = np.stack([v.R for v in views])
    c_gt = np.stack([-v.R.T @ v.t for v in views])
    s, A, b = similarity_to_truth(R_pred, c_pred, R_gt, c_gt)
    overlap: dict[int, np.ndarray] = {}
    for v, (rec, view) in enumerate(zip(scene.views, views, strict=True)):
        lut = np.full(int(rec.labels.max()) + 1, -1)
        for local, glob in scene.links[v].items():
            lut[local] = glob
        pred = lut[rec.labels].ravel()
        glut = np.full(int(view.gt_labels.max()) + 1, -1)
        for local, glob in gt_links[v].items():
            glut[local] = glob
        gt = glut[view.gt_labels].ravel()
        ok = (pred >= 0) & (gt >= 0)
        for g, t in zip(pred[ok], gt[ok], strict=True):
            overlap.setdefault(int(g), np.zeros(len(gt_planes)))[t] += 1
    normal_err, offset_err = [], []
    for g, counts in overlap.items():
        t = int(np.argmax(counts))
        n, d = scene.planes[g, :3], scene.planes[g, 3]
        # n·x + d = 0 with x = (y − b) / (s A) ⇒ (A n)·y + (s d − (A n)·b) = 0.
        n_gt_frame = A @ n
        d_gt_frame = s * d - n_gt_frame @ b
        ref = gt_planes[t]
        if n_gt_frame @ ref[:3] < 0:
            n_gt_frame, d_gt_frame = -n_gt_frame, -d_gt_frame
        normal_err.append(float(np.degrees(np.arccos(np.clip(n_gt_frame @ ref[:3], -1, 1)))))
        offset_err.append(float(abs(d_gt_frame - ref[3])))
    return normal_err, offset_err


def true_planes_seen(views: list[Any], gt_links: list[dict[int, int]],
                     min_area: float = 0.0) -> set[int]:
    """Distinct true planes (rows of ``gt_planes_world``) that some view sees.

    Parameters
    ----------
    views : list
        The registered views, with ``gt_labels`` (H, W) (0 = non-planar).
    gt_links : list of dict
        ``gt_links[v][local] = global`` true plane of each view label.
    min_area : float
        Smallest area, as a share of a view's pixels, at which a view sees a true plane.

    Returns
    -------
    set of int
    """
    seen: set[int] = set()
    for view, table in zip(views, gt_links, strict=True):
        counts = np.bincount(view.gt_labels.ravel(), minlength=max(table, default=0) + 1)
        seen |= {glob for local, glob in table.items()
                 if counts[local] > 0 and counts[local] >= min_area * view.gt_labels.size}
    return seen


def curved_global_planes(scene: Scene, views: list[Any]) -> int:
    """Global planes whose pixels, over all their views, lie mostly on non-planar truth.

    Parameters
    ----------
    scene : Scene
        Predicted scene (its views in the order of ``views``).
    views : list
        The registered views, with ``gt_labels`` (H, W) (0 = non-planar: curved objects and
        planar faces too small to count).

    Returns
    -------
    int
        Global planes with more than half of their linked pixels on label 0.
    """
    area = np.zeros(scene.planes.shape[0])
    off = np.zeros(scene.planes.shape[0])
    for v, (rec, view) in enumerate(zip(scene.views, views, strict=True)):
        lut = np.full(int(rec.labels.max()) + 1, -1)
        for local, glob in scene.links[v].items():
            lut[local] = glob
        glob = lut[rec.labels].ravel()
        linked = glob >= 0
        area += np.bincount(glob[linked], minlength=len(area))
        off += np.bincount(glob[linked & (view.gt_labels.ravel() == 0)], minlength=len(area))
    return int(np.sum((area > 0) & (off > 0.5 * area)))


def consistency(scene: Scene, views: list[Any], gt_links: list[dict[int, int]],
                min_area: float = 0.0) -> tuple[int, int]:
    """(consistent, total) true planes seen in two or more views (module docstring).

    ``min_area`` is the smallest area, as a share of a view's pixels, at which a true plane
    counts as seen in that view (0: any area).
    """
    votes: dict[int, list[int]] = {}
    for v, (rec, view) in enumerate(zip(scene.views, views, strict=True)):
        lut = np.full(int(rec.labels.max()) + 1, -1)
        for local, glob in scene.links[v].items():
            lut[local] = glob
        for local, glob_gt in gt_links[v].items():
            mask = view.gt_labels == local
            if mask.sum() < min_area * mask.size:
                continue
            ids = lut[rec.labels[mask]]
            values, counts = np.unique(ids, return_counts=True)
            vote = int(values[np.argmax(counts)])
            if vote >= 0:
                votes.setdefault(glob_gt, []).append(vote)
    multi = [v for v in votes.values() if len(v) >= 2]
    good = sum(1 for v in multi if all(x == v[0] for x in v))
    return good, len(multi)


def evaluate_sequences(n: int = 10, views: int = 5, path: str = "walk", level: str = "mild",
                       seed: int = 0, progress: bool = False, preset: str = "monoplane",
                       overrides: list[str] | None = None, width: int = 256,
                       height: int = 192, workers: int | None = None) -> dict[str, Any]:
    """Run the multi-view pipeline on ``n`` synthetic sequences and score it.

    Sequence ``k`` is ``generate_sequence(seed + k, views, path, level, width, height)``;
    intrinsics are known, so the matcher holds them fixed when it can.

    Returns
    -------
    dict
        ``sequences``, ``views``, ``path``, ``registered_views`` / ``total_views``,
        ``all_registered`` (sequences with every view registered), ``rotation_error_deg`` and
        ``translation_error_deg`` (median/mean over all registered pairs),
        ``global_planes``, ``gt_planes`` (every true plane) and ``gt_planes_seen`` (those a
        registered view sees, :func:`true_planes_seen`), sums; ``plane_count_ratio`` (global
        over all true planes) and ``plane_count_ratio_seen`` (over the seen ones);
        ``curved_global_planes`` (:func:`curved_global_planes`, sum); ``consistency`` (and
        ``consistency_all``, counting planes of any area, with their counts),
        ``normal_error_deg`` / ``offset_error_m`` (medians, ``fused`` and ``refined``),
        ``time_s`` (mean per sequence), ``step_time_s`` (mean seconds per pipeline step) and
        ``failures``.
    """
    from tqdm import tqdm

    # the pipeline, multiview and the generator load OpenCV
    from monoplane.host.pipeline import Pipeline
    from monoplane.multiview import hold_intrinsics_fixed, reconstruct_multiview
    from monoplane.synth.sequence import generate_sequence

    if n < 1:
        raise InvalidInput(f"n must be at least 1, got {n}")
    if views < 2:
        raise InvalidInput(f"--views must be at least 2, got {views}")
    pipe = Pipeline.from_preset(preset, overrides=overrides)
    hold_intrinsics_fixed(pipe)
    min_area = float(pipe.config.to_dict()["ransac"]["min_support"])
    tally = _Tally()
    for k in tqdm(range(n), desc=f"{path} sequences", disable=not progress):
        synth = generate_sequence(seed + k, views, path, level, width, height)
        tally.g_true += len(synth.gt_planes_world)
        start = time.perf_counter()
        try:
            out = reconstruct_multiview([v.frame for v in synth.views], pipe, workers=workers)
        except MonoplaneError as exc:
            tally.failures.append(f"seed {seed + k}: {exc}")
            continue
        tally.times.append(time.perf_counter() - start)
        tally.add(out, synth, views, min_area)
    return tally.result(n, views, path, level)


def _stats(x: list[float]) -> dict[str, float]:
    if not x:
        return {"mean": float("nan"), "median": float("nan")}
    return {"mean": float(np.mean(x)), "median": float(np.median(x))}


@dataclass
class _Tally:
    """What :func:`evaluate_sequences` sums and collects over its sequences: pose errors,
    plane counts, consistency counts, plane errors (``fused`` and ``refined``), times and
    failures."""

    rot: list[float] = field(default_factory=list)
    trans: list[float] = field(default_factory=list)
    times: list[float] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    steps: dict[str, list[float]] = field(default_factory=dict)
    reg_views: int = 0
    all_reg: int = 0
    g_pred: int = 0
    g_true: int = 0
    g_seen: int = 0
    curved: int = 0
    good: int = 0
    multi: int = 0
    good_all: int = 0
    multi_all: int = 0
    errors: dict[str, dict[str, list[float]]] = field(
        default_factory=lambda: {"fused": {"n": [], "d": []}, "refined": {"n": [], "d": []}})

    def add(self, out: MultiviewResult, synth: Any, views: int, min_area: float) -> None:
        """Score one sequence's result against its truth (``synth``, a synthetic sequence of
        ``views`` views); ``min_area`` is the smallest plane (pixels) consistency counts."""
        for step, sec in out.timings.items():
            self.steps.setdefault(step, []).append(sec)
        keep = out.frame_indices
        self.reg_views += len(keep)
        self.all_reg += len(keep) == views
        true_views = [synth.views[v] for v in keep]
        links = [synth.view_to_global[v] for v in keep]
        self.g_seen += len(true_planes_seen(true_views, links, min_area))
        cams = out.scene.cameras
        for a in range(len(keep)):
            for b in range(a + 1, len(keep)):
                va, vb = true_views[a], true_views[b]
                r, t = relative_pose_error(cams[a], cams[b], va.R, va.t, vb.R, vb.t)
                self.rot.append(r)
                self.trans.append(t)
        areas = np.zeros(out.scene.planes.shape[0])
        for v, rec in enumerate(out.scene.views):
            for local, glob in out.scene.links[v].items():
                areas[glob] += rec.area_px[local - 1]
        self.g_pred += int((areas > 0).sum())
        self.curved += curved_global_planes(out.scene, true_views)
        c_good, c_all = consistency(out.scene, true_views, links, min_area)
        self.good += c_good
        self.multi += c_all
        c_good, c_all = consistency(out.scene, true_views, links)
        self.good_all += c_good
        self.multi_all += c_all
        for tag, scene in (("fused", out.fused or out.scene), ("refined", out.scene)):
            ne, oe = plane_errors(scene, true_views, synth.gt_planes_world, links)
            self.errors[tag]["n"] += ne
            self.errors[tag]["d"] += oe

    def result(self, n: int, views: int, path: str, level: str) -> dict[str, Any]:
        """The dict :func:`evaluate_sequences` returns."""
        good, multi, good_all, multi_all = self.good, self.multi, self.good_all, self.multi_all
        return {
            "sequences": n, "views": views, "path": path, "level": level,
            "registered_views": self.reg_views, "total_views": n * views,
            "all_registered": self.all_reg,
            "rotation_error_deg": _stats(self.rot), "translation_error_deg": _stats(self.trans),
            "global_planes": self.g_pred, "gt_planes": self.g_true, "gt_planes_seen": self.g_seen,
            "plane_count_ratio": self.g_pred / max(self.g_true, 1),
            "plane_count_ratio_seen": self.g_pred / max(self.g_seen, 1),
            "curved_global_planes": self.curved,
            "consistency": good / multi if multi else float("nan"),
            "consistent_planes": good, "multi_view_planes": multi,
            "consistency_all": good_all / multi_all if multi_all else float("nan"),
            "consistent_planes_all": good_all, "multi_view_planes_all": multi_all,
            "normal_error_deg": {t: _stats(e["n"]) for t, e in self.errors.items()},
            "offset_error_m": {t: _stats(e["d"]) for t, e in self.errors.items()},
            "time_s": _stats(self.times), "failures": self.failures,
            "step_time_s": {k: float(np.mean(v)) for k, v in self.steps.items()},
        }


def format_sequences(r: dict[str, Any]) -> str:
    """Human-readable summary of :func:`evaluate_sequences` output."""
    ne, oe = r["normal_error_deg"], r["offset_error_m"]
    lines = [
        f"{r['sequences']} {r['path']} sequences of {r['views']} views ({r['level']} cues)",
        f"views registered: {r['registered_views']}/{r['total_views']} "
        f"(all views in {r['all_registered']}/{r['sequences']} sequences)",
        "pairwise pose error: rotation {:.2f}° median / {:.2f}° mean, translation direction "
        "{:.2f}° median / {:.2f}° mean".format(
            r["rotation_error_deg"]["median"], r["rotation_error_deg"]["mean"],
            r["translation_error_deg"]["median"], r["translation_error_deg"]["mean"]),
        f"global planes: {r['global_planes']} for {r['gt_planes_seen']} distinct true planes "
        f"seen (ratio {r['plane_count_ratio_seen']:.2f}; {r['gt_planes']} in all, ratio "
        f"{r['plane_count_ratio']:.2f}); {r['curved_global_planes']} lie mostly on "
        "non-planar truth",
        f"cross-view consistency: {r['consistency']:.3f} ({r['consistent_planes']} of "
        f"{r['multi_view_planes']} true planes seen in 2+ views); counting planes of any "
        f"area: {r['consistency_all']:.3f} ({r['consistent_planes_all']} of "
        f"{r['multi_view_planes_all']})",
        "plane error after similarity alignment (median): fused {:.2f}° / {:.3f} m, "
        "refined {:.2f}° / {:.3f} m".format(
            ne["fused"]["median"], oe["fused"]["median"], ne["refined"]["median"],
            oe["refined"]["median"]),
        "plane error (mean): fused {:.2f}° / {:.3f} m, refined {:.2f}° / {:.3f} m".format(
            ne["fused"]["mean"], oe["fused"]["mean"], ne["refined"]["mean"],
            oe["refined"]["mean"]),
        f"time per sequence: {r['time_s']['mean']:.2f} s (mean; "
        + ", ".join(f"{k} {v:.2f}" for k, v in r.get("step_time_s", {}).items()
                    if k != "total") + ")",
    ]
    lines += [f"failed: {f}" for f in r["failures"]]
    return "\n".join(lines)
