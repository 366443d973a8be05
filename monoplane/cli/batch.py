"""``monoplane batch``: many frames, in parallel, resumable."""

from __future__ import annotations

import argparse

from monoplane.cli.common import (
    add_depth_value_args,
    add_pipeline_args,
    add_rerun_arg,
    check_rerun_arg,
    depth_reading,
)

DESCRIPTION = """Recover the planes of every frame of INPUT into DIR/<name>/ (the files of
'monoplane run'), then write DIR/summary.json (status, planes, seconds and error of every frame,
and the config) and, with --report, DIR/index.html.

With --rerun FILE.rrd, every finished frame is also logged into one Rerun recording, frame i
of INPUT at step i of the timeline 'frame'.

INPUT is a folder of frame folders (rgb.png or rgb.jpg, optional depth.npy or depth.png,
normals.npy, intrinsics.json; the layout of data_samples/room_000) or a .jsonl/.csv manifest
with the columns name, image, depth, normals, intrinsics, depth_scale, depth_encoding (paths
relative to the manifest; an empty image means a depth-only frame; depth_encoding as
--depth-encoding, so frames of several datasets can share a manifest).

Frames whose folder is complete are skipped, so a killed batch resumes where it stopped;
--overwrite recomputes everything. A failing frame is recorded with its reason and the others
go on; the exit status is 1 when any frame failed."""

EXAMPLES = """examples:
  monoplane batch data_samples --out out/batch --workers 2 --report
  monoplane batch frames.jsonl --out out/scannet --depth-scale 1000 --engine ray
  monoplane batch frames.csv --out /shared/out --engine ray --ray-address auto
  monoplane batch frames.csv --out /shared/out --engine ray --ray-address 10.0.0.5:6379"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("batch", help="recover planes from many frames (folder or manifest)",
                       description=DESCRIPTION, epilog=EXAMPLES,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("input", metavar="INPUT", help="folder of frame folders, or .jsonl/.csv "
                                                  "manifest")
    add_pipeline_args(p)
    add_depth_value_args(p.add_argument_group("inputs"),
                         scale_note="; a manifest's depth_scale and depth_encoding columns "
                                    "win")
    out = p.add_argument_group("outputs")
    out.add_argument("--out", required=True, metavar="DIR", help="batch output folder")
    out.add_argument("--overwrite", action="store_true",
                     help="recompute every frame (default: skip frames already complete)")
    out.add_argument("--report", action="store_true",
                     help="write each frame's report.html and DIR/index.html")
    add_rerun_arg(out)
    run = p.add_argument_group("execution")
    run.add_argument("--engine", choices=("local", "ray"), default="local",
                     help="local: a process pool on this machine (default); ray: Ray tasks, "
                          "a frame lost with its worker or node runs again (pip install "
                          "'monoplane[ray]')")
    run.add_argument("--workers", type=int, metavar="N",
                     help="worker processes (local) or frames in flight (ray); default: all "
                          "cores (local) or all cluster CPUs (ray)")
    run.add_argument("--ray-address", metavar="ADDR",
                     help="join a Ray cluster: 'auto', HOST:PORT (its GCS address) or "
                          "'ray://HOST:PORT' (Ray Client); default: start a local Ray instance")
    run.add_argument("--quiet", action="store_true", help="no progress bar, no final line")
    p.set_defaults(func=run_cmd)


def run_cmd(args: argparse.Namespace) -> int:
    from monoplane.batch import run_batch

    check_rerun_arg(args)
    summary = run_batch(
        args.input, args.out, config=args.config, preset=args.preset, overrides=args.overrides,
        workers=args.workers, engine=args.engine, ray_address=args.ray_address,
        overwrite=args.overwrite, report=args.report, progress=not args.quiet,
        **depth_reading(args))
    if not args.quiet:
        for note in summary.notes:
            print(f"note: {note}")
        for f in summary.failed:
            print(f"failed: {f.name}: {f.error}")
    if args.rerun:
        from monoplane.batch.recording import record_batch

        missing = record_batch(args.rerun, args.input, args.out, summary.frames,
                               **depth_reading(args))
        if not args.quiet:
            for reason in missing:
                print(f"note: not in {args.rerun}: {reason}")
    if not args.quiet:
        ok, failed, skipped = (summary.count(s) for s in ("ok", "failed", "skipped"))
        print(f"{ok} done, {failed} failed, {skipped} skipped in {summary.seconds:.1f} s "
              f"-> {args.out}/summary.json")
    return 1 if summary.failed else 0
