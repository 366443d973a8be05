"""The ``plane-ba`` adjuster keeps a solve only if it lowers its objective (exact two-view room)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import scipy.optimize

from monoplane.datamodel import Scene, SfmResult
from monoplane.stages.adjusters import PlaneBundleAdjuster
from monoplane.stages.fusers import AverageFuser
from monoplane.testing import two_view_room


def _fused_room(shift: float) -> tuple[Scene, SfmResult]:
    """The exact room fused from two views, view 1's camera moved by ``shift`` metres along x
    (in the scene and the SfM result alike, as SfM would hand it over)."""
    room = two_view_room()
    sfm = room.sfm()
    cams = list(sfm.cameras)
    cams[1] = replace(cams[1], t=cams[1].t + np.array([shift, 0.0, 0.0]))
    sfm = replace(sfm, cameras=cams)
    return AverageFuser().fuse(room.reconstructions(), sfm), sfm


def test_a_solve_that_raises_the_cost_returns_the_scene_as_fused(monkeypatch) -> None:
    scene, sfm = _fused_room(0.01)

    def away(fun, x0, **kwargs):
        return scipy.optimize.OptimizeResult(x=x0 + 0.05, success=True, message="stepped off")

    monkeypatch.setattr(scipy.optimize, "least_squares", away)
    out_scene, out_sfm, report = PlaneBundleAdjuster().adjust(scene, sfm)
    assert out_scene is scene and out_sfm is sfm  # cameras, scales, planes, points untouched
    assert report["accepted"] is False
    assert "raised the robust cost" in report["reason"]
    assert report["rejected"]["cost"] > report["before"]["cost"]
    assert report["after"] == report["before"]
    assert report["depth_scale_factors"] == [1.0, 1.0]
    json.dumps(report)  # scene.json holds it


def test_a_solve_that_lowers_the_cost_is_kept() -> None:
    scene, sfm = _fused_room(0.01)
    out_scene, out_sfm, report = PlaneBundleAdjuster().adjust(scene, sfm)
    assert report["accepted"] is True and "reason" not in report
    assert report["after"]["cost"] < report["before"]["cost"]
    assert not np.allclose(out_scene.cameras[1].t, scene.cameras[1].t)
    np.testing.assert_array_equal(out_sfm.cameras[1].t, out_scene.cameras[1].t)
    json.dumps(report)


def test_without_sfm_points_on_planes_nothing_is_refined() -> None:
    # No SfM point: the plane terms alone would follow the monocular depth (docs/multiview.md).
    scene, sfm = _fused_room(0.01)
    sfm = replace(sfm, points=np.zeros((0, 3)),
                  point_ids=[np.full_like(ids, -1) for ids in sfm.point_ids])
    out_scene, out_sfm, report = PlaneBundleAdjuster().adjust(scene, sfm)
    assert out_scene is scene and out_sfm is sfm
    assert report["accepted"] is False
    assert "0 SfM points inside planes" in report["reason"]
