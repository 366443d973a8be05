"""Constants and helpers of the batch tests (a uniquely named module: several test folders
have a conftest.py, so importing from "conftest" would be ambiguous)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from monoplane.cli import main

#: Frame folders in the shared input; frame_001 gets a corrupt depth file.
GOOD = ("frame_000", "frame_002", "frame_003")
BROKEN = "frame_001"


def run_cli_labels(args: list[str], out: Path) -> np.ndarray:
    """Labels that ``monoplane run`` writes for ``args``."""
    assert main(["run", *args, "--out", str(out), "--quiet"]) == 0
    return cv2.imread(str(out / "labels.png"), cv2.IMREAD_UNCHANGED)


def frame_args(folder: Path) -> list[str]:
    """``monoplane run`` arguments for a frame folder."""
    return [str(folder / "rgb.png"), "--depth", str(folder / "depth.npy"), "--normals",
            str(folder / "normals.npy"), "--intrinsics", str(folder / "intrinsics.json")]


def read_labels(folder: Path) -> np.ndarray:
    return cv2.imread(str(folder / "labels.png"), cv2.IMREAD_UNCHANGED)
