"""Regenerate the repository's bundled synthetic samples (``data_samples/``)::

    python -m monoplane.synth.samples data_samples

Layout of the files: see :mod:`monoplane.synth.writer`.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

from monoplane.synth.generator import generate
from monoplane.synth.writer import write_scene

#: (folder, seed, level, width, height, n_views) of the bundled samples. The pair is at
#: 320x240 so that the whole folder stays under 5 MB (see data_samples/README.md).
BUNDLED: tuple[tuple[str, int, str, int, int, int], ...] = (
    ("room_000", 0, "mild", 256, 192, 1),
    ("room_001", 1, "mild", 256, 192, 1),
    ("pair_000", 7, "mild", 320, 240, 2),
)


def write_bundled(root: Path) -> list[Path]:
    """(Re)write the bundled samples of :data:`BUNDLED` under ``root``.

    Each sample is written to a temporary folder first and renamed into place, so an
    interrupted run leaves no half-written sample. Other files in ``root`` (the README) are
    kept.

    Returns
    -------
    list of pathlib.Path
        The sample folders written.
    """
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    written = []
    for name, seed, level, width, height, n_views in BUNDLED:
        scene = generate(seed, level, width, height, n_views)
        tmp = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=root))
        try:
            os.chmod(tmp, 0o755)  # mkdtemp makes it private; samples are for everyone
            write_scene(scene, tmp)
            dest = root / name
            if dest.exists():
                shutil.rmtree(dest)
            tmp.rename(dest)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp)
        written.append(root / name)
    return written


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point: ``python -m monoplane.synth.samples OUT_DIR``."""
    parser = argparse.ArgumentParser(
        prog="python -m monoplane.synth.samples",
        description="Regenerate the bundled synthetic samples.")
    parser.add_argument("out_dir", type=Path, help="folder to write (e.g. data_samples)")
    args = parser.parse_args(argv)
    for path in write_bundled(args.out_dir):
        size = sum(f.stat().st_size for f in path.rglob("*") if f.is_file())
        print(f"{path}  ({size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
