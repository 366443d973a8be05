"""Two-view evaluation: relative pose error and plane AP (SparsePlanes / NOPE-SAC protocol).

Protocol (see ``docs/multiview.md``):

* **Relative pose**: rotation error is the angle of ``R_pred R_gtᵀ`` (degrees); translation
  error is the angle between predicted and true translation directions (degrees), since SfM
  has no scale.
* **Scale**: the predicted scene is brought to metres by one median factor for the pair,
  ``median(gt depth) / median(predicted planar depth)`` over both views (as the paper aligns
  every method's depth by the median before evaluating).
* **Plane AP**: each fused (global) plane is one detection with the union of its views' masks
  in both images; its score is its total area in pixels. Predicted and true planes are compared
  in camera 0's frame, the prediction through its *predicted* pose. A detection is a true
  positive when an unmatched true plane has mask IoU ≥ 0.5 (intersection and union summed over
  both images), normal error ≤ 30° and offset error ≤ 1 m; true planes are matched greedily in
  score order, each to the candidate with the highest IoU. AP is the area under the
  all-point-interpolated precision-recall curve over all pairs, in percent. Variants drop the
  offset test (``-offset``), the normal test (``-normal``) or both (``-offset-normal``).
* A pair whose SfM fails contributes its true planes as misses and no detection.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from monoplane.datamodel import (
    Camera,
    Scene,
    SfmResult,
    orient_towards_camera,
    pixel_rays,
    plane_to_camera,
)
from monoplane.errors import InvalidInput, MonoplaneError
from monoplane.evaluation.recall import median_scale

if TYPE_CHECKING:
    from monoplane.datamodel import SfmResult
    from monoplane.synth import SynthScene

#: AP variants: name -> (use normal test, use offset test).
AP_VARIANTS: dict[str, tuple[bool, bool]] = {
    "all": (True, True),
    "-offset": (True, False),
    "-normal": (False, True),
    "-offset-normal": (False, False),
}
IOU_THRESHOLD = 0.5
NORMAL_THRESHOLD_DEG = 30.0
OFFSET_THRESHOLD_M = 1.0


def rotation_error_deg(R_pred: np.ndarray, R_gt: np.ndarray) -> float:
    """Angle of ``R_pred R_gtᵀ`` in degrees, for (3, 3) rotations."""
    cos = (np.trace(np.asarray(R_pred) @ np.asarray(R_gt).T) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def translation_angle_deg(t_pred: np.ndarray, t_gt: np.ndarray) -> float:
    """Angle between two translation directions in degrees (180 if either is zero)."""
    a, b = np.asarray(t_pred, dtype=np.float64), np.asarray(t_gt, dtype=np.float64)
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0 or nb == 0:
        return 180.0
    return float(np.degrees(np.arccos(np.clip(a @ b / (na * nb), -1.0, 1.0))))


def relative_pose_error(cam0: Camera, cam1: Camera, R0: np.ndarray, t0: np.ndarray,
                        R1: np.ndarray, t1: np.ndarray) -> tuple[float, float]:
    """Rotation and translation-direction errors of camera 1 relative to camera 0.

    Parameters
    ----------
    cam0, cam1 : Camera
        Predicted cameras (world-to-camera, any world frame and scale).
    R0, t0, R1, t1 : numpy.ndarray
        True world-to-camera poses.

    Returns
    -------
    (float, float)
        Rotation error and translation angle, degrees.
    """
    R_pred = cam1.R @ cam0.R.T
    t_pred = cam1.t - R_pred @ cam0.t
    R_gt = np.asarray(R1) @ np.asarray(R0).T
    t_gt = np.asarray(t1) - R_gt @ np.asarray(t0)
    return rotation_error_deg(R_pred, R_gt), translation_angle_deg(t_pred, t_gt)


@dataclass
class PairPlanes:
    """Detections of one pair, already judged against its ground truth.

    Attributes
    ----------
    scores : numpy.ndarray
        (D,) float64 detection scores (total mask area in pixels).
    true_positive : dict
        ``variant -> (D,) bool`` per AP variant.
    n_gt : int
        True planes of the pair.
    """

    scores: np.ndarray
    true_positive: dict[str, np.ndarray]
    n_gt: int


def _global_masks(labels: list[np.ndarray], links: list[dict[int, int]],
                  count: int) -> np.ndarray:
    """(V, G, H*W) bool masks of global planes from per-view labels and link tables."""
    out = np.zeros((len(labels), count, labels[0].size), dtype=bool)
    for v, (lab, table) in enumerate(zip(labels, links, strict=True)):
        lut = np.full(int(lab.max()) + 1, -1, dtype=np.int64)
        for local, glob in table.items():
            if local < len(lut):
                lut[local] = glob
        g = lut[lab.ravel()]
        hit = g >= 0
        out[v, g[hit], np.flatnonzero(hit)] = True
    return out


def judge_pair(pred_masks: np.ndarray, pred_planes: np.ndarray, gt_masks: np.ndarray,
               gt_planes: np.ndarray, scores: np.ndarray) -> PairPlanes:
    """Greedy score-ordered matching of detections to true planes, for every AP variant.

    Parameters
    ----------
    pred_masks : numpy.ndarray
        (V, D, N) bool masks of each detection in each view (N pixels per view).
    pred_planes : numpy.ndarray
        (D, 4) detections in the evaluation frame (metres), normals facing that frame's origin.
    gt_masks : numpy.ndarray
        (V, G, N) bool true masks.
    gt_planes : numpy.ndarray
        (G, 4) true planes in the same frame.
    scores : numpy.ndarray
        (D,) detection scores.

    Returns
    -------
    PairPlanes
    """
    d, g = pred_planes.shape[0], gt_planes.shape[0]
    n = pred_masks.shape[0] * pred_masks.shape[2]
    pm = pred_masks.transpose(1, 0, 2).reshape(d, n).astype(np.float64)
    gm = gt_masks.transpose(1, 0, 2).reshape(g, n).astype(np.float64)
    inter = pm @ gm.T
    union = pm.sum(1)[:, None] + gm.sum(1)[None, :] - inter
    iou = np.where(union > 0, inter / np.maximum(union, 1), 0.0)
    cos = np.clip(np.abs(pred_planes[:, :3] @ gt_planes[:, :3].T), -1.0, 1.0)
    normal_err = np.degrees(np.arccos(cos))
    # Offsets are compared with the normals made to agree in sign.
    sign = np.sign(pred_planes[:, :3] @ gt_planes[:, :3].T)
    sign[sign == 0] = 1.0
    offset_err = np.abs(pred_planes[:, 3:4] * sign - gt_planes[None, :, 3])
    order = np.argsort(-scores, kind="stable")
    tps = {}
    for variant, (use_normal, use_offset) in AP_VARIANTS.items():
        ok = iou >= IOU_THRESHOLD
        if use_normal:
            ok &= normal_err <= NORMAL_THRESHOLD_DEG
        if use_offset:
            ok &= offset_err <= OFFSET_THRESHOLD_M
        taken = np.zeros(g, dtype=bool)
        tp = np.zeros(d, dtype=bool)
        for k in order:
            cand = np.flatnonzero(ok[k] & ~taken)
            if len(cand):
                best = cand[np.argmax(iou[k, cand])]
                taken[best] = True
                tp[k] = True
        tps[variant] = tp
    return PairPlanes(scores=np.asarray(scores, dtype=np.float64), true_positive=tps, n_gt=g)


def average_precision(pairs: list[PairPlanes]) -> dict[str, float]:
    """AP (percent) per variant over all pairs' detections (all-point interpolation)."""
    n_gt = sum(p.n_gt for p in pairs)
    scores = np.concatenate([p.scores for p in pairs]) if pairs else np.zeros(0)
    order = np.argsort(-scores, kind="stable")
    out = {}
    for variant in AP_VARIANTS:
        tp = (np.concatenate([p.true_positive[variant] for p in pairs]) if pairs
              else np.zeros(0, bool))[order]
        if n_gt == 0 or len(tp) == 0:
            out[variant] = 0.0
            continue
        ctp = np.cumsum(tp)
        recall = ctp / n_gt
        precision = ctp / np.arange(1, len(tp) + 1)
        # Precision envelope (monotone non-increasing), integrated over recall steps.
        envelope = np.maximum.accumulate(precision[::-1])[::-1]
        steps = np.diff(np.concatenate([[0.0], recall]))
        out[variant] = float(100.0 * np.sum(steps * envelope))
    return out


def judge_scene(scene: Scene, synth: SynthScene) -> tuple[PairPlanes, float]:
    """Compare a fused scene of a synthetic pair with its ground truth.

    Parameters
    ----------
    scene : Scene
        Predicted scene (any world frame and scale) over the views of ``synth``.
    synth : SynthScene
        Ground truth.

    Returns
    -------
    (PairPlanes, float)
        Judged detections, and the median scale used to bring the prediction to metres.
    """
    views = synth.views
    pred_depth = np.concatenate([rec.planar_depth().ravel() for rec in scene.views])
    gt_depth = np.concatenate([v.gt_depth.ravel() for v in views])
    scale = median_scale(pred_depth[None], gt_depth[None])
    g_pred = scene.planes.shape[0]
    pred_masks = _global_masks([rec.labels for rec in scene.views], scene.links, g_pred)
    scores = pred_masks.sum(axis=(0, 2)).astype(np.float64)
    cam0 = scene.cameras[0]
    pred = np.zeros((0, 4))
    if g_pred:
        pred = plane_to_camera(scene.planes, cam0.R, cam0.t)
        pred = orient_towards_camera(pred * np.array([1.0, 1.0, 1.0, scale]))
    g_gt = synth.gt_planes_world.shape[0]
    gt_masks = _global_masks([v.gt_labels for v in views], synth.view_to_global, g_gt)
    gt = orient_towards_camera(plane_to_camera(synth.gt_planes_world, views[0].R, views[0].t))
    keep = scores > 0
    return judge_pair(pred_masks[:, keep], pred[keep], gt_masks, gt, scores[keep]), scale


def ground_truth_sfm(synth: SynthScene, num_points: int = 400, seed: int = 0) -> SfmResult:
    """An exact SfM result for a synthetic scene: true cameras, points and matches.

    Points are sampled on view 0's pixels, lifted with the true depth and kept when view ``j``
    sees the same point (its true depth agrees within 1 %); every view then has the kept points
    as keypoints. Useful to evaluate plane matching and fusion without SfM errors.

    Parameters
    ----------
    synth : SynthScene
        Scene with two or more views.
    num_points : int
        Pixels sampled in view 0.
    seed : int
        Sampling seed.
    """
    rng = np.random.default_rng(seed)
    v0 = synth.views[0]
    h, w = v0.gt_depth.shape
    idx = rng.choice(h * w, size=min(num_points, h * w), replace=False)
    idx = idx[v0.gt_depth.ravel()[idx] > 0]
    x_cam0 = pixel_rays(v0.frame.K, h, w).reshape(-1, 3)[idx] * v0.gt_depth.ravel()[idx, None]
    x_world = (x_cam0 - v0.t) @ v0.R
    visible = np.ones(len(idx), dtype=bool)
    projections = []
    for view in synth.views:
        x = x_world @ view.R.T + view.t
        uvw = x @ view.frame.K.T
        z = uvw[:, 2]
        front = z > 1e-9
        uv = np.full((len(idx), 2), -1.0)
        uv[front] = uvw[front, :2] / z[front, None]
        r = np.rint(uv).astype(np.int64)
        inside = front & (r[:, 0] >= 0) & (r[:, 0] < view.gt_depth.shape[1]) \
            & (r[:, 1] >= 0) & (r[:, 1] < view.gt_depth.shape[0])
        seen = np.zeros(len(idx), dtype=bool)
        rr = r[inside]
        seen[inside] = np.abs(view.gt_depth[rr[:, 1], rr[:, 0]] - z[inside]) <= 0.01 * z[inside]
        visible &= seen
        projections.append(uv)
    keep = np.flatnonzero(visible)
    cams = [Camera(K=v.frame.K, R=v.R, t=v.t, width=v.frame.width, height=v.frame.height,
                   name=v.frame.name) for v in synth.views]
    ids = np.arange(len(keep), dtype=np.int64)
    n = len(synth.views)
    return SfmResult(
        cameras=cams, points=x_world[keep],
        keypoints=[uv[keep] for uv in projections], point_ids=[ids.copy() for _ in range(n)],
        matches={(i, j): np.stack([ids, ids], axis=1) for i in range(n) for j in range(i + 1, n)},
        notes=["exact ground-truth SfM"],
    )


@dataclass
class TwoViewResults:
    """Aggregate of :func:`evaluate_pairs` (also available as a dict via :meth:`to_dict`)."""

    n_pairs: int
    registered: int
    rotation_errors: list[float] = field(default_factory=list)
    translation_errors: list[float] = field(default_factory=list)
    ap: dict[str, float] = field(default_factory=dict)
    ap_registered: dict[str, float] = field(default_factory=dict)
    time_sfm_s: list[float] = field(default_factory=list)
    time_total_s: list[float] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict with summary statistics."""
        def stats(x: list[float]) -> dict[str, float]:
            if not x:
                return {"mean": float("nan"), "median": float("nan")}
            return {"mean": float(np.mean(x)), "median": float(np.median(x))}

        return {
            "pairs": self.n_pairs,
            "registered": self.registered,
            "rotation_error_deg": stats(self.rotation_errors),
            "translation_error_deg": stats(self.translation_errors),
            "ap": dict(self.ap),
            "ap_registered": dict(self.ap_registered),
            "time_sfm_s": stats(self.time_sfm_s),
            "time_per_pair_s": stats(self.time_total_s),
            "failures": list(self.failures),
        }


def evaluate_pairs(n: int = 20, level: str = "mild", seed: int = 0, progress: bool = False,
                   preset: str = "monoplane", overrides: list[str] | None = None,
                   width: int = 256, height: int = 192, oracle_sfm: bool = False
                   ) -> dict[str, Any]:
    """Run the sparse-view pipeline on ``n`` synthetic two-view pairs and score it.

    Pair ``k`` is ``monoplane.synth.generate(seed + k, level, width, height, n_views=2)``.
    Intrinsics are known, so SfM keeps them fixed (paper appendix).

    Parameters
    ----------
    n : int
        Number of pairs.
    level : {"clean", "mild", "strong"}
        Cue corruption level.
    seed : int
        First scene seed.
    progress : bool
        Show a tqdm progress bar.
    preset : str
        Pipeline preset for the per-view planes.
    overrides : list of str, optional
        Extra ``table.key=value`` overrides.
    width, height : int
        Image size.
    oracle_sfm : bool
        Use exact cameras and matches (:func:`ground_truth_sfm`) instead of the matcher.

    Returns
    -------
    dict
        ``pairs``, ``registered``, ``rotation_error_deg`` and ``translation_error_deg``
        (mean/median over registered pairs), ``ap`` (per variant, failures count as misses),
        ``ap_registered`` (registered pairs only), ``time_sfm_s``, ``time_per_pair_s``
        (mean/median seconds, pairs that registered) and ``failures`` (one line per failed
        pair).
    """
    from tqdm import tqdm

    # the pipeline, multiview and the generator load OpenCV
    from monoplane.host.pipeline import Pipeline
    from monoplane.multiview import hold_intrinsics_fixed, reconstruct_multiview
    from monoplane.synth import generate

    if n < 1:
        raise InvalidInput(f"n must be at least 1, got {n}")
    pipe = Pipeline.from_preset(preset, overrides=overrides)
    hold_intrinsics_fixed(pipe)
    res = TwoViewResults(n_pairs=n, registered=0)
    judged_all, judged_ok = [], []
    for k in tqdm(range(n), desc="two-view pairs", disable=not progress):
        synth = generate(seed + k, level=level, width=width, height=height, n_views=2)
        frames = [v.frame for v in synth.views]
        start = time.perf_counter()
        try:
            sfm = ground_truth_sfm(synth, seed=seed + k) if oracle_sfm else None
            out = reconstruct_multiview(frames, pipe, sfm=sfm)
        except MonoplaneError as exc:
            res.failures.append(f"seed {seed + k}: {exc}")
            judged_all.append(PairPlanes(np.zeros(0), {v: np.zeros(0, bool) for v in
                                                       AP_VARIANTS},
                                         synth.gt_planes_world.shape[0]))
            continue
        res.time_total_s.append(time.perf_counter() - start)
        res.time_sfm_s.append(out.timings.get("matcher", 0.0))
        res.registered += 1
        v0, v1 = synth.views
        rot, trans = relative_pose_error(out.scene.cameras[0], out.scene.cameras[1],
                                         v0.R, v0.t, v1.R, v1.t)
        res.rotation_errors.append(rot)
        res.translation_errors.append(trans)
        judged, _ = judge_scene(out.scene, synth)
        judged_all.append(judged)
        judged_ok.append(judged)
    res.ap = average_precision(judged_all)
    res.ap_registered = average_precision(judged_ok)
    return res.to_dict()


def format_twoview(results: dict[str, Any]) -> str:
    """Human-readable summary of :func:`evaluate_pairs` output."""
    ap, apr = results["ap"], results["ap_registered"]
    lines = [
        f"pairs registered: {results['registered']}/{results['pairs']}",
        "relative pose (registered pairs): rotation {:.2f}° mean / {:.2f}° median, "
        "translation direction {:.2f}° mean / {:.2f}° median".format(
            results["rotation_error_deg"]["mean"], results["rotation_error_deg"]["median"],
            results["translation_error_deg"]["mean"],
            results["translation_error_deg"]["median"]),
        "plane AP (IoU>=0.5, normal<=30°, offset<=1 m)   all  -offset  -normal  -offset-normal",
        "  all pairs (failures = misses)           {:6.2f}  {:7.2f}  {:7.2f}  {:14.2f}".format(
            ap["all"], ap["-offset"], ap["-normal"], ap["-offset-normal"]),
        "  registered pairs only                   {:6.2f}  {:7.2f}  {:7.2f}  {:14.2f}".format(
            apr["all"], apr["-offset"], apr["-normal"], apr["-offset-normal"]),
        "time per pair: SfM {:.2f} s, total {:.2f} s (mean)".format(
            results["time_sfm_s"]["mean"], results["time_per_pair_s"]["mean"]),
    ]
    lines += [f"failed: {f}" for f in results["failures"]]
    return "\n".join(lines)
