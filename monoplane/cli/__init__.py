"""The ``monoplane`` command line: a thin layer over the Python API.

Each subcommand lives in its own module with ``add_parser(subparsers)`` and
``run(args) -> int``. This module builds the parser and turns every user-facing error into one
line on stderr with a non-zero exit status; it holds no algorithm.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
import traceback

from monoplane.errors import MonoplaneError
from monoplane.host.allocator import keep_freed_memory
from monoplane.version import __version__

#: Subcommand modules, in the order ``monoplane --help`` lists them.
SUBCOMMANDS: tuple[str, ...] = (
    "run", "batch", "cloud", "multiview", "match", "eval", "bench", "plugins", "presets",
    "models",
)

EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 70

EPILOG = """examples:
  monoplane run photo.jpg --cues depth-anything-v2-small --fetch --out out/photo
  monoplane run data_samples/room_000/rgb.png --depth data_samples/room_000/depth.npy \\
      --normals data_samples/room_000/normals.npy \\
      --intrinsics data_samples/room_000/intrinsics.json --out out/room_000 --report
  monoplane batch data_samples --out out/batch --report
  monoplane run photo.jpg --set cues.depth_model=my_depth.onnx --out out/photo
  monoplane eval --all --level mild --n 50
  monoplane plugins

Set MONOPLANE_DEBUG=1 to see a full traceback on errors."""


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="monoplane",
        description="Recover the 3D planes of a scene from one image (monocular depth + normals, "
                    "proximity-guided graph-cut RANSAC, dense CRF) or from a few views (SfM).",
        epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"monoplane {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in SUBCOMMANDS:
        importlib.import_module(f"monoplane.cli.{name}").add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``monoplane`` script; returns the process exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_USER_ERROR
    keep_freed_memory()  # this process runs frame after frame: see monoplane.host.allocator
    debug = bool(os.environ.get("MONOPLANE_DEBUG"))
    try:
        return int(args.func(args) or 0)
    except MonoplaneError as exc:
        if debug:
            traceback.print_exc()
        print(f"monoplane: error: {exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except OSError as exc:
        if debug:
            traceback.print_exc()
        where = f": {exc.filename}" if exc.filename else ""
        print(f"monoplane: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("monoplane: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug: still one line, with a way to get the traceback
        if debug:
            traceback.print_exc()
        print(f"monoplane: internal error: {type(exc).__name__}: {exc} "
              "(set MONOPLANE_DEBUG=1 for a traceback, and please report it)", file=sys.stderr)
        return EXIT_INTERNAL_ERROR


if __name__ == "__main__":
    sys.exit(main())
