"""The single-view report: inputs, cues, plane labels, planar depth, 3D views and a plane table."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

import numpy as np
from tqdm import tqdm

from monoplane.datamodel import Frame, Reconstruction
from monoplane.export.gltf import reconstruction_glb
from monoplane.geometry.mesh import planar_mesh
from monoplane.report import figures as fig
from monoplane.report import html
from monoplane.report.colors import colorize_normals, plane_palette, shade
from monoplane.report.render3d import Mesh, RenderResult, Shot, render
from monoplane.report.viewer import install_viewer, viewer_section
from monoplane.report.viewpoints import facing_triangles, orbit_viewpoints, zoom_to_fit

#: Width of the 3D renders in pixels (height follows the image's aspect ratio).
RENDER_WIDTH = 640
#: Aim for about this many mesh vertices; the grid step of :func:`planar_mesh` follows.
MESH_VERTICES = 80_000


def mesh_step(height: int, width: int) -> int:
    """Grid step that keeps a planar mesh near :data:`MESH_VERTICES` vertices."""
    return max(1, int(round(np.sqrt(height * width / MESH_VERTICES))))


def render_size(height: int, width: int) -> tuple[int, int]:
    """``(width, height)`` of the 3D renders: :data:`RENDER_WIDTH` wide, the image's aspect."""
    return RENDER_WIDTH, max(16, int(round(RENDER_WIDTH * height / width)))


def estimate_up(rec: Reconstruction, max_tilt_deg: float = 35.0) -> np.ndarray:
    """The scene's "up" in the camera frame, from its largest floor- or ceiling-like plane.

    A virtual bird's eye view looks along gravity only if it knows where up is; the camera's
    own -y axis is off by the camera's pitch and roll. The largest plane whose normal is within
    ``max_tilt_deg`` of the camera's vertical is taken as horizontal: a floor's normal (facing
    the camera above it) points up, a ceiling's points down.

    Returns
    -------
    numpy.ndarray
        (3,) unit vector, camera frame (OpenCV axes); ``(0, -1, 0)`` when no plane qualifies.
    """
    camera_up = np.array([0.0, -1.0, 0.0])
    if rec.num_planes == 0:
        return camera_up
    cos_up = rec.planes[:, :3] @ camera_up
    horizontal = np.abs(cos_up) > np.cos(np.deg2rad(max_tilt_deg))
    if not np.any(horizontal):
        return camera_up
    area = np.where(horizontal, rec.area_px, -1)
    i = int(np.argmax(area))
    return rec.planes[i, :3] * np.sign(cos_up[i])


def frame_views(rec: Reconstruction, out_dir: Path) -> tuple[list[html.Figure], RenderResult]:
    """Render the planar mesh from the camera, from above and obliquely, by plane and textured.

    Returns
    -------
    figures : list of html.Figure
        Rendered pictures with captions, in display order (plane colours and texture of each
        viewpoint side by side).
    result : RenderResult
        What the renderer produced, with the reason when it failed.
    """
    frame = rec.frame
    vertices, triangles, colors, plane_ids = planar_mesh(rec, mesh_step(*frame.shape))
    if len(triangles) == 0:
        return [], RenderResult({}, "no planar surface to render in 3D", 0.0)
    palette = plane_palette(rec.num_planes) / 255.0
    by_plane = shade(palette[plane_ids - 1], rec.planes[plane_ids - 1, :3])
    meshes = [Mesh(vertices, triangles, by_plane), Mesh(vertices, triangles, colors)]
    width, height = render_size(*frame.shape)
    K = frame.K.copy()
    # Pixel centres sit at integers (OpenCV): a scale s maps x to s (x + ½) - ½, not s x.
    for row, scale in ((0, width / frame.width), (1, height / frame.height)):
        K[row] *= scale
        K[row, 2] += 0.5 * (scale - 1.0)
    tri_planes = plane_ids[triangles[:, 0]] - 1
    views: list[tuple[str, str, np.ndarray, np.ndarray, np.ndarray | None]] = [
        ("frontal", "frontal view (the input camera)", K, np.eye(4), None)]
    for vp in orbit_viewpoints(vertices, estimate_up(rec), np.array([0.0, 0.0, 1.0]), width,
                               height)[:2]:
        facing = facing_triangles(tri_planes, rec.planes, vp.eye)
        vp = zoom_to_fit(vp, vertices[np.unique(triangles[facing])], width, height)
        views.append((vp.name, vp.title, vp.K, vp.world_to_cam, facing))
    shots: list[Shot] = []
    figures: list[html.Figure] = []
    for name, title, K_v, T, keep in views:
        for j, kind in enumerate(("planes", "texture")):
            shots.append(Shot(f"3d_{name}_{kind}", K_v, T, {j: keep}))
            label = "coloured by plane" if kind == "planes" else "image texture"
            figures.append(html.Figure(f"3d_{name}_{kind}.png", f"{title}, {label}"))
    result = render(meshes, [], shots, out_dir, width, height)
    figures = [f for f in figures if f.src[:-4] in result.paths]
    return figures, result


def plane_rows(rec: Reconstruction) -> list[list[str]]:
    """Table rows (markup) for the planes of a reconstruction."""
    palette = plane_palette(rec.num_planes)
    total = rec.frame.height * rec.frame.width
    units = html.esc(rec.frame.depth_units)
    rmse, support = np.asarray(rec.rmse), np.asarray(rec.support)  # filled on construction
    rows = []
    for i in range(rec.num_planes):
        n, d = rec.planes[i, :3], rec.planes[i, 3]
        rows.append([
            f"{html.swatch(palette[i])}{i + 1}",
            "(" + ", ".join(f"{x:+.3f}" for x in n) + ")",
            f"{d:.3f} {units}",
            f"{int(rec.area_px[i])} ({100.0 * rec.area_px[i] / total:.1f} %)",
            f"{rmse[i]:.4f} {units}",
            f"{int(support[i])}",
        ])
    return rows


def rendered_views(render_3d: bool, make: Callable[[], tuple[list[html.Figure], RenderResult]]
                   ) -> tuple[list[html.Figure], RenderResult]:
    """The 3D figures ``make()`` renders, or none (with the reason) when 3D was not asked for
    or ``make()`` raised."""
    if not render_3d:
        return [], RenderResult({}, "3D views were not requested", 0.0)
    start = time.perf_counter()
    try:
        return make()
    except Exception as exc:  # the 3D views are extras: the report's 2D figures must still come out
        first_line = (str(exc).splitlines() or [""])[0]
        return [], RenderResult({}, f"3D rendering failed ({type(exc).__name__}: {first_line})",
                                time.perf_counter() - start)


def views_3d_body(views: list[html.Figure], reason: str | None, complete: str) -> str:
    """HTML of a report's 3D section: why views are missing, if any are, then the views.

    ``complete`` names the 2D figures a reader can still rely on.
    """
    body = ""
    if reason:
        body += html.warning(f"3D views are missing or incomplete: {reason}. {complete}")
    if views:
        body += html.figure_grid(views, 2)
    return body


def open_report(out_dir: Path, steps: int, desc: str, progress: bool
                ) -> tuple[Path, tqdm, float]:
    """The report's folder (created if missing), its progress bar of ``steps`` steps, shown
    on stderr when ``progress`` (:func:`finish_report` takes the last step), and its start
    (a ``time.perf_counter()`` value, for :func:`timing_section`'s total)."""
    start = time.perf_counter()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return out, tqdm(total=steps, desc=desc, unit="step", disable=not progress), start


def summary_section(contents: str) -> str:
    """The section showing ``summary.png``, the report's main figures in one picture, which
    can be shared on its own (markup); ``contents`` says what it gathers."""
    return html.section("Summary", html.figure_grid(
        [html.Figure("summary.png", f"summary.png: {contents}, in one picture")], 1))


def timing_section(timings: dict[str, float], config: dict | None,
                   render_seconds: float | None, start: float) -> str:
    """The "Timing and configuration" section (markup): each step's seconds, the report's own
    rendering (``render_seconds``, None when nothing was rendered) and total since ``start``
    (a ``time.perf_counter()`` value), then the resolved config."""
    rows = [[k, f"{float(v):.3f}"] for k, v in timings.items()]
    if render_seconds is not None:
        rows.append(["3D rendering (report)", f"{render_seconds:.3f}"])
    rows.append(["report total", f"{time.perf_counter() - start:.3f}"])
    body = html.table(["step", "seconds"], rows)
    if config:
        body += html.preformatted(json.dumps(config, indent=2, default=str),
                                  "resolved configuration")
    return html.section("Timing and configuration", body)


def glb_for_report(out: Path, name: str, build: Callable[[], bytes]) -> bytes:
    """The bytes of the ``.glb`` file ``name`` in the report folder ``out``; ``build()`` makes
    it, and it is written, when the folder does not hold it yet (a report written on its own)."""
    path = out / name
    if path.is_file():
        return path.read_bytes()
    data = build()
    path.write_bytes(data)
    return data


def finish_report(out: Path, bar: tqdm, title: str, subtitle: str, sections: list[str]) -> Path:
    """Write ``report.html`` into ``out``, take the progress bar's last step and close it."""
    path = html.write_page(out / "report.html", title, subtitle, sections)
    bar.update()
    bar.close()
    return path


def write_frame_report(rec: Reconstruction, out_dir: Path, render_3d: bool = True,
                       progress: bool = False, viewer: str | None = None) -> Path:
    """Write ``report.html``, its PNG figures and ``summary.png`` for one reconstruction.

    The page also shows ``planes.glb`` in an interactive 3D view; ``planes.glb`` is written
    into ``out_dir`` when it is not there yet.

    Parameters
    ----------
    rec : Reconstruction
        Planes of one frame (camera frame, OpenCV axes).
    out_dir : pathlib.Path
        Folder for ``report.html`` and the PNGs (created if missing).
    render_3d : bool
        Render the planar mesh (:mod:`~monoplane.report.render3d`). When false, or when
        rendering fails, the report has the 2D figures and says why the 3D views are missing.
    progress : bool
        Show a progress bar on stderr.
    viewer : str, optional
        Relative URL, from ``out_dir``, of a copy of the 3D viewer script that several reports
        share (see :func:`~monoplane.report.viewer.install_viewer`); by default the report
        gets its own copy in ``viewer/``.

    Returns
    -------
    pathlib.Path
        Path of ``report.html``.
    """
    out, bar, start = open_report(out_dir, 4, "report", progress)
    frame = rec.frame

    bar.set_postfix_str("inputs")
    inputs = _input_figures(frame, out)
    bar.update()

    bar.set_postfix_str("planes")
    planes_figs, depth_figs = _plane_figures(rec, out)
    bar.update()

    bar.set_postfix_str("3D views")
    notes = list(frame.notes)
    views, rendered = rendered_views(render_3d, lambda: frame_views(rec, out))
    if render_3d and rendered.reason:
        notes.append(f"3D views: {rendered.reason}")
    bar.update()

    bar.set_postfix_str("html")
    _write_summary_sheet(rec, out, views)
    sections = [
        summary_section("input, planes, depth and the rendered 3D views"),
        html.section("Inputs", html.figure_grid(inputs, 3)),
        html.section("Planes", html.figure_grid(planes_figs, 2)
                     + html.figure_grid(depth_figs, 1)),
        viewer_section(glb_for_report(out, "planes.glb", lambda: reconstruction_glb(rec)),
                       "planes.glb", viewer or install_viewer(out),
                       f"The {rec.num_planes} planes in 3D, coloured by plane id as in the "
                       "label map, seen at first from about where the camera stood."),
    ]
    sections.append(html.section("3D planar model", views_3d_body(
        views, rendered.reason, "The 2D figures above are complete.")))
    header = ["id", "normal (x, y, z)", "offset d", "area px (share)", "RMSE", "support"]
    sections.append(html.section(
        "Plane table",
        html.paragraph("Each plane satisfies n · X + d = 0 in the camera frame (x right, "
                       "y down, z forward), with n facing the camera.")
        + html.table(header, plane_rows(rec), raw=True),
    ))
    sections.append(html.section("Notes", html.bullet_list(notes) or html.paragraph("none")))
    sections.append(timing_section(rec.timings, rec.config,
                                   rendered.seconds if render_3d else None, start))
    return finish_report(out, bar, f"monoplane report: {frame.name}", _subtitle(rec),
                         sections)


def _input_figures(frame: Frame, out: Path) -> list[html.Figure]:
    """Write the frame's image and cues as figures (``input.png``, ``depth.png``,
    ``normals.png``, those it has)."""
    inputs = [html.Figure("input.png", "input image")]
    fig.save_png(out / "input.png", fig.input_image(frame.rgb, frame.shape))
    if frame.depth is not None:
        fig.save_png(out / "depth.png", fig.colorized_depth_figure(frame.depth,
                                                                   frame.depth_units))
        inputs.append(html.Figure("depth.png", f"depth cue ({frame.depth_kind}, "
                                               f"{frame.depth_units}; near blue, far red)"))
    if frame.normals is not None:
        fig.save_png(out / "normals.png", fig.enlarge(colorize_normals(frame.normals),
                                                      fig.display_scale(frame.width), True))
        inputs.append(html.Figure("normals.png", "normal cue (blue: facing the camera, "
                                                 "green: facing up, red/cyan: facing sideways)"))
    return inputs


def _plane_figures(rec: Reconstruction, out: Path
                   ) -> tuple[list[html.Figure], list[html.Figure]]:
    """Write the label figures and, with depth, the depth comparison; returns both lists."""
    frame = rec.frame
    fig.save_png(out / "labels_overlay.png", fig.overlay_labels(frame.rgb, rec.labels,
                                                                n_planes=rec.num_planes))
    fig.save_png(out / "label_map.png", fig.label_map(rec.labels, rec.num_planes))
    planes_figs = [
        html.Figure("labels_overlay.png", "planes over the image, with plane ids"),
        html.Figure("label_map.png", "label map (dark: non-planar)"),
    ]
    depth_figs = []
    if frame.depth is not None:
        fig.save_png(out / "depth_compare.png",
                     fig.depth_comparison(frame.depth, rec.planar_depth(), frame.depth_units))
        depth_figs.append(html.Figure(
            "depth_compare.png", "input depth (left) and the depth the planes imply (right), "
                                 "on one colour scale; black: invalid or non-planar"))
    return planes_figs, depth_figs


def _write_summary_sheet(rec: Reconstruction, out: Path, views: list[html.Figure]) -> None:
    """``summary.png``: the input, the planes, the depth cue and the rendered plane views."""
    panels = [(fig.load_png(out / "input.png"), "input image"),
              (fig.load_png(out / "labels_overlay.png"), f"{rec.num_planes} planes")]
    if rec.frame.depth is not None:
        panels.append((fig.load_png(out / "depth.png"), "depth cue"))
    panels += [(fig.load_png(out / f.src), f.caption.split(",")[0]) for f in views
               if f.src.endswith("_planes.png")]
    fig.save_png(out / "summary.png", fig.contact_sheet(panels, columns=3))


def _subtitle(rec: Reconstruction) -> str:
    """The report's subtitle: size, planes, coverage, depth and intrinsics, and the time."""
    frame = rec.frame
    coverage = 100.0 * float((rec.labels > 0).sum()) / (frame.height * frame.width)
    K = frame.K
    return (f"{frame.width}×{frame.height} px · {rec.num_planes} planes covering "
            f"{coverage:.1f} % of the image · depth {frame.depth_kind} in "
            f"{frame.depth_units} · fx={K[0, 0]:.1f} fy={K[1, 1]:.1f} "
            f"cx={K[0, 2]:.1f} cy={K[1, 2]:.1f} · {datetime.now():%Y-%m-%d %H:%M}")
