"""Shared fixtures: tests never autoload third-party plugins, so results do not depend on what
else is installed; every ``plane-ba`` run in any test is checked not to raise its objective."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from monoplane.host.registry import AUTOLOAD_ENV
from monoplane.testing import CORNER_PLANES, box_frame


@pytest.fixture(autouse=True)
def _no_autoload(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(AUTOLOAD_ENV, "1")


@pytest.fixture(autouse=True)
def _plane_ba_lowers_or_keeps_its_objective(monkeypatch: pytest.MonkeyPatch) -> None:
    """Wherever a test runs the ``plane-ba`` adjuster (driver, CLI, eval), its robust cost must
    not end above where it started, and a rejected solve must hand back the scene as given.
    A wrapper here rather than an assert in each test: it also covers tests written later."""
    from monoplane.datamodel import Scene, SfmResult
    from monoplane.stages.adjusters import PlaneBundleAdjuster

    solve = PlaneBundleAdjuster.adjust

    def checked(self: PlaneBundleAdjuster, scene: Scene, sfm: SfmResult
                ) -> tuple[Scene, SfmResult, dict]:
        out_scene, out_sfm, report = solve(self, scene, sfm)
        if report.get("before"):
            assert report["after"]["cost"] <= report["before"]["cost"], report
        if report and not report["accepted"]:
            assert out_scene is scene and out_sfm is sfm
        return out_scene, out_sfm, report

    monkeypatch.setattr(PlaneBundleAdjuster, "adjust", checked)


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
