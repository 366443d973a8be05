"""``monoplane bench``: per-stage time and memory of a preset on synthetic frames."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

DESCRIPTION = """Run a preset on a seeded synthetic frame at one or more image sizes and print
the median time of every pipeline stage and RANSAC sub-step (from the reconstruction's
timings) and the peak memory each stage allocated (tracemalloc: Python and numpy allocations,
not memory C++ libraries allocate internally). See monoplane/bench.py for the method."""

EPILOG = """examples:
  monoplane bench
  monoplane bench --preset gc-ransac --sizes 256x192,640x480 --repeat 5
  monoplane bench --preset monoplane --set ransac.max_points=50000 --sizes 640x480"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="per-stage timings and memory on synthetic frames",
                       description=DESCRIPTION, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", default="monoplane", metavar="NAME",
                   help="preset to benchmark (default: monoplane)")
    p.add_argument("--set", dest="overrides", action="append", default=[],
                   metavar="TABLE.KEY=VALUE", help="override one parameter (repeatable)")
    p.add_argument("--sizes", default="256x192,640x480", metavar="WxH[,WxH...]",
                   help="comma-separated image sizes (default: 256x192,640x480)")
    p.add_argument("--repeat", type=int, default=5,
                   help="timed runs per size; the median is shown (default: 5)")
    p.add_argument("--seed", type=int, default=0, help="synthetic scene seed (default: 0)")
    p.add_argument("--level", default="mild", choices=("clean", "mild", "strong"),
                   help="cue corruption level of the synthetic frame (default: mild)")
    p.add_argument("--json", metavar="FILE", help="also write the numbers as JSON")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monoplane.bench import bench, format_bench, parse_sizes

    sizes = parse_sizes(args.sizes)
    results = bench(args.preset, sizes, repeat=args.repeat, seed=args.seed, level=args.level,
                    overrides=args.overrides, progress=not args.no_progress)
    print(format_bench(results))
    if args.json:
        target = Path(args.json)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(json.dumps([r.to_dict() for r in results], indent=2) + "\n")
        print(f"numbers written to {target}", file=sys.stderr)
    return 0
