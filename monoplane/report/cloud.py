"""The point-cloud report: the plane meshes in 3D (interactive and rendered) and a plane table."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from monoplane.export.gltf import planes_glb
from monoplane.report import figures as fig
from monoplane.report import html
from monoplane.report.colors import plane_palette, shade
from monoplane.report.frame import (
    finish_report,
    glb_for_report,
    open_report,
    rendered_views,
    summary_section,
    timing_section,
    views_3d_body,
)
from monoplane.report.render3d import Mesh, RenderResult, Shot, render
from monoplane.report.viewer import install_viewer, viewer_section
from monoplane.report.viewpoints import orbit_viewpoints, zoom_to_fit

if TYPE_CHECKING:
    from monoplane.detect import CloudPlaneResult
    from monoplane.geometry.polygons import PlaneMesh

#: Size of the 3D renders in pixels.
RENDER_SIZE = (960, 720)


def cloud_glb(result: CloudPlaneResult, mesh: PlaneMesh | None = None) -> bytes:
    """``planes.glb`` of a point cloud: two-sided planes in the cloud's frame, palette colours.

    ``mesh`` is ``result.plane_mesh()`` when the caller already has it.
    """
    if mesh is None:
        mesh = result.plane_mesh()
    return planes_glb(mesh, result.planes, plane_palette(result.num_planes), double_sided=True)


def cloud_views(result: CloudPlaneResult, out_dir: Path) -> tuple[list[html.Figure], RenderResult]:
    """Render the plane meshes from a bird's eye view and two oblique views.

    "Up" is the normal of the plane with the most points (a floor, a table, the ground); the
    views look along a direction in that plane. Both sides of each plane are drawn, as a cloud
    has no camera whose side could be chosen.
    """
    mesh = result.plane_mesh()
    if len(mesh.triangles) == 0:
        return [], RenderResult({}, "no plane to render", 0.0)
    palette = plane_palette(result.num_planes) / 255.0
    face_plane = mesh.plane_ids - 1
    # One colour per vertex: no vertex is shared between planes.
    vertex_plane = np.zeros(len(mesh.vertices), np.int64)
    vertex_plane[mesh.triangles.reshape(-1)] = np.repeat(face_plane, 3)
    colors = shade(palette[vertex_plane], result.planes[vertex_plane, :3])
    mesh_3d = Mesh(mesh.vertices, mesh.triangles, colors)  # the renderer draws both sides
    up = result.planes[int(np.argmax(result.num_points)), :3]
    forward = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    width, height = RENDER_SIZE
    shots, figures = [], []
    for vp in orbit_viewpoints(mesh.vertices, up, forward, width, height):
        vp = zoom_to_fit(vp, mesh.vertices, width, height)
        shots.append(Shot(f"cloud3d_{vp.name}", vp.K, vp.world_to_cam, {0: None}, []))
        figures.append(html.Figure(f"cloud3d_{vp.name}.png",
                                   f"{vp.title}, planes coloured by id (both sides drawn)"))
    result_3d = render([mesh_3d], [], shots, out_dir, width, height)
    return [f for f in figures if f.src[:-4] in result_3d.paths], result_3d


def write_cloud_report(result: CloudPlaneResult, out_dir: Path, source: str = "",
                       render_3d: bool = True, progress: bool = False) -> Path:
    """Write ``report.html``, its renders and ``summary.png`` for the planes of a point cloud.

    The page shows ``planes.glb`` in an interactive 3D view (``planes.glb`` is written into
    ``out_dir`` when it is not there yet), the rendered views, a plane table, the notes, the
    timings and the configuration.

    Parameters
    ----------
    result : CloudPlaneResult
        Planes of the cloud, in its own frame and units.
    out_dir : pathlib.Path
        Folder for ``report.html`` and its pictures (created if missing).
    source : str
        The cloud's file name, for the title.
    render_3d, progress : bool
        As for :func:`~monoplane.report.frame.write_frame_report`.

    Returns
    -------
    pathlib.Path
        Path of ``report.html``.
    """
    out, bar, start = open_report(out_dir, 2, "cloud report", progress)
    bar.set_postfix_str("3D views")
    views, rendered = rendered_views(render_3d, lambda: cloud_views(result, out))
    bar.update()

    bar.set_postfix_str("html")
    notes = list(result.notes)
    if render_3d and rendered.reason:
        notes.append(f"3D views: {rendered.reason}")
    sections = []
    if views:
        fig.save_png(out / "summary.png", fig.contact_sheet(
            [(fig.load_png(out / f.src), f.caption.split(",")[0]) for f in views], columns=3))
        sections.append(summary_section("the rendered 3D views"))
    sections.append(viewer_section(
        glb_for_report(out, "planes.glb", lambda: cloud_glb(result)), "planes.glb",
        install_viewer(out), f"The {result.num_planes} planes in 3D, coloured by plane id, "
                             "both sides drawn."))
    sections.append(html.section("Rendered views", views_3d_body(
        views, rendered.reason, "The interactive view above does not depend on them.")))
    palette = plane_palette(result.num_planes)
    total = max(int(np.isfinite(result.points).all(axis=1).sum()), 1)
    rows = [[f"{html.swatch(palette[i])}{i + 1}",
             "(" + ", ".join(f"{x:+.3f}" for x in result.planes[i, :3]) + ")",
             f"{result.planes[i, 3]:.4g}",
             f"{int(result.num_points[i])} ({100.0 * result.num_points[i] / total:.1f} %)",
             f"{result.rmse[i]:.4g}",
             "(" + ", ".join(f"{x:.3g}" for x in result.centroids[i]) + ")"]
            for i in range(result.num_planes)]
    sections.append(html.section(
        "Plane table",
        html.paragraph("Each plane satisfies n · x + d = 0 in the cloud's frame and units, "
                       "with n on the side the points' normals face.")
        + html.table(["id", "normal (x, y, z)", "offset d", "points (share)", "RMSE",
                      "centroid"], rows, raw=True)))
    sections.append(html.section("Notes", html.bullet_list(notes) or html.paragraph("none")))
    sections.append(timing_section(result.timings, result.config,
                                   rendered.seconds if render_3d else None, start))
    labelled = int((result.labels > 0).sum())
    subtitle = (f"{result.points.shape[0]} points · {result.num_planes} planes covering "
                f"{100.0 * labelled / total:.1f} % of the points · "
                f"{datetime.now():%Y-%m-%d %H:%M}")
    title = f"monoplane cloud report: {Path(source).name}" if source else "monoplane cloud report"
    return finish_report(out, bar, title, subtitle, sections)
