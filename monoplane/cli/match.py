"""``monoplane match``: structure from motion only (cameras and sparse points)."""

from __future__ import annotations

import argparse
import sys

from monoplane.cli.common import add_pipeline_args, pipeline_from_args
from monoplane.export.files import check_output_dir
from monoplane.io.frames import load_frame

DESCRIPTION = """Run the configured matcher (default: pycolmap SIFT + exhaustive matching +
incremental mapping, on the CPU) on two or more images and write into --out:

  cameras.json  {"cameras": [{"image", "K": 3x3, "R": 3x3, "t": [3], "width", "height"}]},
                world-to-camera x_cam = R x_world + t, OpenCV axes (x right, y down, z forward)
  points.ply    the sparse 3D points, coloured

With --intrinsics the calibration is kept fixed; otherwise the focal length is estimated
(starting from a 60 degree horizontal field of view)."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("match", help="structure from motion: cameras and sparse points",
                       description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("images", nargs="+", metavar="IMG", help="two or more colour images")
    p.add_argument("--intrinsics", metavar="fx,fy,cx,cy|FILE.json",
                   help="known pinhole intrinsics shared by all images (kept fixed)")
    add_pipeline_args(p)
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (written atomically: nothing is left on failure)")
    p.add_argument("--overwrite", action="store_true", help="replace DIR if it exists")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monoplane.errors import InvalidInput
    from monoplane.multiview import hold_intrinsics_fixed, save_sfm
    from monoplane.multiview.registration import feature_correspondences, match_views

    check_output_dir(args.out, args.overwrite)  # fail before any work
    if len(args.images) < 2:
        raise InvalidInput(f"match needs at least 2 images, got {len(args.images)}")
    pipe = pipeline_from_args(args)
    if args.intrinsics and not hold_intrinsics_fixed(pipe) and not args.quiet:
        print(f"monoplane: note: matcher '{pipe.config.stages['matcher'][0]}' cannot hold "
              "intrinsics fixed; --intrinsics is its starting guess", file=sys.stderr)
    frames = [load_frame(img, intrinsics=args.intrinsics) for img in args.images]
    timings: dict[str, float] = {}
    sfm = match_views(pipe, frames, feature_correspondences(pipe, frames), "match", timings)
    out = save_sfm(sfm, args.out, overwrite=args.overwrite)
    if not args.quiet:
        pairs = ", ".join(f"{sfm.cameras[i].name}-{sfm.cameras[j].name}: {len(m)}"
                          for (i, j), m in sorted(sfm.matches.items()))
        missing = [c.name for c, ok in zip(sfm.cameras, sfm.registered, strict=True) if not ok]
        if missing:
            print(f"monoplane: warning: could not register {', '.join(missing)}",
                  file=sys.stderr)
        print(f"{sfm.num_views - len(missing)} cameras, {len(sfm.points)} points, "
              f"verified matches {pairs} "
              f"in {timings['matcher']:.2f} s -> {out}", file=sys.stdout)
    return 0
