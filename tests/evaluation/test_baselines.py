"""Built-in baseline on an exact scene, and how baselines are discovered."""

from __future__ import annotations

from importlib import metadata

import numpy as np
import pytest

from monoplane.errors import ConfigError
from monoplane.evaluation import baselines
from monoplane.evaluation.baselines import (
    BUILTIN_BASELINES,
    Open3DRansacConfig,
    baseline_names,
    get_baseline,
    open3d_ransac,
)
from monoplane.evaluation.segmentation import segmentation_scores
from monoplane.plugin_manager import AUTOLOAD_ENV
from monoplane.testing import BOX_PLANES, box_frame


def test_open3d_ransac_finds_the_planes_of_an_exact_box() -> None:
    frame, gt = box_frame()
    rec = open3d_ransac(frame, seed=0)
    assert rec.num_planes == 3
    seg = segmentation_scores(rec.labels, gt)
    assert seg.sc > 0.97
    # Each true plane is found once, in the camera frame and metres.
    for plane in BOX_PLANES:
        err = np.abs(rec.params - plane).max(axis=1)
        assert err.min() < 5e-3  # inliers within ε of a neighbour plane pull the fit a little
    assert np.all(rec.rmse < 0.02)


def test_open3d_ransac_respects_plane_limits() -> None:
    frame, _ = box_frame(64, 48)
    assert open3d_ransac(frame, config=Open3DRansacConfig(max_planes=2)).num_planes == 2
    # The floor and the left wall are smaller than 40 % of the pixels; the back wall is not.
    big_only = open3d_ransac(frame, config=Open3DRansacConfig(min_support=0.4))
    assert big_only.num_planes == 1
    np.testing.assert_allclose(big_only.params[0], BOX_PLANES[0], atol=1e-4)


def test_builtin_baselines_resolve_by_name() -> None:
    assert "open3d-ransac" in baseline_names()
    assert get_baseline("open3d-ransac") is open3d_ransac
    assert set(BUILTIN_BASELINES) <= set(baseline_names())


def test_unknown_baseline_lists_the_choices() -> None:
    with pytest.raises(ConfigError, match="open3d-ransac"):
        get_baseline("no-such-baseline")


def test_entry_points_are_read_only_when_autoload_is_on(monkeypatch: pytest.MonkeyPatch) -> None:
    ep = metadata.EntryPoint(name="fake", value="monoplane.evaluation.baselines:open3d_ransac",
                             group=baselines.ENTRY_POINT_GROUP)

    def fake_entry_points(group: str) -> list[metadata.EntryPoint]:
        return [ep] if group == baselines.ENTRY_POINT_GROUP else []

    monkeypatch.setattr(baselines.metadata, "entry_points", fake_entry_points)
    assert "fake" not in baseline_names()  # the test session disables autoload
    monkeypatch.delenv(AUTOLOAD_ENV)
    assert "fake" in baseline_names()
    assert get_baseline("fake") is open3d_ransac
