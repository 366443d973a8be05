"""Small synthetic frames shared by the batch tests, and their ``monoplane run`` reference."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from monoplane.cli import main
from monoplane.plugin_manager import AUTOLOAD_ENV
from monoplane.synth.batchset import write_frame_folder

#: Frame folders in the shared input; frame_001 gets a corrupt depth file.
GOOD = ("frame_000", "frame_002", "frame_003")
BROKEN = "frame_001"


@pytest.fixture(scope="session")
def frames_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four 128x96 synthetic frames; the second one's depth.npy is not a numpy file."""
    root = tmp_path_factory.mktemp("frames")
    write_frame_folder(root, n=4, width=128, height=96)
    (root / BROKEN / "depth.npy").write_bytes(b"this is not a numpy file")
    return root


def run_cli_labels(args: list[str], out: Path) -> np.ndarray:
    """Labels that ``monoplane run`` writes for ``args``."""
    assert main(["run", *args, "--out", str(out), "--quiet"]) == 0
    return cv2.imread(str(out / "labels.png"), cv2.IMREAD_UNCHANGED)


def frame_args(folder: Path) -> list[str]:
    return [str(folder / "rgb.png"), "--depth", str(folder / "depth.npy"), "--normals",
            str(folder / "normals.npy"), "--intrinsics", str(folder / "intrinsics.json")]


@pytest.fixture(scope="session")
def reference_labels(frames_dir: Path, tmp_path_factory: pytest.TempPathFactory
                     ) -> dict[str, np.ndarray]:
    """``monoplane run`` labels of every good frame."""
    mp = pytest.MonkeyPatch()
    mp.setenv(AUTOLOAD_ENV, "1")  # the function-scoped autouse fixture does not reach here
    out = tmp_path_factory.mktemp("reference")
    try:
        return {name: run_cli_labels(frame_args(frames_dir / name), out / name)
                for name in GOOD}
    finally:
        mp.undo()


def read_labels(folder: Path) -> np.ndarray:
    return cv2.imread(str(folder / "labels.png"), cv2.IMREAD_UNCHANGED)
