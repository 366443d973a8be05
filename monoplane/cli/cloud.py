"""``monoplane cloud``: planes of a point cloud file."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.fileio import atomic_output_dir, check_output_dir, write_plane_mesh_ply

DESCRIPTION = """Detect the planes of a point cloud (PLY, PCD, XYZ or PTS) with MonoPlane's
graph-cut RANSAC and the graph-crf refiner, and write into --out:

  labels.npy    (N,) int32 plane of each input point, in the input order, 0 = no plane
  planes.json   per plane: normal, offset (normal . X + offset = 0), num_points, rmse,
                centroid, in the cloud's own frame and units
  labelled.ply  the points coloured by plane (grey = no plane)
  planes.ply    each plane's area triangulated with its holes, faces tagged plane_id
  config.toml   the resolved configuration
  report/       with --report: 3D renders of the planes

Missing normals are estimated and turned towards --set cloud.viewpoint=[x,y,z] (default the
origin: right for a single scan whose sensor sat there); for fused scans or sampled meshes use
--set cloud.orient=consistent. See docs/clouds.md."""

EPILOG = """examples:
  monoplane cloud scan.ply --out out/scan
  monoplane cloud room.pcd --out out/room --set cloud.orient=consistent --report
  monoplane cloud lidar.xyz --out out/lidar --set ransac.epsilon=0.01"""

SUFFIXES = (".ply", ".pcd", ".xyz", ".xyzn", ".xyzrgb", ".pts")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("cloud", help="detect planes in a point cloud file",
                       description=DESCRIPTION, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("cloud", metavar="IN", help="point cloud: .ply, .pcd, .xyz or .pts")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--preset", default="cloud",
                   help="config preset (default: cloud); its refiner must work without pixels")
    p.add_argument("--set", dest="overrides", action="append", default=[],
                   metavar="TABLE.KEY=VALUE", help="override one parameter (repeatable)")
    p.add_argument("--report", action="store_true", help="also render the planes in 3D")
    p.add_argument("--overwrite", action="store_true", help="replace a non-empty --out")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def read_cloud(path: str | Path) -> Any:
    """Read a point cloud file with Open3D; one-line errors for missing or empty files."""
    import open3d as o3d

    p = Path(path)
    if not p.is_file():
        raise InvalidInput(f"point cloud {p} not found")
    if p.suffix.lower() not in SUFFIXES:
        raise InvalidInput(f"point cloud {p}: unsupported format '{p.suffix}'; use "
                           f"{', '.join(SUFFIXES)}")
    fmt = "xyz" if p.suffix.lower() == ".xyz" else "auto"
    pcd = o3d.io.read_point_cloud(str(p), format=fmt)
    if len(pcd.points) == 0:
        raise InvalidInput(f"point cloud {p} holds no point or cannot be read")
    return pcd


def _render_report(result: Any, folder: Path) -> str | None:
    """3D renders of the plane meshes; returns why nothing was rendered, or None."""
    from monoplane.report.colors import shade
    from monoplane.report.render3d import Mesh, Shot, render
    from monoplane.report.viewpoints import orbit_viewpoints, zoom_to_fit

    verts, tris, cols = [], [], []
    offset = 0
    for pid, mesh in enumerate(result.plane_meshes(), start=1):
        if len(mesh.triangles) == 0:
            continue
        v = np.asarray(mesh.vertices)
        base = np.tile(result.plane_colors()[pid], (len(v), 1))
        n = np.tile(result.planes[pid - 1, :3], (len(v), 1))
        verts.append(v)
        tris.append(np.asarray(mesh.triangles) + offset)
        cols.append(shade(base, n))
        offset += len(v)
    if not verts:
        return "no plane to render"
    vertices, triangles = np.vstack(verts), np.vstack(tris).astype(np.int32)
    # "Up" is the normal of the largest plane (floor, table, ground); the views look along
    # any direction in that plane.
    up = result.planes[int(np.argmax(result.num_points)), :3]
    forward = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    width, height = 960, 720
    shots = []
    both_sides = np.vstack([triangles, triangles[:, ::-1]])
    mesh = Mesh(vertices, both_sides, np.vstack(cols))
    for vp in orbit_viewpoints(vertices, up, forward, width, height):
        vp = zoom_to_fit(vp, vertices, width, height)
        shots.append(Shot(f"cloud3d_{vp.name}", vp.K, vp.world_to_cam, {0: None}, []))
    folder.mkdir(parents=True, exist_ok=True)
    return render([mesh], [], shots, folder, width, height).reason


def run(args: argparse.Namespace) -> int:
    import open3d as o3d

    from monoplane.config import dumps_toml
    from monoplane.detect import detect_planes

    check_output_dir(args.out, args.overwrite)  # fail before any work
    pcd = read_cloud(args.cloud)
    result = detect_planes(pcd, preset=args.preset, overrides=args.overrides or None)
    reason = None
    with atomic_output_dir(args.out, args.overwrite) as tmp:
        np.save(tmp / "labels.npy", result.labels)
        doc = {"source": str(args.cloud), **result.planes_document()}
        (tmp / "planes.json").write_text(json.dumps(doc, indent=2) + "\n")
        (tmp / "config.toml").write_text(dumps_toml(result.config))
        if not o3d.io.write_point_cloud(str(tmp / "labelled.ply"), result.to_open3d()):
            raise InvalidInput(f"cannot write {args.out}/labelled.ply")
        colors = np.round(result.plane_colors()[1:] * 255).astype(np.uint8)
        write_plane_mesh_ply(tmp / "planes.ply", result.plane_mesh(), colors)
        if args.report:
            reason = _render_report(result, tmp / "report")
    if not args.quiet:
        for note in result.notes:
            print(f"note: {note}")
        if reason:
            print(f"note: no 3D renders: {reason}")
        print(f"{result.num_planes} planes in {result.timings['total']:.2f} s -> {args.out}")
    return 0
