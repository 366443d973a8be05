"""``monoplane bench``: per-stage time, throughput and memory of a preset, against baselines."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from monoplane.cli.common import add_depth_encoding_args, add_set_arg
from monoplane.errors import InvalidInput
from monoplane.evaluation.score_files import write_scores

if TYPE_CHECKING:
    from monoplane.evaluation.bench_frames import DataSource

DESCRIPTION = """Run a preset on seeded synthetic frames at one or more image sizes and print one
table: the median time of every pipeline stage and sub-step (from the reconstruction's
timings), the median CPU time of the whole call (process time, all threads: on a busy machine
it grows far less than the wall time), the traced memory of each stage, throughput, the first
call of a fresh process
(numba kernels loaded from their cache), the peak RSS of each size (each size runs in its own
process), and every registered baseline timed on the same frames in the same process: its own
call (without converting the cloud into the library's data structure), its whole call, and
the ratio of the preset's total to the baseline's call. See monoplane/evaluation/bench.py for the
method.

--complexity (or --objects with ranges of your own) adds a scene-complexity axis: each size runs
once per range of objects per scene (default 0, 1-2, 4-6 and 8-12; 0 is the bare room, a few
large planes), on scenes of the same rooms and cameras furnished with that many objects in
view, and a second table gives time against plane count: the ground-truth and found planes,
the preset's time, each baseline's call and the ratio, per range and per frame.

--data DIR times your own frames instead (the layouts 'monoplane batch' reads, or a sequence
folder with depth/ and image/ such as a Redwood-format capture), at their own size; with
--depth-only the colour images are left out, so the preset estimates normals from the depth as
for a range sensor. 16-bit depth is divided by --depth-scale, or read in a dataset's own
encoding with --depth-encoding (tum, sun-rotated, kinect-disparity); frames of several datasets
go in a manifest whose depth_encoding column names each row's. A second table gives each
frame's planes and times. Baselines need normals: on depth-only frames they get the ones the
preset estimated, outside their timed call.

With --batch it times the 'monoplane batch' command instead, on a folder of synthetic frames of
one size (default 640x480, 20 frames), for each --workers count and --engine in alternation:
the whole command's wall time, the batch's own time (summary.json's seconds: the command less
the interpreter's start, imports and exit), frames per second and the speed-up over the first
worker count; and, from samples of /proc taken while each command runs, the peak memory (RSS
and PSS) of its whole process tree, its RSS while the first and the last 200 frames ran (at
most half of them each), and the median time per frame of those frames (--frames 1000 makes
it a soak: does memory grow, do frames slow down?). Beyond 50 frames the batch cycles over 50
distinct frames. See monoplane/batch/throughput.py."""

EPILOG = """examples:
  monoplane bench
  monoplane bench --preset monoplane-nocrf --sizes 256x192,640x480 --frames 5 --repeat 3
  monoplane bench --baseline open3d-ransac --json bench.json
  monoplane bench --from-json bench.json --markdown     # re-render a saved run for the docs
  monoplane bench --preset monoplane-nocrf --baseline cgal --complexity   # time vs. planes
  monoplane bench --objects 1-2,8-12 --sizes 256x192 --json levels.json
  monoplane bench --data livingroom/ --depth-only --depth-scale 1000 \
      --intrinsics 525,525,319.5,239.5 --frames 7 --baseline cgal  # a Redwood-style sequence
  monoplane bench --data frames.jsonl --preset range --no-baselines  # what 'batch' reads
  monoplane bench --data tum_seq/ --depth-only --depth-encoding tum --frames 7
  monoplane bench --batch --workers 1,2 --repeat 5      # batch throughput, 20 frames 640x480
  monoplane bench --batch --engine local --engine ray --json batch.json
  monoplane bench --batch --frames 1000 --sizes 128x96 --workers 2 --repeat 1   # soak"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="per-stage timings, throughput and memory vs. baselines",
                       description=DESCRIPTION, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", default="monoplane", metavar="NAME",
                   help="preset to benchmark (default: monoplane)")
    add_set_arg(p)
    p.add_argument("--sizes", metavar="WxH[,WxH...]",
                   help="comma-separated image sizes (default: 256x192,640x480; with --batch "
                        "one size, default 640x480)")
    p.add_argument("--frames", type=int,
                   help="synthetic frames per size, seeds SEED.. (default: 5; with --batch "
                        "20)")
    p.add_argument("--repeat", type=int, default=3,
                   help="timed runs per frame; medians are shown (default: 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first frame (default: 0)")
    p.add_argument("--level", default="mild", choices=("clean", "mild", "strong"),
                   help="cue corruption level of the synthetic frames (default: mild)")
    p.add_argument("--objects", metavar="LO-HI[,LO-HI...]",
                   help="scene-complexity axis: objects per scene, one range per level, e.g. "
                        "1-2,4-6,8-12 (default: the usual scenes, about 7-16 objects)")
    p.add_argument("--complexity", action="store_true",
                   help="the scene-complexity axis at its default levels: --objects "
                        "0,1-2,4-6,8-12 (0: bare rooms)")
    p.add_argument("--baseline", dest="baselines", action="append", default=None,
                   metavar="NAME", help="baseline to time on the same frames (repeatable; "
                   "default: every registered one)")
    p.add_argument("--no-baselines", action="store_true", help="time the preset only")
    p.add_argument("--json", metavar="FILE", help="also write every number as JSON")
    p.add_argument("--from-json", metavar="FILE",
                   help="print the table of a saved --json run instead of running")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    own = p.add_argument_group("your own frames (--data)")
    own.add_argument("--data", metavar="DIR",
                     help="time on these frames instead of synthetic ones: a folder of frame "
                          "folders or a .jsonl/.csv manifest (what 'monoplane batch' reads), "
                          "or a sequence folder with depth/ (and image/) sorted by name; "
                          "--frames N takes N frames spread over it (default: all)")
    add_depth_encoding_args(own, "; a manifest's depth_scale and depth_encoding columns win")
    own.add_argument("--intrinsics", metavar="FX,FY,CX,CY|JSON",
                     help="intrinsics of every frame (default: each frame's intrinsics.json, "
                          "else a 60 degree field of view)")
    own.add_argument("--depth-only", action="store_true",
                     help="do not read colour images: depth in, normals estimated by the "
                          "preset, as from a range sensor")
    batch = p.add_argument_group("batch throughput (--batch)")
    batch.add_argument("--batch", action="store_true",
                       help="time the 'monoplane batch' command instead of single frames")
    batch.add_argument("--workers", default=None, metavar="N[,N...]",
                       help="worker counts to compare, the first being the reference "
                            "(default: 1 and the number of cores)")
    batch.add_argument("--engine", dest="engines", action="append", default=None,
                       choices=("local", "ray"),
                       help="engine to time (repeatable; default: local)")
    p.set_defaults(func=run)


def _write_json(path: str, doc: dict) -> None:
    # --from-json reads the numbers back as floats, NaN included.
    print(f"numbers written to {write_scores(path, doc, nan_as_null=False)}", file=sys.stderr)


def _run_batch(args: argparse.Namespace, settings: dict) -> int:
    from monoplane.batch.throughput import bench_batch, format_batch_bench
    from monoplane.evaluation.bench import parse_sizes
    from monoplane.evaluation.bench_options import parse_worker_counts

    if args.data is not None:
        raise InvalidInput("--data applies to the frame bench; 'monoplane batch' itself "
                           "reads a folder: time it with --batch on synthetic frames")
    if settings["objects"] is not None:
        raise InvalidInput("--objects and --complexity apply to the frame bench, not --batch")
    sizes = parse_sizes(args.sizes or "640x480")
    if len(sizes) != 1:
        raise InvalidInput(f"--batch takes one size in --sizes, got {args.sizes!r}")
    result = bench_batch(args.preset, sizes[0], frames=20 if args.frames is None else args.frames,
                         workers=parse_worker_counts(args.workers),
                         engines=args.engines or ["local"], repeat=args.repeat, seed=args.seed,
                         level=args.level, overrides=args.overrides,
                         progress=not args.no_progress)
    print(format_batch_bench(result, markdown=args.markdown))
    if args.json:
        _write_json(args.json, {"kind": "batch", "settings": settings,
                                "result": result.to_dict()})
    return 0


def _data_source(args: argparse.Namespace, settings: dict) -> DataSource | None:
    """``--data`` and its options as the frames to time (None: synthetic frames); recorded in
    ``settings``."""
    from monoplane.evaluation.bench_frames import DataSource

    if args.data is None:
        if (args.depth_scale, args.depth_encoding, args.intrinsics,
                args.depth_only) != (None, "scaled", None, False):
            raise InvalidInput("--depth-scale, --depth-encoding, --intrinsics and --depth-only "
                               "apply to --data only")
        return None
    if args.sizes is not None:
        raise InvalidInput("--sizes applies to synthetic frames; --data times the frames "
                           "at their own size")
    settings.update(data=args.data, depth_scale=args.depth_scale,
                    depth_encoding=args.depth_encoding, intrinsics=args.intrinsics,
                    depth_only=args.depth_only)
    return DataSource(args.data, args.depth_scale, args.intrinsics, args.depth_only,
                      args.frames, args.depth_encoding)


def run(args: argparse.Namespace) -> int:
    from monoplane.evaluation.bench import bench, format_bench, parse_sizes
    from monoplane.evaluation.bench_options import parse_object_ranges, saved_bench_table

    if args.from_json:
        print(saved_bench_table(args.from_json, args.markdown))
        return 0
    objects = parse_object_ranges(args.objects, args.complexity)
    settings = {"preset": args.preset, "sizes": args.sizes, "frames": args.frames,
                "repeat": args.repeat, "seed": args.seed, "level": args.level,
                "overrides": args.overrides,
                "objects": None if objects is None else [list(r) for r in objects]}
    if args.batch:
        return _run_batch(args, settings)
    if args.workers is not None or args.engines is not None:
        raise InvalidInput("--workers and --engine apply to --batch only")
    data = _data_source(args, settings)
    results = bench(args.preset, parse_sizes(args.sizes or "256x192,640x480"),
                    repeat=args.repeat, seed=args.seed, level=args.level,
                    overrides=args.overrides, progress=not args.no_progress,
                    frames=5 if args.frames is None else args.frames,
                    baselines=[] if args.no_baselines else args.baselines, objects=objects,
                    data=data)
    print(format_bench(results, markdown=args.markdown))
    if args.json:
        _write_json(args.json, {"settings": settings,
                                "results": [r.to_dict() for r in results]})
    return 0
