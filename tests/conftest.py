"""Shared fixtures: tests never autoload third-party plugins, so results do not depend on what
else is installed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from monoplane.plugin_manager import AUTOLOAD_ENV
from monoplane.types import intrinsics_matrix, pixel_rays


@pytest.fixture(autouse=True)
def _no_autoload(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(AUTOLOAD_ENV, "1")


def box_corner_depth(width: int = 64, height: int = 48) -> tuple[np.ndarray, np.ndarray, list]:
    """Depth of a camera looking into a room corner: floor and two walls, exact.

    Returns K (3, 3), depth (H, W) float32 metres and the three planes (n, d) facing the camera.
    """
    K = intrinsics_matrix(50.0, 50.0, (width - 1) / 2, (height - 1) / 2)
    rays = pixel_rays(K, height, width)
    planes = [np.array([0.0, -1.0, 0.0, 1.0]),            # floor y = 1 m below the camera
              np.array([0.6, 0.0, -0.8, 3.0]),            # wall to the left-front
              np.array([-0.6, 0.0, -0.8, 3.0])]           # wall to the right-front
    depth = np.full((height, width), np.inf)
    for p in planes:
        z = -p[3] / (rays @ p[:3])
        z[z <= 0] = np.inf
        depth = np.minimum(depth, z)
    return K, depth.astype(np.float32), planes


@pytest.fixture
def sample_dir(tmp_path: Path) -> Path:
    """Files of a tiny RGB-D frame: rgb.png, depth.npy, normals.npy, intrinsics.json."""
    import cv2

    K, depth, _ = box_corner_depth()
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 255, size=(*depth.shape, 3), dtype=np.uint8)
    cv2.imwrite(str(tmp_path / "rgb.png"), rgb)
    np.save(tmp_path / "depth.npy", depth)
    (tmp_path / "intrinsics.json").write_text(json.dumps(
        {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}))
    return tmp_path
