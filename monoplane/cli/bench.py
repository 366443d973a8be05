"""``monoplane bench``: per-stage time, throughput and memory of a preset, against baselines."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from monoplane.errors import InvalidInput

DESCRIPTION = """Run a preset on seeded synthetic frames at one or more image sizes and print one
table: the median time of every pipeline stage and sub-step (from the reconstruction's
timings), the traced memory of each stage, throughput, the first call of a fresh process
(numba kernels loaded from their cache), the peak RSS of each size (each size runs in its own
process), and every registered baseline timed on the same frames in the same process: its own
call (without converting the cloud into the library's data structure), its whole call, and
the ratio of the preset's total to the baseline's call. See monoplane/bench.py for the
method."""

EPILOG = """examples:
  monoplane bench
  monoplane bench --preset monoplane-nocrf --sizes 256x192,640x480 --frames 5 --repeat 3
  monoplane bench --baseline open3d-ransac --json bench.json
  monoplane bench --from-json bench.json --markdown     # re-render a saved run for the docs"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="per-stage timings, throughput and memory vs. baselines",
                       description=DESCRIPTION, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--preset", default="monoplane", metavar="NAME",
                   help="preset to benchmark (default: monoplane)")
    p.add_argument("--set", dest="overrides", action="append", default=[],
                   metavar="TABLE.KEY=VALUE", help="override one parameter (repeatable)")
    p.add_argument("--sizes", default="256x192,640x480", metavar="WxH[,WxH...]",
                   help="comma-separated image sizes (default: 256x192,640x480)")
    p.add_argument("--frames", type=int, default=5,
                   help="synthetic frames per size, seeds SEED.. (default: 5)")
    p.add_argument("--repeat", type=int, default=3,
                   help="timed runs per frame; medians are shown (default: 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the first frame (default: 0)")
    p.add_argument("--level", default="mild", choices=("clean", "mild", "strong"),
                   help="cue corruption level of the synthetic frames (default: mild)")
    p.add_argument("--baseline", dest="baselines", action="append", default=None,
                   metavar="NAME", help="baseline to time on the same frames (repeatable; "
                   "default: every registered one)")
    p.add_argument("--no-baselines", action="store_true", help="time the preset only")
    p.add_argument("--json", metavar="FILE", help="also write every number as JSON")
    p.add_argument("--from-json", metavar="FILE",
                   help="print the table of a saved --json run instead of running")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    p.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from monoplane.bench import BenchResult, bench, format_bench, parse_sizes

    if args.from_json:
        try:
            data = json.loads(Path(args.from_json).read_text())
            results = [BenchResult.from_dict(r) for r in data["results"]]
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise InvalidInput(f"{args.from_json}: not a 'monoplane bench --json' file "
                               f"({exc})") from exc
        print(format_bench(results, markdown=args.markdown))
        return 0
    sizes = parse_sizes(args.sizes)
    results = bench(args.preset, sizes, repeat=args.repeat, seed=args.seed, level=args.level,
                    overrides=args.overrides, progress=not args.no_progress,
                    frames=args.frames, baselines=[] if args.no_baselines else args.baselines)
    print(format_bench(results, markdown=args.markdown))
    if args.json:
        target = Path(args.json)
        target.parent.mkdir(parents=True, exist_ok=True)
        settings = {"preset": args.preset, "sizes": args.sizes, "frames": args.frames,
                    "repeat": args.repeat, "seed": args.seed, "level": args.level,
                    "overrides": args.overrides}
        tmp = target.with_name(target.name + ".tmp")
        tmp.write_text(json.dumps({"settings": settings,
                                   "results": [r.to_dict() for r in results]}, indent=2) + "\n")
        tmp.replace(target)
        print(f"numbers written to {target}", file=sys.stderr)
    return 0
