"""Shared fixtures: tests never autoload third-party plugins, so results do not depend on what
else is installed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from monoplane.plugin_manager import AUTOLOAD_ENV
from monoplane.testing import CORNER_PLANES, box_frame


@pytest.fixture(autouse=True)
def _no_autoload(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(AUTOLOAD_ENV, "1")


@pytest.fixture
def sample_dir(tmp_path: Path) -> Path:
    """Files of a tiny RGB-D frame: rgb.png, depth.npy, normals.npy, intrinsics.json."""
    import cv2

    frame, _ = box_frame(64, 48, CORNER_PLANES, focal=50.0)
    K, depth = frame.K, frame.depth
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 255, size=(*depth.shape, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "rgb.png"), rgb)
    np.save(tmp_path / "depth.npy", depth)
    (tmp_path / "intrinsics.json").write_text(json.dumps(
        {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}))
    return tmp_path
