"""``index.html`` of a batch: a label-overlay thumbnail per frame, links to the frame reports
and their interactive 3D views, and the distributions of frame time and plane count.

The plots are inline SVG histograms: they need no plotting library, stay sharp at any zoom and
keep the page self-contained. Thumbnails are PNGs in ``index_files/``, made from each frame's
``labels.png`` and its input image, so frames skipped on resume get one too.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from monoplane.batch.frame import ASSETS, REPORT_FILE, BatchSummary
from monoplane.batch.specs import FrameSpec
from monoplane.io.frames import read_image
from monoplane.report import figures as fig
from monoplane.report import html
from monoplane.report.viewer import SECTION_ID

THUMB_WIDTH = 240


def thumbnail(spec: FrameSpec, frame_dir: Path, dest: Path) -> bool:
    """Write a small label overlay of one finished frame; False if its files are unreadable."""
    labels = cv2.imread(str(frame_dir / "labels.png"), cv2.IMREAD_UNCHANGED)
    if labels is None or labels.ndim != 2:
        return False
    rgb = None
    if spec.image is not None:
        try:
            rgb = read_image(spec.image)
        except Exception:  # the input moved since the run: a grey background will do
            rgb = None
        if rgb is not None and rgb.shape[:2] != labels.shape:
            rgb = None
    over = fig.overlay_labels(rgb, labels.astype(np.int32), ids=False)
    h = max(1, round(over.shape[0] * THUMB_WIDTH / over.shape[1]))
    fig.save_png(dest, cv2.resize(over, (THUMB_WIDTH, h), interpolation=cv2.INTER_AREA))
    return True


def svg_histogram(values: Sequence[float | None], title: str, unit: str, integer: bool = False,
                  bins: int = 20, width: int = 420, height: int = 220) -> str:
    """An inline SVG histogram of ``values`` with labelled axes (markup)."""
    vals = np.asarray([v for v in values if v is not None], dtype=float)
    if vals.size == 0:
        return html.paragraph(f"{title}: no data")
    # Both quantities are non-negative; an axis from 0 shows spread relative to magnitude.
    hi = float(vals.max())
    if integer:
        edges = np.arange(0, np.ceil(hi) + 2) - 0.5
        if edges.size - 1 > bins:
            edges = np.linspace(-0.5, hi + 0.5, bins + 1)
    else:
        edges = np.linspace(0.0, hi * 1.05 if hi > 0 else 1.0, bins + 1)
    counts, edges = np.histogram(vals, bins=edges)
    left, right, top, bottom = 44, 12, 26, 40
    pw, ph = width - left - right, height - top - bottom
    cmax = max(1, int(counts.max()))
    bw = pw / len(counts)
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
             f'font-family="sans-serif" font-size="11">',
             f'<text x="{width / 2}" y="16" text-anchor="middle" font-size="13">'
             f'{html.esc(title)}</text>']
    for i, c in enumerate(counts):
        bh = ph * c / cmax
        x, y = left + i * bw, top + ph - bh
        tip = f"{edges[i]:.3g} to {edges[i + 1]:.3g} {unit}: {c}"
        parts.append(f'<rect x="{x + 1:.1f}" y="{y:.1f}" width="{max(bw - 2, 1):.1f}" '
                     f'height="{bh:.1f}" fill="#4a7fb5"><title>{html.esc(tip)}</title></rect>')
    parts.append(f'<line x1="{left}" y1="{top + ph}" x2="{left + pw}" y2="{top + ph}" '
                 'stroke="#333"/>')
    parts.append(f'<line x1="{left}" y1="{top}" x2="{left}" y2="{top + ph}" stroke="#333"/>')
    if integer:  # label bin centres: the first, middle and last bin
        picks = sorted({0, len(counts) // 2, len(counts) - 1})
        ticks = [((edges[i] + edges[i + 1]) / 2, left + (i + 0.5) * bw) for i in picks]
    else:
        ticks = [(edges[0] + f * (edges[-1] - edges[0]), left + f * pw) for f in (0.0, 0.5, 1.0)]
    for value, x in ticks:
        label = f"{value:.0f}" if integer else f"{value:.3g}"
        parts.append(f'<text x="{x:.1f}" y="{top + ph + 14}" text-anchor="middle">{label}</text>')
    parts.append(f'<text x="{left + pw / 2}" y="{height - 6}" text-anchor="middle">'
                 f'{html.esc(unit)}</text>')
    for cv in sorted({0, cmax // 2, cmax}):
        y = top + ph - ph * cv / cmax
        parts.append(f'<text x="{left - 6}" y="{y + 4:.1f}" text-anchor="end">{cv}</text>')
    parts.append(f'<text x="12" y="{top + ph / 2}" text-anchor="middle" '
                 f'transform="rotate(-90 12 {top + ph / 2})">frames</text></svg>')
    return "".join(parts)


def write_index(summary: BatchSummary, specs: Sequence[FrameSpec], out: Path) -> Path:
    """Write ``out/index.html`` (atomically) and its thumbnails in ``out/index_files/``.

    Returns
    -------
    pathlib.Path
        Path of ``index.html``.
    """
    assets = out / ASSETS
    assets.mkdir(exist_ok=True)
    by_name = {s.name: s for s in specs}
    cells = []
    for res in summary.frames:
        frame_dir = out / res.name
        name = html.esc(res.name)
        if res.status != "failed" and (frame_dir / "labels.png").is_file():
            thumb = assets / f"{res.name}.png"
            made = thumb.is_file() and (
                thumb.stat().st_mtime >= (frame_dir / "labels.png").stat().st_mtime)
            if not made:
                made = thumbnail(by_name[res.name], frame_dir, thumb)
            target = (f"{res.name}/{REPORT_FILE}" if (frame_dir / REPORT_FILE).is_file()
                      else f"{res.name}/planes.json")
            img = (f'<img src="{ASSETS}/{html.esc(res.name)}.png" alt="{name}" loading="lazy">'
                   if made else "")
            caption = f"{name}: {res.planes} planes" + (
                f", {res.seconds:.2f} s" if res.seconds is not None else ", done before")
            view3d = ""
            if target.endswith(REPORT_FILE):
                view3d = f' · <a href="{html.esc(target)}#{SECTION_ID}">3D view</a>'
            cells.append(f'<figure><a href="{html.esc(target)}">{img}</a>'
                         f'<figcaption><a href="{html.esc(target)}">{caption}</a>{view3d}'
                         '</figcaption></figure>')
        else:
            cells.append(f'<figure><figcaption><b>{name}: failed</b><br>'
                         f'{html.esc(res.error or "")}</figcaption></figure>')
    counts = {s: summary.count(s) for s in ("ok", "failed", "skipped")}
    timed = [f.seconds for f in summary.frames if f.status == "ok"]
    planes = [f.planes for f in summary.frames if f.planes is not None]
    plots = ('<div class="grid cols2">'
             + svg_histogram(timed, "time per frame (frames run now)", "seconds")
             + svg_histogram(planes, "planes per frame", "planes", integer=True)
             + "</div>")
    failed_rows = [[f.name, f.error or ""] for f in summary.frames if f.status == "failed"]
    sections = [
        html.section("Distributions", plots),
        html.section("Frames", f'<div class="grid cols4">{"".join(cells)}</div>'),
    ]
    if failed_rows:
        sections.insert(0, html.section("Failed frames", html.table(["frame", "reason"],
                                                                     failed_rows)))
    subtitle = (f"{len(summary.frames)} frames: {counts['ok']} done, {counts['failed']} failed, "
                f"{counts['skipped']} skipped (done by an earlier run); engine {summary.engine}, "
                f"{summary.seconds:.1f} s. Click a thumbnail for the frame's report, or "
                "'3D view' to turn its planes in 3D.")
    fd, tmp = tempfile.mkstemp(prefix=".index.", suffix=".tmp", dir=out)
    os.close(fd)
    try:
        html.write_page(Path(tmp), "monoplane batch", subtitle, sections)
        os.replace(tmp, out / "index.html")
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return out / "index.html"
