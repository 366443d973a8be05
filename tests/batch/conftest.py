"""Small synthetic frames shared by the batch tests, and their ``monoplane run`` reference."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from batch_helpers import BROKEN, GOOD, frame_args, run_cli_labels

from monoplane.host.registry import AUTOLOAD_ENV
from monoplane.synth.batchset import write_frame_folder


@pytest.fixture(scope="session")
def frames_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four 128x96 synthetic frames; the second one's depth.npy is not a numpy file."""
    root = tmp_path_factory.mktemp("frames")
    write_frame_folder(root, n=4, width=128, height=96)
    (root / BROKEN / "depth.npy").write_bytes(b"this is not a numpy file")
    return root


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
