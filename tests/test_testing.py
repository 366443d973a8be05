"""monoplane.testing: the exact scene builder and the stage contract checks themselves."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from monoplane.contracts import Fuser, Matcher
from monoplane.datamodel import Scene, SfmResult, intrinsics_matrix, plane_to_world
from monoplane.host.registry import get_plugin_manager, get_registry
from monoplane.testing import (
    ROOM,
    check_stage_contract,
    plane_scene,
    two_view_room,
)

REGISTRY = get_registry(get_plugin_manager(autoload=False))


def test_plane_scene_depth_lies_on_the_labelled_plane() -> None:
    K = intrinsics_matrix(60.0, 60.0, 39.5, 29.5)
    # The camera's forward axis (third row of R) is the world's -x: it is turned 90° left.
    R = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    t = np.array([0.1, -0.2, 0.3])
    scene = plane_scene(ROOM, K, 80, 60, R=R, t=t)
    points = scene.frame.points()
    p = scene.planes[scene.labels - 1]
    # Depth is stored as float32: about 1e-7 relative.
    np.testing.assert_allclose(np.einsum("hwc,hwc->hw", points, p[..., :3]) + p[..., 3], 0,
                               atol=1e-6)
    # ... so it sees only the left wall (x = -2 in the world, row 4 of ROOM).
    assert np.all(scene.labels == 4)
    np.testing.assert_allclose(plane_to_world(scene.planes, R, t), ROOM, atol=1e-12)


def test_two_views_see_the_same_room() -> None:
    room = two_view_room()
    sfm = room.sfm()
    assert len(sfm.points) > 100
    for view, kp in zip(room.views, sfm.keypoints, strict=True):
        x = sfm.points @ view.R.T + view.t
        uv = x[:, :2] / x[:, 2:] * [view.frame.K[0, 0], view.frame.K[1, 1]] + view.frame.K[:2, 2]
        np.testing.assert_allclose(uv, kp, atol=1e-9)


@pytest.mark.parametrize("info", [i for i in REGISTRY.all() if i.kind in ("matcher", "fuser")],
                         ids=lambda i: f"{i.kind}-{i.name}")
def test_builtin_multiview_stages_pass_the_running_contract(info) -> None:
    check_stage_contract(info.cls, run=True)


class _MixUpFuser(Fuser):
    """Links every plane of every view to one global plane: a broken fuser."""

    name = "mix-up"

    def fuse(self, views, sfm: SfmResult) -> Scene:
        return Scene(cameras=sfm.cameras, views=views, planes=np.array([[0.0, 0.0, 1.0, 1.0]]),
                     links=[{k: 0 for k in range(1, v.num_planes + 1)} for v in views])


class _OffImageMatcher(Matcher):
    """Reports keypoints in normalised coordinates instead of pixels: a broken matcher."""

    name = "off-image"

    def match(self, frames) -> SfmResult:
        room = two_view_room()
        sfm = room.sfm()
        return dataclasses.replace(sfm, keypoints=[kp * 100.0 for kp in sfm.keypoints])


def test_contract_catches_a_fuser_that_links_unrelated_planes() -> None:
    with pytest.raises(AssertionError, match="does not match"):
        check_stage_contract(_MixUpFuser, run=True)


def test_contract_catches_a_matcher_with_keypoints_outside_the_image() -> None:
    with pytest.raises(AssertionError, match="inside their image"):
        check_stage_contract(_OffImageMatcher, run=True)


def test_running_a_frame_stage_needs_a_frame() -> None:
    with pytest.raises(ValueError, match="needs a frame"):
        check_stage_contract(REGISTRY.get("sampler", "uniform").cls, run=True)


def test_baseline_contract_accepts_the_builtin_and_rejects_a_broken_one() -> None:
    from monoplane.datamodel import Reconstruction
    from monoplane.evaluation.baselines import open3d_ransac
    from monoplane.testing import check_baseline_contract

    check_baseline_contract(open3d_ransac)

    def floor_only(frame, *, seed=0):
        rec = open3d_ransac(frame, seed=seed)
        keep = int(np.argmin(np.abs(rec.planes[:, 1] + 1)))  # the plane facing up
        labels = np.where(rec.labels == keep + 1, 1, 0)
        return Reconstruction(frame=rec.frame, labels=labels, planes=rec.planes[keep:keep + 1])

    with pytest.raises(AssertionError, match="misses the back wall"):
        check_baseline_contract(floor_only)

    def no_options(frame, *, seed=0):
        return open3d_ransac(frame, seed=seed)

    def ignores_options(frame, *, seed=0, **options):
        return open3d_ransac(frame, seed=seed)

    with pytest.raises(AssertionError, match="must take keyword options"):
        check_baseline_contract(no_options)
    with pytest.raises(AssertionError, match="accepts an unknown option"):
        check_baseline_contract(ignores_options)
