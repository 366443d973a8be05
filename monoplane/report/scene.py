"""The multi-view report: cameras and fused global planes in 3D, per-view label maps, tables."""

from __future__ import annotations

import time
from datetime import datetime
from pathlib import Path

import numpy as np
from tqdm import tqdm

from monoplane.datamodel import Reconstruction, Scene, plane_to_camera, plane_to_world
from monoplane.export.gltf import SOURCE_TO_GLTF, scene_glb
from monoplane.geometry.camera import frustum
from monoplane.geometry.mesh import planar_mesh
from monoplane.report import figures as fig
from monoplane.report import html
from monoplane.report.colors import LIGHT_DIRECTION, plane_palette, shade
from monoplane.report.frame import (
    estimate_up,
    finish_report,
    glb_for_report,
    mesh_step,
    open_report,
    render_size,
    rendered_views,
    summary_section,
    views_3d_body,
)
from monoplane.report.render3d import Lines, Mesh, RenderResult, Shot, render
from monoplane.report.viewer import install_viewer, viewer_section
from monoplane.report.viewpoints import facing_triangles, orbit_viewpoints, zoom_to_fit

#: Colour of planes that no global plane claims, in 3D views and label maps.
UNLINKED_GREY = np.array([170, 170, 170], dtype=np.uint8)


def global_label_maps(scene: Scene) -> list[np.ndarray]:
    """Per-view label maps renumbered to global plane ids.

    Returns
    -------
    list of numpy.ndarray
        (H, W) int32 per view: ``g + 1`` for pixels of a local plane linked to global plane
        ``g`` (0-based), ``G + 1 + k`` for the ``k``-th unlinked local plane of the view (so that
        it gets a colour distinct from every global plane), 0 for non-planar pixels.
    """
    G = scene.planes.shape[0]
    out = []
    for rec, links in zip(scene.views, scene.links, strict=True):
        lut = np.zeros(rec.num_planes + 1, dtype=np.int32)
        k = 0
        for local in range(1, rec.num_planes + 1):
            if local in links:
                lut[local] = links[local] + 1
            else:
                k += 1
                lut[local] = G + k
        out.append(lut[rec.labels])
    return out


def fused_view_mesh(rec: Reconstruction, links: dict[int, int], planes_world: np.ndarray,
                    R: np.ndarray, t: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One view's planar mesh with linked planes snapped onto their fused global plane.

    Each linked pixel is lifted along its ray onto the global plane (expressed in this camera's
    frame), so the views' pieces of one global plane meet in one surface.

    Returns
    -------
    vertices : numpy.ndarray
        (V, 3) world points.
    triangles : numpy.ndarray
        (T, 3) int32 indices into ``vertices``.
    colors : numpy.ndarray
        (V, 3) image colours in [0, 1].
    local_ids : numpy.ndarray
        (V,) int local plane id (1..P) of each vertex.
    planes : numpy.ndarray
        (P, 4) the view's planes in world coordinates (after snapping), positive on the side the
        camera saw; row ``local - 1`` is local plane ``local``.
    """
    params = rec.planes.copy()
    for local, g in links.items():
        params[local - 1] = plane_to_camera(planes_world[g], R, t)[0]
    snapped = Reconstruction(frame=rec.frame, labels=rec.labels, planes=params)
    v, tris, colors, local_ids = planar_mesh(snapped, mesh_step(*rec.frame.shape))
    return (v - t) @ R, tris, colors, local_ids, plane_to_world(snapped.planes, R, t)


def scene_views(scene: Scene, out_dir: Path) -> tuple[list[html.Figure], RenderResult]:
    """Render cameras and fused planes from a bird's eye and two oblique viewpoints."""
    G = scene.planes.shape[0]
    palette = plane_palette(G) / 255.0
    # Light from the first camera's viewpoint, so that orientations read as in view 1.
    light = scene.cameras[0].R.T @ LIGHT_DIRECTION
    verts, tris, img_cols, plane_cols, tri_planes, planes = [], [], [], [], [], []
    offset = plane_offset = 0
    for cam, rec, links in zip(scene.cameras, scene.views, scene.links, strict=True):
        v, t, c, local_ids, pw = fused_view_mesh(rec, links, scene.planes, cam.R, cam.t)
        lut = np.full(rec.num_planes + 1, -1)
        for local, g in links.items():
            lut[local] = g
        gid = lut[local_ids]
        base = np.where(gid[:, None] >= 0, palette[np.maximum(gid, 0)], UNLINKED_GREY / 255.0)
        verts.append(v)
        tris.append(t + offset)
        img_cols.append(c)
        plane_cols.append(shade(base, pw[local_ids - 1, :3], light))
        tri_planes.append(local_ids[t[:, 0]] - 1 + plane_offset)
        planes.append(pw)
        offset += len(v)
        plane_offset += len(pw)
    vertices = np.vstack(verts)
    triangles = np.vstack(tris).astype(np.int32)
    if len(triangles) == 0:
        return [], RenderResult({}, "no planar surface to render in 3D", 0.0)
    tri_plane = np.concatenate(tri_planes)
    all_planes = np.vstack(planes)
    meshes = [Mesh(vertices, triangles, np.vstack(plane_cols)),
              Mesh(vertices, triangles, np.vstack(img_cols))]

    radius = float(np.percentile(np.linalg.norm(vertices - np.median(vertices, 0), axis=1), 90))
    lines: list[Lines] = []
    frustum_pts = []
    for i, cam in enumerate(scene.cameras):
        pts, edges = frustum(cam.K, cam.R, cam.t, cam.width, cam.height, 0.2 * radius)
        colour = np.array([0.1, 0.1, 0.1]) if i else np.array([0.85, 0.1, 0.1])
        lines.append(Lines(pts, edges, np.tile(colour, (len(edges), 1))))
        frustum_pts.append(pts)
    up = scene.cameras[0].R.T @ estimate_up(scene.views[0])
    forward = np.mean([cam.R[2] for cam in scene.cameras], axis=0)
    width, height = render_size(scene.cameras[0].height, scene.cameras[0].width)
    shots, figures = [], []
    for vp in orbit_viewpoints(vertices, up, forward, width, height):
        keep = facing_triangles(tri_plane, all_planes, vp.eye)
        vp = zoom_to_fit(vp, vertices[np.unique(triangles[keep])], width, height,
                         always=np.vstack(frustum_pts))
        for j, kind in enumerate(("planes", "texture")):
            name = f"scene3d_{vp.name}_{kind}"
            shots.append(Shot(name, vp.K, vp.world_to_cam, {j: keep}, list(range(len(lines)))))
            label = "fused planes by global id" if kind == "planes" else "image texture"
            figures.append(html.Figure(f"{name}.png", f"{vp.title}, {label}; cameras as "
                                                      "frusta (view 1 red)"))
    result = render(meshes, lines, shots, out_dir, width, height)
    return [f for f in figures if f.src[:-4] in result.paths], result


def first_camera_orbit(scene: Scene, raise_deg: float = 15.0) -> tuple[float, float]:
    """Start the interactive view from the first camera's side of the scene.

    The direction is from the middle of what view 0 sees (the median of its depth's points) to
    its camera, in ``scene.glb``'s glTF frame, raised by ``raise_deg`` (as a single view's
    report starts 15° above its camera) so that the planes are seen a little from above.

    Returns
    -------
    (float, float)
        model-viewer's ``camera-orbit`` angles in radians: azimuth about +y from +z, and polar
        angle from +y.
    """
    cam, frame = scene.cameras[0], scene.views[0].frame
    valid = frame.depth > 0 if frame.depth is not None else None
    middle = (np.median(frame.points()[valid], axis=0) if valid is not None and valid.any()
              else np.array([0.0, 0.0, 1.0]))
    d = SOURCE_TO_GLTF @ (cam.center - (middle - cam.t) @ cam.R)
    azimuth = float(np.arctan2(d[0], d[2]))
    polar = float(np.arccos(np.clip(d[1] / max(np.linalg.norm(d), 1e-12), -1.0, 1.0)))
    return azimuth, float(np.clip(polar - np.deg2rad(raise_deg), 0.05, np.pi - 0.05))


def write_scene_report(scene: Scene, out_dir: Path, render_3d: bool = True,
                       progress: bool = False) -> Path:
    """Write ``report.html``, its PNG figures and ``summary.png`` for a multi-view scene.

    The page also shows ``scene.glb`` (fused planes and cameras) in an interactive 3D view;
    ``scene.glb`` is written into ``out_dir`` when it is not there yet.

    Parameters
    ----------
    scene : Scene
        Cameras (world-to-camera, OpenCV axes), per-view reconstructions, global planes
        (world frame) and view-to-global links.
    out_dir : pathlib.Path
        Folder for ``report.html`` and the PNGs (created if missing).
    render_3d : bool
        Render cameras and fused planes (:mod:`~monoplane.report.render3d`). When false, or
        when rendering fails, the report keeps its 2D figures and says why 3D views are missing.
    progress : bool
        Show a progress bar on stderr.

    Returns
    -------
    pathlib.Path
        Path of ``report.html``.
    """
    n_views, G = len(scene.views), scene.planes.shape[0]
    out, bar, start = open_report(out_dir, n_views + 2, "scene report", progress)

    bar.set_postfix_str("3D views")
    views3d, rendered = rendered_views(render_3d, lambda: scene_views(scene, out))
    bar.update()

    per_view = _view_figures(scene, out, bar)

    bar.set_postfix_str("html")
    plane_rows = _global_plane_rows(scene)
    cam_rows = _camera_rows(scene)
    panels = [(fig.load_png(out / f.src), f.caption.split(":")[0]) for f in per_view[1::2][:3]]
    panels += [(fig.load_png(out / f.src), f.caption.split(",")[0]) for f in views3d
               if f.src.endswith("_planes.png")]
    fig.save_png(out / "summary.png", fig.contact_sheet(panels, columns=3))
    body3d = views_3d_body(views3d, rendered.reason, "The per-view figures below are complete.")
    notes = list(dict.fromkeys(n for rec in scene.views for n in rec.frame.notes))
    if render_3d and rendered.reason:
        notes.append(f"3D views: {rendered.reason}")
    timing = [["3D rendering (report)", f"{rendered.seconds:.3f}"],
              ["report total", f"{time.perf_counter() - start:.3f}"]]
    sections = [
        summary_section("the first views' planes by global id and the rendered 3D views"),
        viewer_section(glb_for_report(out, "scene.glb", lambda: scene_glb(scene)), "scene.glb",
                       install_viewer(out),
                       f"The {G} fused planes in the world frame, coloured by global id as in "
                       "the views below, and the cameras as pyramids (view 1 red), seen at "
                       "first from view 1's side.", orbit=first_camera_orbit(scene)),
        html.section("Cameras and fused planes in 3D", body3d),
        html.section("Views", html.figure_grid(per_view, 2)),
        html.section("Global planes",
                     html.paragraph("n · x + d = 0 in the world frame of the reconstruction "
                                    "(SfM units). 'seen in' lists view:local-plane pairs.")
                     + html.table(["id", "normal (x, y, z)", "offset d", "seen in",
                                   "area px"], plane_rows, raw=True)),
        html.section("Cameras", html.table(
            ["view", "image", "centre (x, y, z)", "depth scale", "planes", "linked"],
            cam_rows, left=2)),
        html.section("Notes", html.bullet_list(notes) or html.paragraph("none")),
        html.section("Timing", html.table(["step", "seconds"], timing)),
    ]
    subtitle = (f"{n_views} views · {G} global planes · {len(scene.points)} sparse points · "
                f"{datetime.now():%Y-%m-%d %H:%M}")
    return finish_report(out, bar, "monoplane multi-view report", subtitle, sections)


def _view_figures(scene: Scene, out: Path, bar: tqdm) -> list[html.Figure]:
    """Write each view's image and its planes by global id (G…, and L… for the planes only
    that view has); one progress step per view."""
    G, n_views = scene.planes.shape[0], len(scene.views)
    per_view: list[html.Figure] = []
    maps = global_label_maps(scene)
    n_colours = G + max((r.num_planes for r in scene.views), default=0)
    for v, (rec, links, lab) in enumerate(zip(scene.views, scene.links, maps, strict=True)):
        bar.set_postfix_str(f"view {v + 1}/{n_views}")
        names = {g + 1: f"G{g}" for g in range(G)}
        names.update({G + k: f"L{local}" for k, local in enumerate(
            [lo for lo in range(1, rec.num_planes + 1) if lo not in links], start=1)})
        fig.save_png(out / f"view{v + 1}_input.png", fig.input_image(rec.frame.rgb,
                                                                     rec.frame.shape))
        fig.save_png(out / f"view{v + 1}_labels.png",
                     fig.overlay_labels(rec.frame.rgb, lab, n_planes=n_colours, id_names=names))
        title = rec.frame.name or scene.cameras[v].name
        per_view += [
            html.Figure(f"view{v + 1}_input.png", f"view {v + 1}: {title}"),
            html.Figure(f"view{v + 1}_labels.png",
                        f"view {v + 1}: planes by global id (G…); L…: planes only this view "
                        "has (grey in 3D)"),
        ]
        bar.update()
    return per_view


def _global_plane_rows(scene: Scene) -> list[list[str]]:
    """Rows of the global plane table: swatch and id, normal, offset, the view:local planes
    it fuses and their area in pixels."""
    G = scene.planes.shape[0]
    palette = plane_palette(max(G, 1))
    owners: dict[int, list[str]] = {g: [] for g in range(G)}
    area = np.zeros(G, dtype=np.int64)
    for v, (rec, links) in enumerate(zip(scene.views, scene.links, strict=True)):
        for local, g in sorted(links.items()):
            owners[g].append(f"{v + 1}:{local}")
            area[g] += rec.area_px[local - 1]
    return [
        [f"{html.swatch(palette[g])}G{g}",
         "(" + ", ".join(f"{x:+.3f}" for x in scene.planes[g, :3]) + ")",
         f"{scene.planes[g, 3]:.3f}", html.esc(", ".join(owners[g]) or "none"), f"{area[g]}"]
        for g in range(G)
    ]


def _camera_rows(scene: Scene) -> list[list[str]]:
    """Rows of the camera table: view, image, centre, depth scale, planes, linked planes."""
    cam_rows = []
    for v, (cam, rec, links) in enumerate(zip(scene.cameras, scene.views, scene.links,
                                                 strict=True)):
        scale = f"{scene.scales[v]:.4g}" if v < len(scene.scales) else "n/a"
        cam_rows.append([f"{v + 1}", cam.name or rec.frame.name,
                         "(" + ", ".join(f"{x:+.3f}" for x in cam.center) + ")", scale,
                         f"{rec.num_planes}", f"{len(links)}"])
    return cam_rows
