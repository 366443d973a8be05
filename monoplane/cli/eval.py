"""``monoplane eval``: score presets and baselines on seeded synthetic scenes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from monoplane.cli.common import add_set_arg
from monoplane.errors import InvalidInput
from monoplane.evaluation.score_files import write_scores
from monoplane.io.depth_encodings import DEPTH_ENCODINGS, check_depth_encoding

DESCRIPTION = """Score pipeline presets and external baselines on N seeded synthetic indoor
scenes with exact plane ground truth (monoplane.synth), using the paper's single-view protocol:
VOI (nats), RI and SC over ground-truth planar pixels, and plane recall at 0.05/0.1/0.6 m after
median-scale alignment. Every method sees the same corrupted depth and normals. With
--multiview, score two-view pairs instead (relative pose error and plane AP); with --multiview
--data DIR, score sparse-view registration on a posed RGB-D sequence (pairs or a set of views
chosen from its ground-truth poses)."""

EPILOG = """examples:
  monoplane eval --all --level mild --n 50
  monoplane eval --preset monoplane --preset gc-ransac --baseline open3d-ransac --n 20
  monoplane eval --preset monoplane --set labeler.lambda=0.9 --level strong --json out.json
  monoplane eval --all --n 50 --report eval_report/
  monoplane eval --multiview --n 10
  monoplane eval --data abw-dev/ --preset range --baseline cgal \
      --baseline-set cgal.min_support=0.001 --baseline-set cgal.normal_deg=35
  monoplane eval --data abw-dev/ --as-cloud --preset cloud
  monoplane eval --multiview --views 5 --path walk --n 10
  monoplane eval --multiview --data livingroom/ --intrinsics 525,525,319.5,239.5 \
      --n 10 --split tune --mode all
  monoplane eval --multiview --data livingroom/ --views 5 --mode rgbd --json views5.json
  monoplane eval --multiview --data livingroom/ --pairs 0-32,53-102 --mode mono \
      --level strong
  monoplane eval --multiview --data livingroom/ --n 3 --mode network \
      --set cues.plugin=onnx --set cues.model=depth-anything-v2-small

Scene i uses seed SEED+i, so equal arguments give equal tables (timings aside). Baselines come
registered through the 'monoplane_register_baselines' plugin hook: open3d-ransac is built in,
installed plugins add more (--all scores every one); --baseline-set NAME.FIELD=VALUE sets the
fields of a baseline's settings, so peers are compared tuned. 's/frame' is the whole call,
'core s' a baseline's own call without data conversion when it reports one. See
docs/evaluation.md."""


# The names of monoplane.evaluation.posed_sequences.MODES and MODE_GROUPS, spelled out so that
# building the parser does not import the evaluation (tests check that they agree).
POSED_MODES = ("rgbd", "mono", "mono-depth", "network")
POSED_MODE_GROUPS = ("all", "both")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("eval", help="score presets and baselines on synthetic scenes",
                       description=DESCRIPTION, epilog=EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    what = p.add_argument_group("methods")
    what.add_argument("--preset", dest="presets", action="append", default=[], metavar="NAME",
                      help="pipeline preset to score (repeatable); see 'monoplane presets'")
    what.add_argument("--baseline", dest="baselines", action="append", default=[],
                      metavar="NAME",
                      help="external baseline to score (repeatable), e.g. open3d-ransac")
    what.add_argument("--baseline-set", dest="baseline_sets", action="append", default=[],
                      metavar="NAME.FIELD=VALUE",
                      help="set one option of a baseline (repeatable), e.g. "
                           "cgal.min_support=0.001; unknown fields list the valid ones")
    what.add_argument("--all", dest="all_methods", action="store_true",
                      help="the paper's six ablation presets plus every available baseline")
    add_set_arg(what, "override one parameter of every preset (repeatable)")
    data = p.add_argument_group("data")
    data.add_argument("--level", default="mild", choices=("clean", "mild", "strong"),
                      help="cue corruption: exact cues, or monocular-like errors (default: "
                           "mild); with --multiview --data, the level of the mono and "
                           "mono-depth modes (mild or strong)")
    data.add_argument("--n", type=int,
                      help="number of scenes or pairs (default: 50; 10 with --multiview --data)")
    data.add_argument("--seed", type=int, default=0,
                      help="seed of the first scene, or of the monocular-like cues of "
                           "--multiview --data (default: 0)")
    data.add_argument("--size", default="256x192", metavar="WxH",
                      help="image size (default: 256x192, the paper's)")
    data.add_argument("--multiview", action="store_true",
                      help="two-view evaluation: relative pose error and plane AP; with "
                           "--views N > 2, N-view synthetic sequences")
    data.add_argument("--data", metavar="DIR",
                      help="score real frames instead: a folder of frame folders with "
                           "gt_labels.png and depth (VOI, RI, SC and SegComp counts); with "
                           "--multiview, a posed RGB-D sequence (image/, depth/, "
                           "trajectory.log)")
    data.add_argument("--as-cloud", action="store_true",
                      help="with --data: run presets through detect_planes on the frames' "
                           "shuffled 3D points")
    data.add_argument("--tolerance", type=float, default=0.8,
                      help="with --data: SegComp overlap tolerance T (default: 0.8)")
    data.add_argument("--views", type=int, default=2, metavar="N",
                      help="with --multiview: views per sequence (default: 2, the pair "
                           "protocol); with --data, N >= 3 scores one set of N frames spread "
                           "over the sequence")
    data.add_argument("--path", default="walk", choices=("walk", "star"),
                      help="with --multiview --views N > 2: camera path (default: walk)")
    posed = p.add_argument_group("posed RGB-D sequences (--multiview --data DIR)")
    posed.add_argument("--intrinsics", metavar="fx,fy,cx,cy|K.json",
                       help="pinhole intrinsics of the sequence (default: DIR/intrinsics.json)")
    posed.add_argument("--depth-scale", type=float, metavar="S",
                       help="divide the depth files' values by S (default: 1000, millimetres; "
                            "only with --depth-encoding scaled)")
    posed.add_argument("--depth-encoding", default="scaled", choices=DEPTH_ENCODINGS,
                       help="how the depth files hold depth: scaled (by --depth-scale) or a "
                            "dataset's own 16-bit encoding (default: scaled)")
    posed.add_argument("--mode", default="all",
                       choices=(*POSED_MODES, *POSED_MODE_GROUPS),
                       help="what each view gets: its sensor depth (rgbd); depth corrupted as "
                            "a network errs at --level, with the network's normals (mono) or "
                            "alone (mono-depth); nothing, the cue provider predicting from the "
                            "image (network, needs --set cues.plugin=...); all = rgbd, mono "
                            "and mono-depth (default: all; 'both' is a deprecated name of "
                            "rgbd + mono)")
    posed.add_argument("--split", default="all", choices=("tune", "report", "all"),
                       help="frames the view sets may use: tune = the first half of the "
                            "trajectory, report = the second half (default: all)")
    posed.add_argument("--pairs", metavar="I-J,K-L",
                       help="evaluate these frame-id pairs instead of choosing pairs")
    posed.add_argument("--min-angle", type=float, default=20.0, metavar="DEG",
                       help="smallest true rotation of a chosen pair (default: 20)")
    posed.add_argument("--max-angle", type=float, default=40.0, metavar="DEG",
                       help="largest true rotation of a chosen pair (default: 40)")
    posed.add_argument("--min-overlap", type=float, default=0.4, metavar="F",
                       help="smallest overlap of a chosen pair, and of the links of a --views "
                            "set (default: 0.4)")
    posed.add_argument("--rotation-threshold", type=float, default=5.0, metavar="DEG",
                       help="a correct pair's rotation error is below this (default: 5)")
    posed.add_argument("--translation-threshold", type=float, default=10.0, metavar="DEG",
                       help="a correct pair's translation-direction error is below this "
                            "(default: 10)")
    out = p.add_argument_group("outputs")
    out.add_argument("--json", metavar="FILE", help="also write every score as JSON")
    out.add_argument("--report", metavar="DIR", help="also write an HTML report into DIR")
    out.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    p.set_defaults(func=run)


def _write_json(path: str, data: dict[str, Any]) -> None:
    print(f"scores written to {write_scores(path, data)}", file=sys.stderr)


def _run_multiview(args: argparse.Namespace, size: tuple[int, int]) -> int:
    try:
        from monoplane.evaluation import twoview
    except ImportError as exc:
        raise InvalidInput(f"two-view evaluation is not available in this installation: {exc}"
                           ) from exc
    if args.baselines or args.baseline_sets or args.all_methods or len(args.presets) > 1:
        raise InvalidInput("--multiview scores one preset; drop --baseline/--baseline-set/--all "
                           "and give at most one --preset")
    kwargs: dict[str, Any] = {"width": size[0], "height": size[1],
                              "overrides": args.overrides or None}
    if args.presets:
        kwargs["preset"] = args.presets[0]
    if args.views < 2:
        raise InvalidInput(f"--views must be at least 2, got {args.views}")
    if args.views > 2:
        from monoplane.evaluation import sequences

        res = sequences.evaluate_sequences(args.n, args.views, args.path, args.level,
                                           args.seed, not args.no_progress, **kwargs)
        print(sequences.format_sequences(res))
        if args.json:
            _write_json(args.json, {"settings": {"level": args.level, "n": args.n,
                                                 "seed": args.seed, "width": size[0],
                                                 "height": size[1], "views": args.views,
                                                 "path": args.path, "multiview": True},
                                    **res})
        return 0
    results = twoview.evaluate_pairs(args.n, args.level, args.seed, not args.no_progress,
                                     **kwargs)
    print(twoview.format_twoview(results))
    if args.json:
        _write_json(args.json, {"settings": {"level": args.level, "n": args.n,
                                             "seed": args.seed, "width": size[0],
                                             "height": size[1], "multiview": True},
                                **results})
    return 0


def _run_posed_sequence(args: argparse.Namespace) -> int:
    from monoplane.evaluation.posed_sequences import (
        evaluate_posed_sequence,
        format_posed_sequence,
    )

    if (args.baselines or args.baseline_sets or args.all_methods or len(args.presets) > 1
            or args.report or args.as_cloud):
        raise InvalidInput("--multiview --data scores one preset; drop --baseline/--baseline-set/"
                           "--all/--report/--as-cloud and give at most one --preset")
    if args.views < 2:
        raise InvalidInput(f"--views must be at least 2, got {args.views}")
    if args.pairs and args.views > 2:
        raise InvalidInput("give --pairs or --views, not both")
    if args.mode == "both":
        print("monoplane: note: --mode both is deprecated (it runs rgbd and mono); use --mode "
              "all for rgbd, mono and mono-depth", file=sys.stderr)
    check_depth_encoding(args.depth_encoding, args.depth_scale, "--depth-encoding")
    results = evaluate_posed_sequence(
        args.data, args.intrinsics, mode=args.mode, split=args.split,
        n=10 if args.n is None else args.n, views=args.views if args.views > 2 else None,
        pairs=args.pairs, preset=args.presets[0] if args.presets else "monoplane",
        overrides=args.overrides,
        depth_scale=1000.0 if args.depth_scale is None else args.depth_scale,
        min_angle=args.min_angle, max_angle=args.max_angle, min_overlap=args.min_overlap,
        rotation_threshold=args.rotation_threshold,
        translation_threshold=args.translation_threshold, seed=args.seed, level=args.level,
        progress=not args.no_progress, depth_encoding=args.depth_encoding)
    print(format_posed_sequence(results))
    if args.json:
        _write_json(args.json, results)
    return 0


def _write_report(results: Any, methods: list[Any], out_dir: str, progress: bool) -> None:
    try:
        from monoplane.report import write_eval_report
    except ImportError:
        print("monoplane: note: this installation has no evaluation report writer; "
              "skipping --report", file=sys.stderr)
        return
    # The methods are passed so the report can draw their predictions on the best and worst
    # scenes (it re-runs them there; scenes are pure functions of their seed).
    path = write_eval_report(results, Path(out_dir), methods=methods, progress=progress)
    print(f"report written to {path}", file=sys.stderr)


def _run_dataset(args: argparse.Namespace) -> int:
    from monoplane.evaluation.baselines import parse_baseline_options
    from monoplane.evaluation.dataset import evaluate_dataset, format_dataset_table

    if args.multiview or args.all_methods or args.report:
        raise InvalidInput("--data scores --preset/--baseline methods; drop --multiview, --all "
                           "and --report")
    results = evaluate_dataset(args.data, args.presets, args.baselines, args.overrides or None,
                               as_cloud=args.as_cloud, tolerance=args.tolerance,
                               seed=args.seed, progress=not args.no_progress,
                               baseline_options=parse_baseline_options(args.baseline_sets,
                                                                        args.baselines))
    print(format_dataset_table(results))
    if args.json:
        _write_json(args.json, results.to_dict())
    return 0


def run(args: argparse.Namespace) -> int:
    from monoplane.evaluation.baselines import parse_baseline_options
    from monoplane.evaluation.runner import evaluate, format_table, parse_size, resolve_methods

    if args.data and args.multiview:
        return _run_posed_sequence(args)
    if args.pairs or args.intrinsics:
        raise InvalidInput("--pairs and --intrinsics are for posed sequences: add --multiview "
                           "--data DIR")
    if args.data:
        return _run_dataset(args)
    if args.as_cloud:
        raise InvalidInput("--as-cloud needs --data DIR")

    size = parse_size(args.size)
    if args.n is None:
        args.n = 50
    if args.n < 1:
        raise InvalidInput(f"--n must be at least 1, got {args.n}")
    if args.multiview:
        return _run_multiview(args, size)
    methods = resolve_methods(args.presets, args.baselines, args.all_methods, args.overrides,
                              parse_baseline_options(args.baseline_sets, args.baselines,
                                                     args.all_methods))
    results = evaluate(methods, n=args.n, level=args.level, seed=args.seed, size=size,
                       progress=not args.no_progress)
    print(format_table(results))
    if args.json:
        _write_json(args.json, results.to_dict())
    if args.report:
        _write_report(results, methods, args.report, not args.no_progress)
    return 0
