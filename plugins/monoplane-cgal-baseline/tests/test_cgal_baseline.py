"""The CGAL baseline finds the planes of an exact box and is discoverable by the host."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("CGAL.CGAL_Shape_detection", reason="the GPL 'cgal' package is optional")

from monoplane_cgal_baseline import CgalRansacConfig, cgal_efficient_ransac  # noqa: E402

from monoplane.evaluation.segmentation import segmentation_scores  # noqa: E402
from monoplane.testing import BOX_PLANES, box_frame, check_baseline_contract  # noqa: E402


def test_finds_the_three_planes_of_an_exact_box() -> None:
    frame, gt = box_frame()
    rec = cgal_efficient_ransac(frame)
    # CGAL's unseeded sampling may occasionally cut a sparse far strip of the floor off as a
    # second shape of the same plane; it never misses or invents a plane.
    assert 3 <= rec.num_planes <= 4
    assert segmentation_scores(rec.labels, gt).sc > 0.9
    for plane in BOX_PLANES:
        assert np.abs(rec.params - plane).max(axis=1).min() < 5e-3


def test_baseline_contract() -> None:
    check_baseline_contract(cgal_efficient_ransac)


def test_minimum_support_drops_small_planes() -> None:
    frame, _ = box_frame(64, 48)
    rec = cgal_efficient_ransac(frame, config=CgalRansacConfig(min_support=0.4))
    assert rec.num_planes == 1
    np.testing.assert_allclose(rec.params[0], BOX_PLANES[0], atol=1e-3)


def test_reports_the_efficient_ransac_call_time() -> None:
    frame, _ = box_frame(64, 48)
    rec = cgal_efficient_ransac(frame)
    assert rec.timings["baseline.call"] > 0


def test_registered_through_the_baseline_hook() -> None:
    import monoplane_cgal_baseline

    from monoplane.evaluation.baselines import baseline_names, get_baseline
    from monoplane.plugin_manager import get_plugin_manager

    pm = get_plugin_manager(autoload=False, extra_plugins=(monoplane_cgal_baseline,))
    assert "cgal" in baseline_names(pm)
    assert get_baseline("cgal", pm) is cgal_efficient_ransac


def test_shares_the_pipeline_ransac_defaults() -> None:
    from monoplane.ransac import RansacConfig

    cfg, ransac = CgalRansacConfig(), RansacConfig()
    assert (cfg.epsilon, cfg.normal_deg, cfg.min_support, cfg.min_support_points) == (
        ransac.epsilon, ransac.epsilon_n_deg, ransac.min_support, ransac.min_support_points)
