"""Real RGB-D frames with ground-truth poses (../shared/data/rgbd-livingroom), 3 views."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from monoplane.evaluation.twoview import relative_pose_error
from monoplane.host.pipeline import Pipeline
from monoplane.io.frames import load_frame
from monoplane.multiview import hold_intrinsics_fixed, reconstruct_multiview

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgbd-livingroom"


def trajectory(path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """World-to-camera (R, t) of each frame of a Redwood ``.log`` (camera-to-world) file."""
    rows = [line.split() for line in path.read_text().splitlines() if line.strip()]
    poses = []
    for k in range(0, len(rows), 5):
        M = np.array(rows[k + 1:k + 5], dtype=np.float64)
        R = M[:3, :3].T
        poses.append((R, -R @ M[:3, 3]))
    return poses


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason="living-room data not available")
def test_three_real_views_register_with_small_pose_error() -> None:
    frames = [load_frame(str(DATA / f"color_0000{k}.jpg"), depth=str(DATA / f"depth_0000{k}.png"),
                         depth_scale=1000.0, intrinsics="525,525,319.5,239.5")
              for k in range(3)]
    pipe = Pipeline.from_preset("monoplane", overrides=["cues.plugin=given"])
    hold_intrinsics_fixed(pipe)
    out = reconstruct_multiview(frames, pipe)
    assert out.frame_indices == [0, 1, 2]
    gt = trajectory(DATA / "trajectory.log")
    cams = out.scene.cameras
    for a in range(3):
        for b in range(a + 1, 3):
            rot, _ = relative_pose_error(cams[a], cams[b], *gt[a], *gt[b])
            assert rot < 1.0
            c_pred = [-c.R.T @ c.t for c in (cams[a], cams[b])]
            c_true = [-R.T @ t for R, t in (gt[a], gt[b])]
            # Metric depth: the baselines (2-5 cm) come out in metres.
            assert abs(np.linalg.norm(c_pred[1] - c_pred[0])
                       - np.linalg.norm(c_true[1] - c_true[0])) < 0.01
