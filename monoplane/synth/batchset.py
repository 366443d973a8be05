"""A folder of synthetic frames for ``monoplane batch`` (tests and throughput measurements)::

    python -m monoplane.synth.batchset /tmp/frames --n 20 --size 256x192

writes ``/tmp/frames/frame_000`` ... ``frame_019``, each in the layout of
``data_samples/room_000`` (see :func:`monoplane.synth.writer.write_sample`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from monoplane.synth.generator import generate
from monoplane.synth.writer import write_sample


def write_frame_folder(root: str | Path, n: int = 20, width: int = 256, height: int = 192,
                       level: str = "mild", first_seed: int = 0) -> list[Path]:
    """Write ``n`` single-view synthetic frames as ``root/frame_<i>`` folders.

    Parameters
    ----------
    root : path
        Created if missing.
    n : int
        Number of frames; frame ``i`` is the scene of seed ``first_seed + i``.
    width, height : int
        Image size in pixels.
    level : {"clean", "mild", "strong"}
        Cue corruption level (see :mod:`monoplane.synth.corrupt`).

    Returns
    -------
    list of pathlib.Path
        The frame folders, in order.
    """
    root = Path(root)
    folders = []
    for i in range(n):
        scene = generate(seed=first_seed + i, level=level, width=width, height=height)
        folder = root / f"frame_{i:03d}"
        write_sample(scene.views[0], folder)
        folders.append(folder)
    return folders


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m monoplane.synth.batchset",
                                     description=__doc__.split("::")[0].strip())
    parser.add_argument("out", help="folder to write the frame folders into")
    parser.add_argument("--n", type=int, default=20, help="number of frames (default 20)")
    parser.add_argument("--size", default="256x192", metavar="WxH",
                        help="image size (default 256x192)")
    parser.add_argument("--level", default="mild", help="cue corruption: clean, mild, strong")
    parser.add_argument("--seed", type=int, default=0, help="seed of the first frame")
    args = parser.parse_args(argv)
    try:
        width, height = (int(v) for v in args.size.lower().split("x"))
    except ValueError:
        parser.error(f"--size must be WxH, e.g. 256x192, got {args.size!r}")
    folders = write_frame_folder(args.out, args.n, width, height, args.level, args.seed)
    print(f"{len(folders)} frames -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
