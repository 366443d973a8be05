"""The point-cloud report: the plane meshes in 3D (interactive and rendered) and a plane table."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from monoplane.export.gltf import cloud_glb
from monoplane.geometry.cloud_mesh import cloud_mesh
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
from monoplane.report.room import RoomFrame, estimate_room_frame, section_below
from monoplane.report.viewer import install_viewer, viewer_section
from monoplane.report.viewpoints import (
    facing_triangles,
    inside_viewpoints,
    orbit_viewpoints,
    zoom_to_fit,
)

if TYPE_CHECKING:
    from monoplane.datamodel import CloudResult

#: Size of the 3D renders in pixels.
RENDER_SIZE = (960, 720)
#: "Up" in a camera frame (y down): the prior for clouds in the frame of the camera that took
#: them, the frame a scan fused from camera poses usually has.
CAMERA_UP = (0.0, -1.0, 0.0)
#: The bird's eye and outside views cut everything above this share of the floor-to-ceiling
#: height away: the ceiling and the tops of the walls.
CUT_SHARE = 0.8


def room_frame(result: CloudResult, up_hint: tuple[float, float, float] | None = CAMERA_UP
               ) -> RoomFrame:
    """Up, floor and ceiling of a cloud (see :func:`~monoplane.report.room.estimate_room_frame`).

    ``up_hint`` is roughly up in the cloud's frame; the default suits clouds in a camera frame
    (y down), ``None`` lets the planes alone decide.
    """
    hint = None if up_hint is None else np.asarray(up_hint, dtype=np.float64)
    return estimate_room_frame(result.points, result.planes, result.support, hint)


def _horizontal_forward(up: np.ndarray) -> np.ndarray:
    """The cloud frame's z (a camera frame's viewing direction) made horizontal, or its x when
    z is nearly vertical."""
    for axis in ([0.0, 0.0, 1.0], [1.0, 0.0, 0.0]):
        fwd = np.asarray(axis) - (up @ axis) * up
        if np.linalg.norm(fwd) > 0.3:
            return fwd / np.linalg.norm(fwd)
    return np.cross(up, [0.0, 1.0, 0.0])


def cloud_views(result: CloudResult, out_dir: Path, frame: RoomFrame | None = None
                ) -> tuple[list[html.Figure], RenderResult]:
    """Render the plane meshes from above, from outside at an angle, and from inside.

    "Up" comes from the floor (``frame``, by default :func:`room_frame`), not from the largest
    plane, which in a room scan is often a wall. The bird's eye and the two outside views show
    the mesh below :data:`CUT_SHARE` of the room's height, so that neither the ceiling nor the
    tops of the walls hide the room; the outside and inside views also leave out planes seen
    from behind (a cloud's planes face the side their points' normals face, the scanner's).
    The inside views are drawn only when a plane was found to be the floor.
    """
    mesh = cloud_mesh(result)
    if len(mesh.triangles) == 0:
        return [], RenderResult({}, "no plane to render", 0.0)
    frame = frame or room_frame(result)
    palette = plane_palette(result.num_planes) / 255.0
    face_plane = mesh.plane_ids - 1
    # One colour per vertex: no vertex is shared between planes.
    vertex_plane = np.zeros(len(mesh.vertices), np.int64)
    vertex_plane[mesh.triangles.reshape(-1)] = np.repeat(face_plane, 3)
    colors = shade(palette[vertex_plane], result.planes[vertex_plane, :3])
    full = Mesh(mesh.vertices, mesh.triangles, colors)  # the renderer draws both sides
    room = frame.top_height - frame.floor_height
    cut, cut_plane = section_below(full, face_plane, frame, CUT_SHARE * room)
    if len(cut.indices) == 0:
        cut, cut_plane = full, face_plane
    up = frame.up
    forward = _horizontal_forward(up)
    width, height = RENDER_SIZE
    shots, figures = [], []
    for vp in orbit_viewpoints(cut.points, up, forward, width, height):
        keep = None if vp.name == "birdseye" else facing_triangles(cut_plane, result.planes,
                                                                   vp.eye)
        shown = cut.points if keep is None else cut.points[cut.indices[keep].reshape(-1)]
        vp = zoom_to_fit(vp, shown if len(shown) else cut.points, width, height)
        shots.append(Shot(f"cloud3d_{vp.name}", vp.K, vp.world_to_cam, {1: keep}, []))
        what = ("ceiling and wall tops cut away" if vp.name == "birdseye" else
                "ceiling cut away, planes seen from behind left out")
        figures.append(html.Figure(f"cloud3d_{vp.name}.png",
                                   f"{vp.title}, planes coloured by id ({what})"))
    # Inside views need a room: without a floor, nothing says where one could stand.
    inside = [] if frame.floor is None else inside_viewpoints(
        mesh.vertices, up, forward, frame.floor_height, frame.top_height, width, height)
    for vp in inside:
        keep = facing_triangles(face_plane, result.planes, vp.eye)
        shots.append(Shot(f"cloud3d_{vp.name}", vp.K, vp.world_to_cam, {0: keep}, []))
        figures.append(html.Figure(f"cloud3d_{vp.name}.png",
                                   f"{vp.title}, planes coloured by id (planes seen from "
                                   f"behind left out)"))
    result_3d = render([full, cut], [], shots, out_dir, width, height)
    return [f for f in figures if f.src[:-4] in result_3d.paths], result_3d


def write_cloud_report(result: CloudResult, out_dir: Path, source: str = "",
                       render_3d: bool = True, progress: bool = False,
                       up_hint: tuple[float, float, float] | None = CAMERA_UP) -> Path:
    """Write ``report.html``, its renders and ``summary.png`` for the planes of a point cloud.

    The page shows ``planes.glb`` in an interactive 3D view (``planes.glb`` is written into
    ``out_dir`` when it is not there yet), the rendered views, a plane table, the notes, the
    timings and the configuration.

    Parameters
    ----------
    result : CloudResult
        Planes of the cloud, in its own frame and units.
    out_dir : pathlib.Path
        Folder for ``report.html`` and its pictures (created if missing).
    source : str
        The cloud's file name, for the title.
    render_3d, progress : bool
        As for :func:`~monoplane.report.frame.write_frame_report`.
    up_hint : tuple of float or None
        Roughly up in the cloud's frame, a prior for the views' "up" (see :func:`room_frame`).

    Returns
    -------
    pathlib.Path
        Path of ``report.html``.
    """
    out, bar, start = open_report(out_dir, 2, "cloud report", progress)
    bar.set_postfix_str("3D views")
    frame = room_frame(result, up_hint)
    views, rendered = rendered_views(render_3d, lambda: cloud_views(result, out, frame))
    bar.update()

    bar.set_postfix_str("html")
    notes = list(result.notes)
    if views:
        notes.append(f"3D views: up is {tuple(round(float(x), 3) for x in frame.up)}; "
                     f"{frame.reason}")
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
             f"{int(result.support[i])} ({100.0 * result.support[i] / total:.1f} %)",
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
