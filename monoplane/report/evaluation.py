"""The evaluation report: the metrics table and the best and worst scene of every method.

Input is the :class:`~monoplane.evaluation.runner.EvalResults` of ``monoplane eval``. It keeps
only scores, not images: every scene is a pure function of its seed, level and size
(:func:`monoplane.synth.generate`), so the report regenerates the best and worst scenes and, when
given the methods, runs them again on those scenes to draw their predictions.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

from tqdm import tqdm

from monoplane.errors import MonoplaneError
from monoplane.report import figures as fig
from monoplane.report import html
from monoplane.synth import generate

if TYPE_CHECKING:
    from monoplane.evaluation.runner import EvalResults, FrameScores, Method, MethodResult

#: Metrics a case can be ranked by, and whether higher is better.
RANKING = {"sc": True, "ri": True, "voi": False}


def pick_cases(method: MethodResult, metric: str = "sc") -> list[tuple[str, FrameScores]]:
    """The best and the worst frame of a method by one metric.

    Returns
    -------
    list of (str, FrameScores)
        ``[("best", frame), ("worst", frame)]``; one entry when the method saw one frame, none
        when it saw none. Frames with a NaN score are skipped.
    """
    higher = RANKING[metric]
    frames = [f for f in method.frames if not math.isnan(getattr(f, metric))]
    if not frames:
        return []
    ranked = sorted(frames, key=lambda f: getattr(f, metric), reverse=higher)
    cases = [("best", ranked[0])]
    if len(ranked) > 1:
        cases.append(("worst", ranked[-1]))
    return cases


def metrics_rows(results: EvalResults) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the metrics table (the columns of ``monoplane eval``)."""
    thr = results.settings.get("thresholds", [])
    header = ["method", "VOI ↓", "RI ↑", "SC ↑", *[f"recall@{t:g} m ↑" for t in thr],
              "planes/frame", "s/frame", "failed"]
    rows = []
    for m in results.methods:
        rows.append([m.name, f"{m.voi:.3f}", f"{m.ri:.3f}", f"{m.sc:.3f}",
                     *[f"{r:.3f}" for r in m.recall], f"{m.planes_per_frame:.1f}",
                     f"{m.seconds_per_frame:.3f}", f"{m.n_failed}/{len(m.frames)}"])
    return header, rows


def write_eval_report(results: EvalResults, out_dir: Path,
                      methods: Sequence[Method] | None = None, metric: str = "sc",
                      progress: bool = False) -> Path:
    """Write ``report.html`` with the metrics table and per-method best/worst thumbnails.

    Parameters
    ----------
    results : EvalResults
        Output of :func:`monoplane.evaluation.runner.evaluate`.
    out_dir : pathlib.Path
        Folder for ``report.html`` and the PNGs (created if missing).
    methods : sequence of Method, optional
        The evaluated methods; those given (matched by name) are re-run on their best and
        worst scenes to draw predictions. Without them, thumbnails show image and ground truth.
    metric : {"sc", "ri", "voi"}
        Metric that ranks the scenes of a method.
    progress : bool
        Show a progress bar on stderr.

    Returns
    -------
    pathlib.Path
        Path of ``report.html``.
    """
    if metric not in RANKING:
        raise ValueError(f"metric must be one of {', '.join(RANKING)}, got {metric!r}")
    start = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    s = results.settings
    runners = {m.name: m for m in methods or ()}
    jobs = [(m, kind, f) for m in results.methods for kind, f in pick_cases(m, metric)]
    notes: list[str] = []
    blocks: list[str] = []
    figures: dict[str, list[html.Figure]] = {m.name: [] for m in results.methods}
    for m, kind, frame_result in tqdm(jobs, desc="eval report", unit="case",
                                      disable=not progress):
        seed = frame_result.scene_seed
        view = generate(seed, s["level"], width=s["width"], height=s["height"],
                        n_views=1).views[0]
        runner = runners.get(m.name)
        pred = None
        if runner is not None:
            try:
                pred = runner.run(view.frame, seed).labels
            except MonoplaneError as exc:
                notes.append(f"{m.name} failed again on scene {seed}: {exc}")
        score = getattr(frame_result, metric)
        title = f"{kind}: scene {seed}, {metric.upper()} {score:.3f}"
        name = f"case_{_slug(m.name)}_{kind}.png"
        if pred is None:
            panel = fig.hstack([fig.titled(fig.input_image(view.frame.rgb, view.gt_labels.shape),
                                           title),
                                fig.titled(fig.overlay_labels(view.frame.rgb, view.gt_labels,
                                                              ids=False), "ground truth")])
        else:
            panel = fig.comparison_row(view.frame.rgb, view.gt_labels, pred, title)
        fig.save_png(out / name, panel)
        figures[m.name].append(html.Figure(
            name, f"{m.name}, {kind} scene by {metric.upper()} (seed {seed}, {metric.upper()} "
                  f"{score:.3f}): image, ground truth"
                  + (", prediction" if pred is not None else "")))
    if methods is None:
        notes.append("methods were not given to the report, so thumbnails show the image and "
                     "the ground truth only")
    for m in results.methods:
        if figures[m.name]:
            blocks.append(f"<h3>{html.esc(m.name)}</h3>" + html.figure_grid(figures[m.name], 1))

    header, rows = metrics_rows(results)
    settings = (f"{s['n']} synthetic scenes (seeds {s['seed']}..{s['seed'] + s['n'] - 1}), "
                f"cue corruption '{s['level']}', {s['width']}×{s['height']} px")
    sections = [
        html.section("Metrics", html.paragraph(
            "VOI, RI and SC over ground-truth planar pixels (prediction's non-planar pixels "
            "pooled into one segment); plane recall pooled over frames, after median-scale "
            "alignment of depth. ↑ higher is better, ↓ lower is better.")
            + html.table(header, rows)),
        html.section(f"Best and worst scenes by {metric.upper()}",
                     html.paragraph("Label colours are independent per map: ground-truth and "
                                    "predicted plane ids are not matched.") + "".join(blocks)),
        html.section("Notes", html.bullet_list(notes) or html.paragraph("none")),
        html.section("Timing", html.table(["step", "seconds"], [
            ["report total", f"{time.perf_counter() - start:.3f}"]])),
    ]
    return html.write_page(out / "report.html", "monoplane evaluation report",
                           f"{settings} · {datetime.now():%Y-%m-%d %H:%M}", sections)


def _slug(name: str) -> str:
    """A file-name-safe version of a method name."""
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name)
