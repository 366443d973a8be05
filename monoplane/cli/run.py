"""``monoplane run``: planes from one image."""

from __future__ import annotations

import argparse
import functools

from monoplane.cli.common import (
    add_input_args,
    add_output_args,
    add_pipeline_args,
    check_output_args,
    depth_reading,
    pipeline_from_args,
    write_rerun_arg,
)
from monoplane.export.saving import save
from monoplane.host.config import cue_model_overrides
from monoplane.host.cue_models import prepare_cue_model, require_depth_source
from monoplane.io.frames import load_frame

DESCRIPTION = """Recover the planes of one image and write labels.png (uint16, 0 = non-planar),
planes.json (normal . X + offset = 0 in the camera frame and the depth's units), planes.ply,
planes.glb (glTF, one mesh node per plane), depth_planar.npy and config.toml into --out.

Depth and normals come from --depth/--normals (RGB-D, precomputed network outputs), from a
catalogue model (--cues NAME, see 'monoplane models list'; --fetch downloads it once) or from
the configured cue provider (see 'monoplane plugins'). IMAGE may be omitted for depth-only
range images."""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("run", help="recover planes from one image",
                       description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("image", nargs="?", metavar="IMAGE", help="colour image (PNG, JPEG, ...)")
    add_input_args(p)
    group = p.add_argument_group("monocular models")
    group.add_argument("--cues", metavar="NAME",
                       help="predict depth/normals with a catalogue model (the configured cue "
                            "provider sets its own keys for it; onnx: cues.model=NAME) or, "
                            "with onnx, your own model's profile file NAME.toml "
                            "(cues.profile=NAME.toml, see docs/cues.md)")
    group.add_argument("--fetch", action="store_true",
                       help="download the configured catalogue model first if it is not "
                            "cached (nothing is downloaded without this flag)")
    add_pipeline_args(p)
    add_output_args(p)
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    check_output_args(args)  # fail before any work
    overrides = (cue_model_overrides(args.cues, args.preset, args.config, args.overrides)
                 if args.cues else args.overrides)
    pipe = pipeline_from_args(args, overrides)
    fetched = prepare_cue_model(pipe, fetch_missing=args.fetch,
                                has_depth=args.depth is not None,
                                has_normals=args.normals is not None)
    if fetched is not None and not args.quiet:
        name, result = fetched
        print(f"fetched {name} -> {result.path} (sha256 {result.sha256})")
    frame = load_frame(args.image, depth=args.depth, normals=args.normals,
                       intrinsics=args.intrinsics, **depth_reading(args))
    if frame.depth is None:
        require_depth_source(pipe, args.image)
    rec = pipe.run(frame)
    report = None
    if args.report:
        from monoplane.report import write_frame_report  # loads the plotting libraries

        report = functools.partial(write_frame_report, rec, progress=not args.quiet)
    out = save(rec, args.out, overwrite=args.overwrite, also=report)
    write_rerun_arg(args, rec)
    if not args.quiet:
        for note in rec.frame.notes:
            print(f"note: {note}")
        print(f"{rec.num_planes} planes in {rec.timings.get('total', 0.0):.2f} s -> {out}")
    return 0

