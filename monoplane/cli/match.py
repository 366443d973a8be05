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
    from monoplane.multiview import (
        hold_given_intrinsics,
        save_sfm,
        sfm_summary,
        structure_from_motion,
        unregistered_names,
    )

    check_output_dir(args.out, args.overwrite)  # fail before any work
    if len(args.images) < 2:
        raise InvalidInput(f"match needs at least 2 images, got {len(args.images)}")
    pipe = pipeline_from_args(args)
    note = hold_given_intrinsics(pipe) if args.intrinsics else None
    if note and not args.quiet:
        print(f"monoplane: note: {note}", file=sys.stderr)
    frames = [load_frame(img, intrinsics=args.intrinsics) for img in args.images]
    timings: dict[str, float] = {}
    sfm = structure_from_motion(pipe, frames, "match", timings)
    out = save_sfm(sfm, args.out, overwrite=args.overwrite)
    if not args.quiet:
        missing = unregistered_names(sfm)
        if missing:
            print(f"monoplane: warning: could not register {', '.join(missing)}",
                  file=sys.stderr)
        print(f"{sfm_summary(sfm, timings['matcher'])} -> {out}", file=sys.stdout)
    return 0
