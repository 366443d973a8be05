"""``monoplane cloud``: planes of a point cloud file."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from monoplane.cli.common import add_rerun_arg, add_set_arg, check_output_args, write_rerun_arg
from monoplane.errors import InvalidInput

DESCRIPTION = """Detect the planes of a point cloud (PLY, PCD, XYZ or PTS) with MonoPlane's
graph-cut RANSAC and the graph-crf refiner, and write into --out:

  labels.npy    (N,) int32 plane of each input point, in the input order, 0 = no plane
  planes.json   per plane: normal, offset (normal . X + offset = 0), num_points, rmse,
                centroid, in the cloud's own frame and units
  labelled.ply  the points coloured by plane (grey = no plane)
  planes.ply    each plane's area triangulated with its holes, faces tagged plane_id
  planes.glb    the same triangles as glTF, one mesh node plane_<id> per plane
  config.toml   the resolved configuration
  report.html   with --report: an interactive 3D view, 3D renders (cloud3d_*.png,
                summary.png) and a plane table

Missing normals are estimated and turned towards --set cloud.viewpoint=[x,y,z] (default the
origin: right for a single scan whose sensor sat there); for fused scans or sampled meshes use
--set cloud.orient=consistent. See docs/clouds.md."""

EPILOG = """examples:
  monoplane cloud scan.ply --out out/scan
  monoplane cloud room.pcd --out out/room --set cloud.orient=consistent --report
  monoplane cloud lidar_room.ply --out out/room --report --up 0,0,1
  monoplane cloud lidar.xyz --out out/lidar --set ransac.epsilon=0.01"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("cloud", help="detect planes in a point cloud file",
                       description=DESCRIPTION, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("cloud", metavar="IN", help="point cloud: .ply, .pcd, .xyz or .pts")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--preset", default="cloud",
                   help="config preset (default: cloud); its refiner must work without pixels")
    add_set_arg(p)
    p.add_argument("--report", action="store_true",
                   help="also write report.html: the planes in an interactive 3D view, 3D "
                        "renders and a plane table")
    p.add_argument("--up", default="0,-1,0", metavar="X,Y,Z|none", type=_up_hint,
                   help="the report's prior for 'up' in the cloud's frame (default 0,-1,0: a "
                        "camera frame, y down; 0,0,1 for z-up clouds, 0,1,0 for y-up; none: "
                        "the planes alone decide); the floor plane itself sets 'up'")
    add_rerun_arg(p)
    p.add_argument("--overwrite", action="store_true", help="replace a non-empty --out")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def _up_hint(text: str) -> tuple[float, float, float] | None:
    """``--up``: three numbers, not all zero, or ``none``."""
    if text.strip().lower() == "none":
        return None
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not np.all(np.isfinite(values)) or not any(values):
        raise argparse.ArgumentTypeError(f"expected X,Y,Z (not all zero) or none, got {text!r}")
    return values  # type: ignore[return-value]


def run(args: argparse.Namespace) -> int:
    from monoplane.export.saving import save
    from monoplane.host.detect import detect_planes
    from monoplane.io.clouds import read_point_cloud

    check_output_args(args)  # fail before any work
    cloud = read_point_cloud(args.cloud)
    try:
        result = detect_planes(cloud.to_open3d(), preset=args.preset,
                               overrides=args.overrides or None)
    except InvalidInput as exc:  # what is wrong with the points: name the file
        raise InvalidInput(f"point cloud {args.cloud}: {exc}") from None
    result.source = str(args.cloud)
    report = None
    if args.report:
        from monoplane.report.cloud import write_cloud_report

        def report(folder: Path) -> None:
            write_cloud_report(result, folder, source=str(args.cloud), progress=not args.quiet,
                               up_hint=args.up)
    save(result, args.out, args.overwrite, also=report)
    write_rerun_arg(args, result)
    if not args.quiet:
        for note in result.notes:
            print(f"note: {note}")
        print(f"{result.num_planes} planes in {result.timings['total']:.2f} s -> {args.out}")
    return 0
