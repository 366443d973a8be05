"""``monoplane multiview``: planes of a scene seen in a few images."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from monoplane.cli.common import (
    add_input_args,
    add_output_args,
    add_pipeline_args,
    check_output_args,
    depth_reading,
    pipeline_from_args,
    write_rerun_arg,
)
from monoplane.geometry.plane_adjustment import refinement_summary
from monoplane.io.frames import load_frame

DESCRIPTION = """Sparse-view planar reconstruction (MonoPlane §III-C): structure from motion
(pycolmap SIFT, CPU), monocular cues per image, scale alignment of each depth onto the SfM
points, single-view planes per image, then plane matching and fusion into global planes.

Writes into --out: view_000/, view_001/, ... (the single-view outputs of each image, planes in
that camera's frame), scene.json (cameras and global planes in the SfM world frame, with the
links from view planes to global planes), scene.ply (one coloured polygon per global plane),
scene.glb (the same planes, one glTF mesh node per global plane, and the cameras),
cameras.json and points.ply (sparse SfM points). Each view folder also holds
labels_global.png (global plane id + 1 per pixel).

Images that structure from motion cannot register (and weakly supported SfM placements) go to
the registrar stage ([registrar], default plane-aware): it places them from their planes,
normals, depth and whatever feature matches exist, verifies each pose densely, and names the
method and evidence in cameras.json. Images no method places are left out, named with their
reason in a warning and in scene.json ("unregistered"). --strict makes that an error instead.

--depth/--normals, when given, take one file per image, in image order."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("multiview", help="planes from a few views (SfM + per-view planes + fusion)",
                       description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("images", nargs="+", metavar="IMG", help="two or more colour images")
    add_input_args(p, per_image=True)
    add_pipeline_args(p)
    add_output_args(p)
    p.add_argument("--strict", action="store_true",
                   help="fail when any image cannot be registered (default: reconstruct the "
                        "registered ones and name the others in scene.json and a warning)")
    p.add_argument("--workers", type=int, metavar="N",
                   help="processes for the per-view stages (default: the available CPUs)")
    p.add_argument("--quiet", action="store_true", help="no progress bars or summary")
    p.set_defaults(func=run)


def _per_image(files: list[str] | None, n: int, what: str) -> list[str | None]:
    from monoplane.errors import InvalidInput

    if files is None:
        return [None] * n
    if len(files) != n:
        raise InvalidInput(f"{len(files)} {what} files for {n} images; give one per image")
    return list(files)


def run(args: argparse.Namespace) -> int:
    from monoplane.errors import InvalidInput
    from monoplane.export.saving import save
    from monoplane.multiview import hold_given_intrinsics, reconstruct_multiview, scene_summary

    check_output_args(args)  # fail before any work
    n = len(args.images)
    if n < 2:
        raise InvalidInput(f"multiview needs at least 2 images, got {n}")
    depths = _per_image(args.depth, n, "--depth")
    normals = _per_image(args.normals, n, "--normals")
    if args.workers is not None and args.workers < 1:
        raise InvalidInput(f"--workers must be at least 1, got {args.workers}")
    pipe = pipeline_from_args(args)
    note = hold_given_intrinsics(pipe) if args.intrinsics else None
    if note and not args.quiet:
        print(f"monoplane: note: {note}", file=sys.stderr)
    frames = [
        load_frame(img, depth=d, normals=nm, intrinsics=args.intrinsics, **depth_reading(args))
        for img, d, nm in zip(args.images, depths, normals, strict=True)
    ]
    if not args.quiet and not args.intrinsics:
        print("monoplane: note: intrinsics not given: the focal length is estimated by SfM "
              "from a 60 degree field-of-view start", file=sys.stderr)
    result = reconstruct_multiview(frames, pipe, progress=not args.quiet, strict=args.strict,
                                   workers=args.workers)
    out = save(result, args.out, overwrite=args.overwrite, also=_scene_report(args, result))
    write_rerun_arg(args, result)
    if not args.quiet:
        print(f"{scene_summary(result)} -> {out}")
        refined = refinement_summary(result.adjustment)
        if refined:
            print(refined)
    return 0


def _scene_report(args: argparse.Namespace, result: Any):  # -> Callable[[Path], None] | None
    """With ``--report``, what writes ``report.html`` into the output folder."""
    if not args.report:
        return None
    from monoplane.report import write_scene_report

    return lambda folder: write_scene_report(result.scene, folder)
