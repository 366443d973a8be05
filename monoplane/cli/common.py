"""Argument groups shared by several subcommands."""

from __future__ import annotations

import argparse
from typing import Any

from monoplane.export.files import check_output_dir
from monoplane.host.pipeline import Pipeline
from monoplane.io.depth_encodings import DEPTH_ENCODINGS


def add_pipeline_args(parser: argparse.ArgumentParser) -> None:
    """``--preset``, ``--config`` and repeatable ``--set table.key=value``."""
    group = parser.add_argument_group("pipeline configuration")
    group.add_argument("--preset", metavar="NAME",
                       help="start from a shipped preset (default: monoplane); "
                            "see 'monoplane presets'")
    group.add_argument("--config", metavar="FILE.toml",
                       help="TOML config: one table per stage with plugin = \"name\" and its "
                            "parameters; may set preset = \"name\"")
    add_set_arg(group, "override one parameter, e.g. --set labeler.lambda=0.9 or "
                       "--set cues.profile=zerodepth (repeatable)")


def add_set_arg(parser: argparse.ArgumentParser | argparse._ArgumentGroup,
                text: str = "override one parameter (repeatable)") -> None:
    """Repeatable ``--set TABLE.KEY=VALUE`` into ``args.overrides``, the list every command
    hands to the config loader as its ``overrides``; ``text`` is the help."""
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="TABLE.KEY=VALUE", help=text)


def pipeline_from_args(args: argparse.Namespace,
                       overrides: dict[str, Any] | list[str] | None = None) -> Pipeline:
    """Build the pipeline the user asked for (validates the whole config); ``overrides``, when
    given, stand for ``args.overrides`` (e.g. with a catalogue model's keys under them)."""
    return Pipeline.from_config(args.config, preset=args.preset,
                                overrides=args.overrides if overrides is None else overrides)


def add_input_args(parser: argparse.ArgumentParser, per_image: bool = False) -> None:
    """Cue files and intrinsics of one view, or with ``per_image`` one cue file per image."""
    group = parser.add_argument_group("inputs")
    nargs, each = ("+", "one per image: ") if per_image else (None, "")
    group.add_argument("--depth", nargs=nargs, metavar="FILE",
                       help=f"{each}depth map: .npy float (any unit) or 16-bit PNG with "
                            "--depth-scale or --depth-encoding")
    group.add_argument("--normals", nargs=nargs, metavar="FILE",
                       help=f"{each}normals: .npy (H, W, 3) in the camera frame (x right, y down, "
                            "z forward), or 8-bit PNG storing (n+1)/2*255")
    group.add_argument("--intrinsics", metavar="fx,fy,cx,cy|FILE.json",
                       help="pinhole intrinsics in pixels"
                            + (" shared by all images, held fixed in SfM where the matcher can"
                               if per_image else "")
                            + "; default: 60 degree horizontal FOV")
    add_depth_value_args(group)


def add_depth_encoding_args(group: argparse._ArgumentGroup, note: str = "") -> None:
    """``--depth-scale`` and ``--depth-encoding``: how 16-bit depth holds its values (every
    command that reads depth files takes both; :func:`monoplane.io.frames.read_depth`).

    ``note`` is appended to both helps (e.g. what overrides them).
    """
    group.add_argument("--depth-scale", type=float, metavar="S",
                       help="divide 16-bit depth by S (1000 for millimetres, 5000 for TUM)"
                            + note)
    group.add_argument("--depth-encoding", choices=DEPTH_ENCODINGS, default="scaled",
                       metavar="NAME",
                       help="how 16-bit depth holds its values: scaled (divided by "
                            "--depth-scale; default), tum (metres x 5000), sun-rotated (SUN "
                            "RGB-D's bit-rotated millimetres), kinect-disparity (raw Kinect v1 "
                            "disparity, e.g. NYU Depth v2's raw .pgm)" + note)


def add_depth_value_args(group: argparse._ArgumentGroup, scale_note: str = "") -> None:
    """``--depth-scale``, ``--depth-encoding``, ``--relative-depth`` and ``--nan-as-invalid``:
    how depth values read.

    ``scale_note`` is appended to the ``--depth-scale`` and ``--depth-encoding`` helps (e.g.
    what overrides them).
    """
    add_depth_encoding_args(group, scale_note)
    group.add_argument("--relative-depth", action="store_true",
                       help="the given depth is correct only up to scale (e.g. a network output)")
    group.add_argument("--nan-as-invalid", action="store_true",
                       help="treat NaN/inf depth as invalid pixels instead of an error")


def depth_reading(args: argparse.Namespace) -> dict[str, Any]:
    """Keyword arguments ``depth_scale``, ``depth_encoding``, ``depth_kind`` and
    ``nan_as_invalid`` of the loaders, from the options of :func:`add_depth_value_args`."""
    return dict(depth_scale=args.depth_scale, depth_encoding=args.depth_encoding,
                nan_as_invalid=args.nan_as_invalid,
                depth_kind="relative" if args.relative_depth else "metric")


def add_output_args(parser: argparse.ArgumentParser) -> None:
    """``--out`` (required), ``--overwrite`` and ``--report``."""
    group = parser.add_argument_group("outputs")
    group.add_argument("--out", required=True, metavar="DIR",
                       help="output folder (written atomically: nothing is left on failure)")
    group.add_argument("--overwrite", action="store_true",
                       help="replace DIR if it exists")
    group.add_argument("--report", action="store_true",
                       help="also write report.html with 2D figures, an interactive 3D view "
                            "and rendered 3D views")
    add_rerun_arg(group)


def add_rerun_arg(group: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--rerun FILE.rrd``: also write a Rerun recording (optional extra ``rerun``)."""
    group.add_argument("--rerun", metavar="FILE.rrd",
                       help="also write a Rerun recording of the result (image, depth, label "
                            "map, points, plane meshes, camera; open it with 'rerun "
                            "FILE.rrd'); needs pip install 'monoplane[rerun]'")


def check_output_args(args: argparse.Namespace) -> None:
    """Fail before any work when ``--out`` exists and is not empty (without ``--overwrite``) or
    ``--rerun`` cannot be written."""
    check_output_dir(args.out, args.overwrite)
    check_rerun_arg(args)


def check_rerun_arg(args: argparse.Namespace) -> None:
    """Fail before any work when ``--rerun`` cannot be written (bad name, no Rerun SDK)."""
    if args.rerun:
        from monoplane.export.rerun_log import check_recording_path

        check_recording_path(args.rerun)


def write_rerun_arg(args: argparse.Namespace, result: Any) -> None:
    """Write the ``--rerun`` recording of ``result``, if asked for (see
    :func:`monoplane.log_rerun`)."""
    if args.rerun:
        from monoplane.export.rerun_log import log_rerun

        log_rerun(result, args.rerun)
