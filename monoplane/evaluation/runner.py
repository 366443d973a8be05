"""Score methods (pipeline presets and external baselines) on seeded synthetic scenes.

The protocol of ``monoplane eval``:

1. Scene ``i`` of a run is ``monoplane.synth.generate(seed + i, level, width, height)``; every
   method sees exactly the same view-0 frame (its corrupted monocular-like cues) and is scored
   against the same exact ground truth.
2. Segmentation (VOI, RI, SC) is averaged over frames; plane recall is pooled over frames
   (``Σ recalled / Σ ground-truth planes``); see :mod:`~monoplane.evaluation.segmentation` and
   :mod:`~monoplane.evaluation.recall`.
3. Time per frame (``s/frame``) is the wall time of the method's call on a frame that already
   carries its cues (for presets: the whole :meth:`Pipeline.run`, whose cue step passes the
   given cues through; for baselines: the whole baseline call, data conversion included). The
   *core* time (``core s``) is what compares methods' algorithms: for presets the same
   pipeline time, for a baseline the time of its own call alone when it reports one
   (``timings["baseline.call"]``, e.g. a library's detection call without converting the
   cloud into its data structure), else its whole call. Before the timed runs every method
   runs once, untimed, on the first scene: that run loads compiled kernels from their disk
   cache and builds lazily created state, a one-off cost of a process that ``monoplane bench``
   reports apart (``first call``), so the times are steady-state ones.
4. Next to them, what that protocol cannot see (:mod:`~monoplane.evaluation.surfaces`), pooled
   over frames: the share of curved-surface pixels labelled planar (``curved``), predicted
   planes lying mostly on curved surfaces per frame (``false/fr``) and the purity of the
   predicted planes (share of planar-labelled pixels on their plane's dominant true face).
5. A method that raises a :class:`~monoplane.errors.MonoplaneError` on a frame is scored as if
   it had found no plane there (all pixels non-planar), and counted in ``n_failed``.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from monoplane.datamodel import Frame, Reconstruction
from monoplane.deprecation import renamed_names
from monoplane.errors import ConfigError, InvalidInput, MonoplaneError
from monoplane.evaluation.baselines import CALL_TIMING, baseline_names, bind_baseline
from monoplane.evaluation.recall import DEPTH_THRESHOLDS, plane_recall
from monoplane.evaluation.segmentation import segmentation_scores
from monoplane.evaluation.surfaces import SurfaceCounts, pooled, surface_counts

#: The paper's ablation rows (Tab. IV), in table order.
PAPER_PRESETS: tuple[str, ...] = (
    "seq-ransac", "seq-ransac+crf", "gc-ransac", "gc-ransac+crf", "monoplane-nocrf", "monoplane",
)
#: Corruption levels of :func:`monoplane.synth.generate`.
LEVELS: tuple[str, ...] = ("clean", "mild", "strong")


@dataclass
class Method:
    """Something that turns a cue-filled frame into planes.

    Attributes
    ----------
    name : str
        Row name in the table (preset or baseline name).
    kind : str
        ``"preset"`` or ``"baseline"``.
    run : callable
        ``run(frame, seed) -> Reconstruction``.
    """

    name: str
    kind: str
    run: Callable[[Frame, int], Reconstruction]


def preset_method(name: str, overrides: list[str] | None = None) -> Method:
    """A pipeline preset as a method (the config is validated now, not on the first frame).

    The synthetic frames carry their (corrupted) cues already, so the pipeline skips the cue
    provider for them (:meth:`~monoplane.contracts.CueProvider.needs_cues`).
    """
    from monoplane.host.pipeline import Pipeline  # loads OpenCV

    pipe = Pipeline.from_preset(name, overrides=overrides)
    return Method(name=name, kind="preset", run=lambda frame, seed: pipe.run(frame))


def baseline_method(name: str, options: dict[str, Any] | None = None) -> Method:
    """A registered baseline as a method (see :mod:`monoplane.evaluation.baselines`), with its
    keyword ``options`` (checked now when the baseline exposes its settings class)."""
    fn = bind_baseline(name, options)
    return Method(name=name, kind="baseline", run=lambda frame, seed: fn(frame, seed=seed))


def resolve_methods(presets: Sequence[str] = (), baselines: Sequence[str] = (),
                    all_methods: bool = False,
                    overrides: list[str] | None = None,
                    baseline_options: dict[str, dict[str, Any]] | None = None
                    ) -> list[Method]:
    """Build the method list of an evaluation run.

    Parameters
    ----------
    presets : sequence of str
        Pipeline presets, in order.
    baselines : sequence of str
        Baseline names, in order.
    all_methods : bool
        Prepend the paper's six ablation presets and append every registered baseline
        (:func:`~monoplane.evaluation.baselines.baseline_names`).
    overrides : list of str, optional
        ``table.key=value`` overrides applied to every preset.
    baseline_options : dict, optional
        Baseline name -> keyword options (see
        :func:`~monoplane.evaluation.baselines.parse_baseline_options`).

    Returns
    -------
    list of Method
        Without duplicates, presets first.
    """
    preset_names = list(PAPER_PRESETS) if all_methods else []
    preset_names += [p for p in presets if p not in preset_names]
    baseline_list = list(baselines)
    if all_methods:
        baseline_list += [b for b in baseline_names() if b not in baseline_list]
    if not preset_names and not baseline_list:
        raise InvalidInput("nothing to evaluate: give --preset, --baseline or --all")
    methods = [preset_method(p, overrides) for p in preset_names]
    options = baseline_options or {}
    methods += [baseline_method(b, options.get(b)) for b in dict.fromkeys(baseline_list)]
    return methods


@dataclass
class FrameScores:
    """Scores of one method on one frame."""

    scene_seed: int
    voi: float
    ri: float
    sc: float
    recalled: list[int]
    n_gt: int
    n_planes: int
    seconds: float
    core_seconds: float = float("nan")
    failed: bool = False
    error: str = ""
    surfaces: SurfaceCounts | None = None


class FrameMean:
    """Read-only attribute of a result holding ``frames``: one per-frame field's mean.

    ``NaN`` when there are no frames.

    Parameters
    ----------
    attr : str
        The per-frame field averaged.
    doc : str
        The attribute's docstring.
    """

    def __init__(self, attr: str, doc: str) -> None:
        self.attr = attr
        self.__doc__ = doc

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:  # looked up on the class: the descriptor itself, for help()
            return self
        values = [getattr(f, self.attr) for f in obj.frames]
        return float(np.mean(values)) if values else float("nan")


@dataclass
class MethodResult:
    """Aggregated scores of one method.

    Attributes
    ----------
    name, kind : str
        As in :class:`Method`.
    thresholds : list of float
        Depth thresholds of ``recall`` (metres).
    frames : list of FrameScores
        Per-frame scores, in scene order.
    """

    name: str
    kind: str
    thresholds: list[float]
    frames: list[FrameScores] = field(default_factory=list)

    voi = FrameMean("voi", "Mean VOI (nats).")
    ri = FrameMean("ri", "Mean Rand index.")
    sc = FrameMean("sc", "Mean segmentation covering.")
    seconds_per_frame = FrameMean("seconds", "Mean wall time per frame, seconds.")
    core_seconds_per_frame = FrameMean(
        "core_seconds", "Mean core time per frame, seconds (see the module docstring).")
    planes_per_frame = FrameMean("n_planes", "Mean number of predicted planes.")

    @property
    def recall(self) -> list[float]:
        """Pooled plane recall at each threshold."""
        total = sum(f.n_gt for f in self.frames)
        if total == 0:
            return [float("nan")] * len(self.thresholds)
        return [sum(f.recalled[k] for f in self.frames) / total
                for k in range(len(self.thresholds))]

    @property
    def surfaces(self) -> dict[str, float]:
        """Surface-truth scores pooled over the frames (:func:`monoplane.evaluation.surfaces.
        pooled`): ``curved_planar``, ``false_planes`` per frame and ``purity``."""
        return pooled([f.surfaces for f in self.frames if f.surfaces is not None])

    @property
    def n_failed(self) -> int:
        """Frames on which the method raised."""
        return sum(f.failed for f in self.frames)

    def summary(self) -> dict[str, Any]:
        """Aggregates only (one table row) as plain data."""
        return {
            "name": self.name, "kind": self.kind, "voi": self.voi, "ri": self.ri, "sc": self.sc,
            "recall": {f"{t:g}": r for t, r in zip(self.thresholds, self.recall, strict=True)},
            "seconds_per_frame": self.seconds_per_frame,
            "core_seconds_per_frame": self.core_seconds_per_frame,
            "planes_per_frame": self.planes_per_frame, **self.surfaces,
            "n_frames": len(self.frames), "n_failed": self.n_failed,
        }


@dataclass
class EvalResults:
    """Everything one ``monoplane eval`` run measured.

    Attributes
    ----------
    methods : list of MethodResult
        One per method, in the order they were given.
    settings : dict
        ``level``, ``n``, ``seed``, ``width``, ``height`` and the thresholds of the run.
    """

    methods: list[MethodResult]
    settings: dict[str, Any]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form: settings, per-method summaries and per-frame scores."""
        return {
            "settings": dict(self.settings),
            "methods": [{**m.summary(), "frames": [asdict(f) for f in m.frames]}
                        for m in self.methods],
        }


def score_reconstruction(rec: Reconstruction, gt_labels: np.ndarray, gt_depth: np.ndarray,
                         thresholds: Sequence[float] = DEPTH_THRESHOLDS
                         ) -> tuple[float, float, float, list[int], int]:
    """VOI, RI, SC and recall counts of one reconstruction.

    Parameters
    ----------
    rec : Reconstruction
        Prediction; its ``planar_depth()`` is median-scale aligned to ``gt_depth``.
    gt_labels : numpy.ndarray
        (H, W) int ground-truth plane labels, 0 = non-planar.
    gt_depth : numpy.ndarray
        (H, W) ground-truth z-depth in metres, 0 = invalid.
    thresholds : sequence of float
        Recall depth thresholds in metres.

    Returns
    -------
    tuple
        ``(voi, ri, sc, recalled per threshold, number of ground-truth planes)``.
    """
    seg = segmentation_scores(rec.labels, gt_labels)
    rec_counts = plane_recall(rec.labels, rec.planar_depth(), gt_labels, gt_depth,
                              thresholds=tuple(thresholds))
    return seg.voi, seg.ri, seg.sc, list(rec_counts.recalled), rec_counts.n_gt


def _empty_reconstruction(frame: Frame) -> Reconstruction:
    return Reconstruction(frame=frame, labels=np.zeros(frame.shape, dtype=np.int32),
                          planes=np.zeros((0, 4)))


def parse_size(text: str) -> tuple[int, int]:
    """Parse ``"WxH"`` (e.g. ``"256x192"``) into ``(width, height)``."""
    parts = text.lower().split("x")
    try:
        width, height = (int(p) for p in parts)
    except ValueError:
        raise InvalidInput(f"size must look like WIDTHxHEIGHT (e.g. 256x192), got '{text}'"
                           ) from None
    if width < 16 or height < 16:
        raise InvalidInput(f"size {text} is too small (at least 16x16)")
    return width, height


def evaluate(methods: Sequence[Method], n: int = 50, level: str = "mild", seed: int = 0,
             size: tuple[int, int] = (256, 192),
             thresholds: Sequence[float] = DEPTH_THRESHOLDS,
             progress: bool = True) -> EvalResults:
    """Run every method on ``n`` synthetic scenes and score it.

    Parameters
    ----------
    methods : sequence of Method
        What to evaluate (see :func:`resolve_methods`).
    n : int
        Number of scenes.
    level : str
        Cue corruption level, one of :data:`LEVELS`.
    seed : int
        Scene ``i`` uses seed ``seed + i``.
    size : tuple of int
        ``(width, height)`` in pixels.
    thresholds : sequence of float
        Recall depth thresholds (metres).
    progress : bool
        Show a tqdm progress bar on stderr.

    Returns
    -------
    EvalResults
    """
    from tqdm import tqdm

    from monoplane.synth import generate  # loads OpenCV

    if n < 1:
        raise InvalidInput(f"--n must be at least 1, got {n}")
    if level not in LEVELS:
        raise InvalidInput(f"unknown level '{level}'; valid levels: {', '.join(LEVELS)}")
    if not methods:
        raise InvalidInput("nothing to evaluate: the method list is empty")
    width, height = size
    thr = [float(t) for t in thresholds]
    results = [MethodResult(m.name, m.kind, thr) for m in methods]
    bar = tqdm(total=n * len(methods), disable=not progress, unit="run", desc="eval")
    try:
        first = generate(seed, level, width=width, height=height, n_views=1).views[0].frame
        for method in methods:  # untimed warm-up (see the module docstring, point 3)
            try:
                method.run(first, seed)
            except ConfigError:
                raise
            except MonoplaneError:
                pass  # scored (and warned about) in the timed run
        for i in range(n):
            scene_seed = seed + i
            view = generate(scene_seed, level, width=width, height=height, n_views=1).views[0]
            gt_labels = np.asarray(view.gt_labels)
            gt_depth = np.asarray(view.gt_depth)
            for method, result in zip(methods, results, strict=True):
                bar.set_postfix_str(f"scene {i + 1}/{n} {method.name}")
                failed, error = False, ""
                start = time.perf_counter()
                try:
                    rec = method.run(view.frame, scene_seed)
                except ConfigError:
                    raise  # a wrong option fails the run, not one scene
                except MonoplaneError as exc:
                    failed, error = True, str(exc)
                    warnings.warn(f"{method.name} failed on scene seed {scene_seed}: {exc}",
                                  stacklevel=2)
                    rec = _empty_reconstruction(view.frame)
                seconds = time.perf_counter() - start
                core = rec.timings.get(CALL_TIMING, seconds) if not failed else seconds
                voi, ri, sc, recalled, n_gt = score_reconstruction(rec, gt_labels, gt_depth, thr)
                result.frames.append(FrameScores(
                    scene_seed=scene_seed, voi=voi, ri=ri, sc=sc, recalled=recalled, n_gt=n_gt,
                    n_planes=rec.num_planes, seconds=seconds, core_seconds=core, failed=failed,
                    error=error,
                    surfaces=surface_counts(rec.labels, view.gt_faces, view.gt_curved)))
                bar.update(1)
    finally:
        bar.close()
    settings = {"level": level, "n": n, "seed": seed, "width": width, "height": height,
                "thresholds": thr}
    return EvalResults(methods=results, settings=settings)


def format_table(results: EvalResults) -> str:
    """The paper's table columns as aligned plain text.

    Columns: method, VOI↓, RI↑, SC↑, recall at each threshold, mean planes and seconds per
    frame (whole call) and core seconds per frame (see the module docstring); a failure count
    is appended to the name when a method failed on some frames.
    """
    thr = results.settings.get("thresholds", list(DEPTH_THRESHOLDS))
    header = ["method", "VOI↓", "RI↑", "SC↑", *[f"R@{t:g}m↑" for t in thr], "curved↓",
              "false/fr↓", "purity↑", "planes", "s/frame", "core s"]
    rows = []
    for m in results.methods:
        name = m.name if not m.n_failed else f"{m.name} ({m.n_failed} failed)"
        rows.append([name, f"{m.voi:.3f}", f"{m.ri:.3f}", f"{m.sc:.3f}",
                     *[f"{r:.3f}" for r in m.recall], f"{m.surfaces['curved_planar']:.3f}",
                     f"{m.surfaces['false_planes']:.2f}", f"{m.surfaces['purity']:.3f}",
                     f"{m.planes_per_frame:.1f}",
                     f"{m.seconds_per_frame:.3f}", f"{m.core_seconds_per_frame:.3f}"])
    widths = [max(len(r[c]) for r in [header, *rows]) for c in range(len(header))]

    def line(cells: list[str]) -> str:
        first = cells[0].ljust(widths[0])
        rest = [c.rjust(w) for c, w in zip(cells[1:], widths[1:], strict=True)]
        return "  ".join([first, *rest])

    s = results.settings
    title = (f"{s['n']} synthetic scenes, level {s['level']}, {s['width']}x{s['height']}, "
             f"seeds {s['seed']}..{s['seed'] + s['n'] - 1}")
    rule = "-" * len(line(header))
    return "\n".join([title, line(header), rule, *[line(r) for r in rows]])


# FrameResult was also monoplane.batch's per-frame outcome.
__getattr__ = renamed_names(__name__, {"FrameResult": "monoplane.evaluation.runner:FrameScores"})
