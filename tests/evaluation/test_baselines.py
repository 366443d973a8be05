"""Built-in baseline on an exact scene, and how baselines are discovered (pluggy hook)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from monoplane import hookimpl, hookspecs
from monoplane.algorithm.ransac import RansacConfig
from monoplane.errors import ConfigError, PluginError
from monoplane.evaluation.baselines import (
    CALL_TIMING,
    Open3DRansacConfig,
    baseline_names,
    bind_baseline,
    get_baseline,
    open3d_ransac,
    parse_baseline_options,
    run_baseline,
)
from monoplane.evaluation.segmentation import segmentation_scores
from monoplane.host.registry import get_plugin_manager
from monoplane.testing import BOX_PLANES, box_frame


def test_open3d_ransac_finds_the_planes_of_an_exact_box() -> None:
    frame, gt = box_frame()
    rec = open3d_ransac(frame, seed=0)
    assert rec.num_planes == 3
    seg = segmentation_scores(rec.labels, gt)
    assert seg.sc > 0.97
    # Each true plane is found once, in the camera frame and metres.
    for plane in BOX_PLANES:
        err = np.abs(rec.planes - plane).max(axis=1)
        assert err.min() < 5e-3  # inliers within ε of a neighbour plane pull the fit a little
    assert np.all(rec.rmse < 0.02)


def test_open3d_ransac_respects_plane_limits() -> None:
    frame, _ = box_frame(64, 48)
    assert open3d_ransac(frame, max_planes=2).num_planes == 2
    # The floor and the left wall are smaller than 40 % of the pixels; the back wall is not.
    big_only = open3d_ransac(frame, min_support=0.4)
    assert big_only.num_planes == 1
    np.testing.assert_allclose(big_only.planes[0], BOX_PLANES[0], atol=1e-4)


def test_builtin_baseline_registers_through_the_hook_and_times_its_call() -> None:
    assert "open3d-ransac" in baseline_names()
    assert get_baseline("open3d-ransac") is open3d_ransac
    frame, _ = box_frame(64, 48)
    rec = run_baseline("open3d-ransac", frame, seed=0)
    assert rec.num_planes == 3
    assert 0 < rec.timings[CALL_TIMING] <= rec.timings["total"]


def test_baseline_config_follows_the_ransac_defaults() -> None:
    cfg, ransac = Open3DRansacConfig(), RansacConfig()
    assert (cfg.epsilon, cfg.num_iterations, cfg.max_planes, cfg.min_support,
            cfg.min_support_points) == (ransac.epsilon, ransac.max_iterations,
                                        ransac.max_planes, ransac.min_support,
                                        ransac.min_support_points)


class _Plugin:
    def __init__(self, table: object) -> None:
        self.table = table

    @hookimpl
    def monoplane_register_baselines(self) -> object:
        return self.table


def test_plugin_baselines_are_discovered_and_checked() -> None:
    pm = get_plugin_manager(autoload=False, extra_plugins=(_Plugin({"mine": open3d_ransac}),))
    assert baseline_names(pm) == ["mine", "open3d-ransac"]
    assert get_baseline("mine", pm) is open3d_ransac
    clash = get_plugin_manager(autoload=False,
                               extra_plugins=(_Plugin({"open3d-ransac": open3d_ransac}),))
    with pytest.raises(PluginError, match="open3d-ransac"):
        baseline_names(clash)
    for bad in ([open3d_ransac], {"x": 3}):
        with pytest.raises(PluginError):
            baseline_names(get_plugin_manager(autoload=False, extra_plugins=(_Plugin(bad),)))


def test_unknown_baseline_lists_the_choices() -> None:
    with pytest.raises(ConfigError, match="open3d-ransac"):
        get_baseline("no-such-baseline")


def test_every_hook_is_documented_in_the_plugin_guide() -> None:
    guide = (Path(__file__).parents[2] / "docs" / "plugins.md").read_text()
    hooks = [name for name in dir(hookspecs) if name.startswith("monoplane_")]
    assert "monoplane_register_baselines" in hooks
    missing = [h for h in hooks if not re.search(rf"`{h}\(", guide)]
    assert not missing, f"hooks missing from docs/plugins.md: {missing}"


def test_options_are_checked_with_the_valid_ones_listed() -> None:
    frame, _ = box_frame(32, 24)
    with pytest.raises(ConfigError, match=r"no option 'min_suport'; valid options: epsilon, "
                                          r"max_planes, min_support, min_support_points"):
        open3d_ransac(frame, min_suport=0.1)
    with pytest.raises(ConfigError, match=r"open3d-ransac.max_planes must be an integer.*"
                                          r"valid options of baseline 'open3d-ransac'"):
        open3d_ransac(frame, max_planes=2.5)
    with pytest.raises(ConfigError, match="min_support must lie in"):
        open3d_ransac(frame, min_support=2.0)
    # An integer is a valid float.
    assert open3d_ransac(frame, epsilon=1).num_planes >= 1


def test_baseline_set_is_parsed_bound_and_checked_before_any_frame() -> None:
    assert parse_baseline_options(
        ["open3d-ransac.min_support=0.4", "open3d-ransac.max_planes=2",
         "open3d-ransac.min_support=0.5"], ["open3d-ransac"]
    ) == {"open3d-ransac": {"min_support": 0.5, "max_planes": 2}}
    with pytest.raises(ConfigError, match="'cgal' is not a baseline of this run; baselines "
                                          "run: open3d-ransac"):
        parse_baseline_options(["cgal.min_support=0.001"], ["open3d-ransac"])
    with pytest.raises(ConfigError, match="must look like NAME.FIELD=VALUE"):
        parse_baseline_options(["min_support=0.001"], ["open3d-ransac"])
    # With --all every registered baseline runs, so each may be set.
    assert parse_baseline_options(["open3d-ransac.max_planes=3"], [], all_baselines=True) == {
        "open3d-ransac": {"max_planes": 3}}
    with pytest.raises(ConfigError, match="baselines run: open3d-ransac$"):
        parse_baseline_options(["x.y=1"], ["open3d-ransac", "open3d-ransac"])
    # Bad options fail when bound, not on the first frame.
    with pytest.raises(ConfigError, match="valid options: epsilon"):
        bind_baseline("open3d-ransac", {"bogus": 1})
    frame, _ = box_frame(64, 48)
    big_only = run_baseline("open3d-ransac", frame, options={"min_support": 0.4})
    assert big_only.num_planes == 1 and big_only.config["min_support"] == 0.4
    assert run_baseline("open3d-ransac", frame).num_planes == 3
