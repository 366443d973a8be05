"""Score presets and baselines on a folder of real frames with labelled planes (``eval --data``).

A dataset is a folder of frame folders, each holding

* ``gt_labels.png``: uint16 (H, W) ground-truth planar regions 1..P, 0 = not labelled;
* ``depth.npy`` (float, any unit, 0 = no measurement) or ``depth.png`` (16-bit millimetres);
* ``intrinsics.json``: ``{"fx": ..., "fy": ..., "cx": ..., "cy": ...}`` (optional);
* ``rgb.png`` / ``rgb.jpg`` / ``color.png`` / ``color.jpg`` (optional; depth-only otherwise).

Every method sees the frame with its depth, and normals estimated from it by the cue
provider of the method's preset (baselines: the default preset's provider). Scores per frame:
VOI, RI and SC on ground-truth planar pixels (:mod:`~monoplane.evaluation.segmentation`) and
Hoover et al.'s SegComp counts at tolerance T (:mod:`~monoplane.evaluation.segcomp`); tables
report their means over frames.

With ``as_cloud`` the presets run through :func:`monoplane.detect_planes` on the frame's valid
pixels unprojected into 3D, in a shuffled order (seeded), without their normals; the labels
come back per point and are put back on their pixels for scoring.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from monoplane.datamodel import Frame, Reconstruction
from monoplane.errors import ConfigError, InvalidInput, MonoplaneError
from monoplane.evaluation.baselines import bind_baseline
from monoplane.evaluation.segcomp import DEFAULT_TOLERANCE, SegCompScores, segcomp
from monoplane.evaluation.segmentation import SegmentationScores, segmentation_scores
from monoplane.host.detect import detect_planes
from monoplane.host.pipeline import Pipeline
from monoplane.io.frames import load_frame

_RGB_NAMES = ("rgb.png", "rgb.jpg", "color.png", "color.jpg")


@dataclass
class LabelledFrame:
    """One frame of a dataset and its ground truth."""

    name: str
    frame: Frame
    gt_labels: np.ndarray


def _read_gt(path: Path) -> np.ndarray:
    import cv2

    gt = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if gt is None or gt.ndim != 2 or not np.issubdtype(gt.dtype, np.integer):
        raise InvalidInput(f"{path}: ground truth must be a single-channel integer PNG")
    return gt.astype(np.int64)


def load_dataset(folder: str | Path) -> list[LabelledFrame]:
    """Read every frame folder of a dataset (see the module docstring), in name order.

    Raises
    ------
    InvalidInput
        When the folder does not exist, holds no frame with ``gt_labels.png``, or a frame's
        files do not agree in size.
    """
    root = Path(folder)
    if not root.is_dir():
        raise InvalidInput(f"--data {root}: not a folder")
    dirs = sorted(p for p in root.iterdir() if (p / "gt_labels.png").is_file())
    if (root / "gt_labels.png").is_file():
        dirs = [root]
    if not dirs:
        raise InvalidInput(f"--data {root}: no frame folder with gt_labels.png inside")
    frames = []
    for d in dirs:
        depth = next((d / n for n in ("depth.npy", "depth.png") if (d / n).is_file()), None)
        if depth is None:
            raise InvalidInput(f"{d}: needs depth.npy or depth.png")
        rgb = next((d / n for n in _RGB_NAMES if (d / n).is_file()), None)
        intr = d / "intrinsics.json"
        frame = load_frame(rgb, depth=depth, intrinsics=intr if intr.is_file() else None,
                           depth_scale=1000.0 if depth.suffix == ".png" else None)
        frame = frame.with_(name=d.name)
        gt = _read_gt(d / "gt_labels.png")
        if gt.shape != frame.shape:
            raise InvalidInput(f"{d}: gt_labels.png is {gt.shape}, the frame is {frame.shape}")
        frames.append(LabelledFrame(d.name, frame, gt))
    return frames


@dataclass
class DatasetFrameResult:
    """Scores of one method on one frame.

    Attributes
    ----------
    frame : str
        Name of the frame folder.
    segmentation : SegmentationScores
        VOI, RI and SC on the frame's ground-truth planar pixels.
    segcomp : SegCompScores
        Hoover et al.'s region counts.
    n_planes : int
        Planes the method found.
    seconds : float
        Wall time of the method's call.
    failed : bool
        The method raised; its labels count as all non-planar.
    error : str
        The error of a failed call.
    """

    frame: str
    segmentation: SegmentationScores
    segcomp: SegCompScores
    n_planes: int
    seconds: float
    failed: bool = False
    error: str = ""

    def to_dict(self) -> dict[str, Any]:
        """One flat JSON record: the frame, every score and count by name, the run's facts."""
        return {"frame": self.frame, **asdict(self.segmentation), **asdict(self.segcomp),
                "n_planes": self.n_planes, "seconds": self.seconds, "failed": self.failed,
                "error": self.error}


@dataclass
class DatasetMethodResult:
    """Per-frame and mean scores of one method."""

    name: str
    kind: str
    frames: list[DatasetFrameResult] = field(default_factory=list)

    def mean(self, key: str) -> float:
        """Mean over frames of one key of :meth:`DatasetFrameResult.to_dict` (NaN without
        frames)."""
        values = [f.to_dict()[key] for f in self.frames]
        return float(np.mean(values)) if values else float("nan")

    def summary(self) -> dict[str, Any]:
        """One table row as plain data."""
        keys = ("voi", "ri", "sc", "correct", "over", "under", "missed", "noise", "n_gt",
                "n_planes", "seconds")
        return {"name": self.name, "kind": self.kind, **{k: self.mean(k) for k in keys},
                "n_frames": len(self.frames),
                "n_failed": sum(f.failed for f in self.frames)}


@dataclass
class DatasetResults:
    """Everything one ``monoplane eval --data`` run measured."""

    methods: list[DatasetMethodResult]
    settings: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {"settings": dict(self.settings),
                "methods": [{**m.summary(), "frames": [f.to_dict() for f in m.frames]}
                            for m in self.methods]}


def cloud_reconstruction(frame: Frame, preset: str, overrides: list[str] | None,
                         seed: int) -> Reconstruction:
    """Run :func:`monoplane.detect_planes` on a frame's shuffled 3D points; labels per pixel."""
    valid = np.flatnonzero(frame.valid.ravel())
    order = np.random.default_rng(seed).permutation(valid.size)
    points = frame.points().reshape(-1, 3)[valid[order]]
    res = detect_planes(points, preset=preset, overrides=overrides)
    flat = np.zeros(frame.height * frame.width, dtype=np.int32)
    flat[valid[order]] = res.labels
    return Reconstruction(frame=frame, labels=flat.reshape(frame.shape), planes=res.planes,
                          rmse=res.rmse, support=res.support)


def _methods(presets: Sequence[str], baselines: Sequence[str], overrides: list[str] | None,
             as_cloud: bool, baseline_options: dict[str, dict[str, Any]]
             ) -> list[tuple[str, str, Any]]:
    out: list[tuple[str, str, Any]] = []
    for name in presets:
        if as_cloud:
            # Validate the config now rather than on the first frame.
            Pipeline.from_preset(name, overrides=overrides)
            out.append((f"{name} (cloud)", "cloud",
                        lambda f, s, n=name: cloud_reconstruction(f, n, overrides, s)))
        else:
            pipe = Pipeline.from_preset(name, overrides=overrides)
            out.append((name, "preset", lambda f, s, p=pipe: p.run(f)))
    for name in baselines:
        fn = bind_baseline(name, baseline_options.get(name))
        out.append((name, "baseline", lambda f, s, fn=fn: fn(f, seed=s)))
    if not out:
        raise InvalidInput("nothing to evaluate: give --preset or --baseline")
    return out


def evaluate_dataset(folder: str | Path, presets: Sequence[str] = (),
                     baselines: Sequence[str] = (), overrides: list[str] | None = None,
                     as_cloud: bool = False, tolerance: float = DEFAULT_TOLERANCE,
                     seed: int = 0, progress: bool = True,
                     baseline_options: dict[str, dict[str, Any]] | None = None
                     ) -> DatasetResults:
    """Score methods on every frame of a dataset folder.

    Parameters
    ----------
    folder : str or Path
        Dataset folder (module docstring).
    presets, baselines : sequence of str
        Methods, presets first.
    overrides : list of str, optional
        ``table.key=value`` applied to every preset.
    as_cloud : bool
        Run presets through :func:`monoplane.detect_planes` on shuffled 3D points.
    tolerance : float
        SegComp tolerance T.
    seed : int
        Seed of baselines and of the cloud shuffling.
    progress : bool
        Show a progress bar on stderr.
    baseline_options : dict, optional
        Baseline name -> keyword options (fields of its settings), e.g.
        ``{"cgal": {"min_support": 0.001}}``; checked before the first frame when the baseline
        exposes its settings class.

    Returns
    -------
    DatasetResults
    """
    from tqdm import tqdm

    if not 0.5 < tolerance <= 1.0:
        raise InvalidInput(f"--tolerance must lie in (0.5, 1], got {tolerance}")
    frames = load_dataset(folder)
    baseline_options = baseline_options or {}
    methods = _methods(presets, baselines, overrides, as_cloud, baseline_options)
    results = [DatasetMethodResult(name, kind) for name, kind, _ in methods]
    # Baselines get their normals from the default preset's cue provider, as any user would.
    cues = Pipeline.from_preset()
    bar = tqdm(total=len(frames) * len(methods), disable=not progress, unit="run",
               desc="eval")
    try:
        for item in frames:
            # Baselines need normals; presets estimate their own with their cue settings.
            with_normals = cues.prepare(item.frame)
            for (name, kind, run), result in zip(methods, results, strict=True):
                bar.set_postfix_str(f"{item.name} {name}")
                frame = with_normals if kind == "baseline" else item.frame
                failed, error = False, ""
                start = time.perf_counter()
                try:
                    rec = run(frame, seed)
                    labels = rec.labels
                except ConfigError:
                    raise  # a wrong option fails the run, not one frame
                except MonoplaneError as exc:
                    failed, error = True, str(exc)
                    warnings.warn(f"{name} failed on {item.name}: {exc}", stacklevel=2)
                    labels = np.zeros(item.frame.shape, dtype=np.int32)
                seconds = time.perf_counter() - start
                result.frames.append(DatasetFrameResult(
                    frame=item.name, segmentation=segmentation_scores(labels, item.gt_labels),
                    segcomp=segcomp(labels, item.gt_labels, tolerance),
                    n_planes=int(labels.max(initial=0)), seconds=seconds, failed=failed,
                    error=error))
                bar.update(1)
    finally:
        bar.close()
    settings = {"data": str(folder), "n_frames": len(frames), "tolerance": tolerance,
                "as_cloud": as_cloud, "seed": seed, "overrides": list(overrides or []),
                "baseline_options": baseline_options}
    return DatasetResults(results, settings)


def format_dataset_table(results: DatasetResults) -> str:
    """Mean scores per method as aligned text (SegComp columns are per-image means)."""
    t = results.settings["tolerance"]
    header = ["method", "VOI↓", "RI↑", "SC↑", f"correct@{t:g}↑", "over", "under", "missed",
              "noise", "GT", "s/frame"]
    rows = []
    for m in results.methods:
        s = m.summary()
        name = m.name if not s["n_failed"] else f"{m.name} ({s['n_failed']} failed)"
        rows.append([name, f"{s['voi']:.3f}", f"{s['ri']:.3f}", f"{s['sc']:.3f}",
                     f"{s['correct']:.1f}", f"{s['over']:.1f}", f"{s['under']:.1f}",
                     f"{s['missed']:.1f}", f"{s['noise']:.1f}", f"{s['n_gt']:.1f}",
                     f"{s['seconds']:.2f}"])
    widths = [max(len(r[c]) for r in [header, *rows]) for c in range(len(header))]

    def line(cells: list[str]) -> str:
        return "  ".join([cells[0].ljust(widths[0]),
                          *[c.rjust(w) for c, w in zip(cells[1:], widths[1:], strict=True)]])

    s = results.settings
    title = (f"{s['n_frames']} frames of {s['data']}"
             f"{' as clouds' if s['as_cloud'] else ''}, SegComp tolerance {t:g}")
    return "\n".join([title, line(header), "-" * len(line(header)), *[line(r) for r in rows]])
