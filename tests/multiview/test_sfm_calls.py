"""The calls ``monoplane match`` and ``monoplane multiview`` make into the library: structure
from motion in one call, the note on given intrinsics, and the one-line summaries."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from monoplane.contracts import Matcher
from monoplane.datamodel import Camera, SfmResult
from monoplane.hookspecs import hookimpl
from monoplane.host.pipeline import Pipeline
from monoplane.host.registry import get_plugin_manager
from monoplane.multiview.registration import (
    hold_given_intrinsics,
    matcher_keeps_intrinsics,
    structure_from_motion,
)
from monoplane.multiview.summaries import scene_summary, sfm_summary, unregistered_names
from monoplane.testing import box_frame


def _camera(name: str) -> Camera:
    K = np.array([[100.0, 0, 32], [0, 100.0, 24], [0, 0, 1]])
    return Camera(K=K, R=np.eye(3), t=np.zeros(3), width=64, height=48, name=name)


def _sfm(registration: list[dict]) -> SfmResult:
    names = ["a", "b", "c"]
    return SfmResult(cameras=[_camera(n) for n in names], points=np.zeros((5, 3)),
                     keypoints=[np.zeros((4, 2))] * 3, point_ids=[np.zeros(4, np.int64)] * 3,
                     matches={(1, 2): np.zeros((7, 2), np.int64),
                              (0, 1): np.zeros((12, 2), np.int64)},
                     registration=registration)


class _Fixed(Matcher):
    """A matcher that returns a known model and cannot hold intrinsics fixed (the default)."""

    name = "fixed-model"

    def match(self, frames):
        return _sfm([{"method": "sfm"}, {"method": "sfm"}, {"method": "none"}])


class _Plugin:
    @hookimpl
    def monoplane_register_matchers(self):
        return [_Fixed]


def _pipeline(matcher: str) -> Pipeline:
    pm = get_plugin_manager(autoload=False, extra_plugins=(_Plugin(),))
    return Pipeline.from_preset("monoplane", overrides=[f"matcher.plugin={matcher}"], pm=pm)


def test_structure_from_motion_brings_the_correspondences_and_times_the_matcher() -> None:
    frames = [box_frame(64, 48)[0].with_(name=n) for n in "abc"]
    timings: dict[str, float] = {}
    sfm = structure_from_motion(_pipeline("fixed-model"), frames, "match", timings)
    assert sfm.correspondences is not None and sfm.correspondences.frames == frames
    assert set(timings) == {"matcher"} and timings["matcher"] >= 0
    assert unregistered_names(sfm) == ["c"]


def test_the_note_on_given_intrinsics_comes_only_from_a_matcher_that_cannot_keep_them() -> None:
    assert hold_given_intrinsics(_pipeline("fixed-model")) == (
        "matcher 'fixed-model' cannot hold intrinsics fixed; --intrinsics is its starting guess")
    colmap = _pipeline("colmap")
    assert hold_given_intrinsics(colmap) is None
    assert matcher_keeps_intrinsics(colmap)  # held fixed as a side effect


def test_summaries_count_placed_cameras_and_name_pairs_in_order() -> None:
    sfm = _sfm([{"method": "sfm"}, {"method": "features"}, {"method": "none"}])
    assert sfm_summary(sfm, 1.234) == (
        "2 cameras, 5 points, verified matches a-b: 12, b-c: 7 in 1.23 s")
    view = SimpleNamespace(num_planes=4)
    result = SimpleNamespace(
        scene=SimpleNamespace(views=[view, SimpleNamespace(num_planes=6)],
                              planes=np.zeros((7, 4))),
        sfm=sfm, timings={"total": 10.0})
    assert scene_summary(result) == "7 global planes from 4, 6 view planes, 5 SfM points, 10.00 s"


@pytest.mark.parametrize("registration, names", [([], []), ([{"method": "none"}] * 3,
                                                            ["a", "b", "c"])])
def test_unregistered_names_follow_the_registration(registration, names) -> None:
    assert unregistered_names(_sfm(registration)) == names
