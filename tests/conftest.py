"""Shared fixtures: tests never autoload third-party plugins, so results do not depend on what
else is installed."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from monoplane.geometry.cloud import PlaneCloud
from monoplane.plugin_manager import AUTOLOAD_ENV
from monoplane.types import default_intrinsics, intrinsics_matrix, pixel_rays


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


# A box room seen from inside: floor, ceiling, back wall, left and right walls (OpenCV axes,
# y down), n·X + d = 0 with n facing the camera; one flat colour per surface.
ROOM = np.array([
    [0.0, -1.0, 0.0, 1.5],
    [0.0, 1.0, 0.0, 1.5],
    [0.0, 0.0, -1.0, 5.0],
    [1.0, 0.0, 0.0, 2.0],
    [-1.0, 0.0, 0.0, 2.5],
])
ROOM_COLORS = np.array([[150, 100, 60], [230, 230, 230], [90, 140, 200], [200, 180, 120],
                        [120, 200, 120]])


def room_cues(height: int = 192, width: int = 256, noise: float = 6.0, seed: int = 0
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact cues of the box room (70° horizontal FOV).

    Returns rgb (H, W, 3) uint8 with Gaussian colour noise, depth (H, W) float32, normals
    (H, W, 3) float32, the true labels (H, W) int32 in 1..5 (row i-1 of ROOM) and K (3, 3).
    """
    K = default_intrinsics(width, height, 70.0)
    rays = pixel_rays(K, height, width)
    with np.errstate(divide="ignore"):
        z = -ROOM[:, 3] / (rays @ ROOM[:, :3].T)
    z[~(z > 0)] = np.inf
    idx = z.argmin(axis=-1)
    rng = np.random.default_rng(seed)
    rgb = np.clip(ROOM_COLORS[idx] + rng.normal(0, noise, (height, width, 3)), 0, 255)
    return (rgb.astype(np.uint8), z.min(axis=-1).astype(np.float32),
            ROOM[idx, :3].astype(np.float32), (idx + 1).astype(np.int32), K)


def cloud_from_arrays(points: np.ndarray, normals: np.ndarray) -> PlaneCloud:
    """A PlaneCloud over given (N, 3) points and normals, already normalised, no colour."""
    n = len(points)
    pixels = np.arange(n, dtype=np.int64)
    return PlaneCloud(points=points, normals=normals, colors=None, pixels=pixels,
                      center=np.zeros(3), scale=1.0, shape=(1, n), all_points=points,
                      all_pixels=pixels)
