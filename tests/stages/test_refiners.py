"""Refiner stages ``none`` and ``dense-crf`` on frames with known planes."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from monoplane.contracts import RansacParams
from monoplane.datamodel import Frame, Reconstruction
from monoplane.errors import ConfigError
from monoplane.stages.refiners import DenseCrfRefiner, NoRefiner, monoplane_register_refiners
from monoplane.testing import ROOM, check_stage_contract, check_work_ahead, room_cues

#: The pipeline's shared thresholds at their defaults.
PARAMS = RansacParams()


def room(height: int = 96, width: int = 128, grey: bool = False, seed: int = 0):
    """Frame of the box room with exact depth and normals, and its true labels 1..5."""
    rgb, depth, normals, labels, K = room_cues(height, width, seed=seed)
    if grey:
        rgb = np.repeat(rgb.mean(axis=2, keepdims=True).astype(np.uint8), 3, axis=2)
    return Frame(rgb=rgb, K=K, depth=depth, normals=normals), labels


def noisy_reconstruction(frame: Frame, gt: np.ndarray, seed: int = 1) -> Reconstruction:
    """RANSAC-like result: 15 % speckle, plus a 4x4 stray patch of plane 1 inside the back
    wall (label 3), with slightly wrong plane parameters."""
    rng = np.random.default_rng(seed)
    labels = np.where(rng.random(gt.shape) < 0.15, rng.integers(0, 6, gt.shape), gt)
    labels[40:44, 60:64] = 1
    params = ROOM.copy()
    params[:, 3] *= 1.05
    return Reconstruction(frame=frame, labels=labels.astype(np.int32), planes=params)


def test_registration_and_contract(synthetic_view):
    assert monoplane_register_refiners() == [NoRefiner, DenseCrfRefiner]
    for cls in (NoRefiner, DenseCrfRefiner):
        check_stage_contract(cls, synthetic_view.frame)


def test_dense_crf_work_prepared_in_the_background_changes_nothing(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    frame, gt = room()
    rec = noisy_reconstruction(frame, gt)
    check_work_ahead(DenseCrfRefiner, frame, room(seed=1)[0], rec, PARAMS, monkeypatch)


def test_points_reuse_the_rays_of_the_same_camera_only():
    refiner = DenseCrfRefiner()
    frame = room()[0]
    np.testing.assert_array_equal(refiner._points(frame), frame.points())
    rays = refiner._rays[2]
    other = room(seed=1)[0]  # same camera, other depth: the rays are reused
    np.testing.assert_array_equal(refiner._points(other), other.points())
    assert refiner._rays[2] is rays
    wider = frame.with_(K=frame.K * np.array([[1.1], [1.1], [1.0]]))
    np.testing.assert_array_equal(refiner._points(wider), wider.points())
    assert refiner._rays[2] is not rays
    smaller = Frame(rgb=None, K=frame.K, depth=frame.depth[:80, :100].copy())
    np.testing.assert_array_equal(refiner._points(smaller), smaller.points())
    assert refiner._rays[2].shape == (80, 100, 3)


def test_none_refiner_is_the_identity():
    frame, gt = room()
    rec = noisy_reconstruction(frame, gt)
    assert NoRefiner().refine(rec, PARAMS) is rec


def test_dense_crf_refiner_recovers_the_room():
    frame, gt = room()
    rec = noisy_reconstruction(frame, gt)
    out = DenseCrfRefiner().refine(rec, PARAMS)
    assert out.num_planes == 5
    # Labels come back in the RANSAC order, so they can be compared directly.
    assert (rec.labels == gt).mean() < 0.9
    assert (out.labels == gt).mean() > 0.99
    # Every plane is one connected region at least the (scaled) minimum area.
    min_area = 75  # 300 px at 256x192 -> 75 px at 128x96
    for k in range(1, out.num_planes + 1):
        _, count = ndimage.label(out.labels == k, structure=np.ones((3, 3)))
        assert count == 1
    assert out.area_px.min() >= min_area
    # Planes refit on the final pixels: exact up to the float32 depth and the few wrong pixels.
    np.testing.assert_allclose(out.planes[:, :3], ROOM[:, :3], atol=2e-3)
    np.testing.assert_allclose(out.planes[:, 3], ROOM[:, 3], rtol=2e-3)
    # Planes are fit on the RANSAC's planar pixels only (fit_inliers_only): the support counts
    # those; in the paper's mode it counts every pixel of the region.
    inliers = np.bincount(out.labels[rec.labels > 0], minlength=6)[1:]
    np.testing.assert_array_equal(out.support, inliers)
    paper = DenseCrfRefiner(DenseCrfRefiner.Config(fit_inliers_only=False)).refine(rec, PARAMS)
    np.testing.assert_array_equal(paper.support, paper.area_px)


@pytest.mark.parametrize("grey", [True, False])
def test_dense_crf_refiner_on_grey_and_depth_only_frames(grey):
    frame, gt = room(grey=True)
    if not grey:
        frame = frame.with_(rgb=None)
    out = DenseCrfRefiner().refine(noisy_reconstruction(frame, gt), PARAMS)
    assert out.num_planes == 5
    assert (out.labels == gt).mean() > 0.98


def test_small_regions_and_splits_without_crf():
    frame, gt = room()
    labels = gt.copy()
    labels[:, 60:64] = 0               # cuts the floor, ceiling and back wall in two
    labels[10:14, 10:14] = 0
    labels[10:13, 10:13] = 3           # 9-px fragment of the back wall inside the left wall
    rec = Reconstruction(frame=frame, labels=labels, planes=ROOM)
    paper = {"iterations": 0, "merge": False, "absorb": False}
    out = DenseCrfRefiner(DenseCrfRefiner.Config(**paper)).refine(rec, PARAMS)
    assert out.num_planes == 8         # 3 planes split in two, plus the two side walls
    assert not np.any(out.labels[10:13, 10:13])
    areas = np.bincount(out.labels.ravel())[1:]
    assert areas.min() >= 75
    keep_all = DenseCrfRefiner(DenseCrfRefiner.Config(**paper, min_area=0)).refine(rec, PARAMS)
    assert keep_all.num_planes == 9
    # Default: the halves of each cut plane lie on one plane and are re-merged; the fragment
    # labelled "back wall" lies on the left wall it touches and joins it. The room comes back.
    merged = DenseCrfRefiner(DenseCrfRefiner.Config(iterations=0)).refine(rec, PARAMS)
    np.testing.assert_array_equal(merged.labels, np.where(labels == 0, 0, gt))
    np.testing.assert_allclose(merged.planes[:, :3], ROOM[:, :3], atol=1e-4)


@pytest.mark.parametrize("changes", [
    {"connectivity": 6},
    {"confidence": 0.5},
    {"confidence": 1.0},
    {"theta_normal": 0.0},
    {"w_depth": -1.0},
    {"iterations": -1},
    {"min_area": -5},
    {"merge_angle_deg": 0.0},
    {"merge_distance": 0.0},
    {"fill_distance": -1.0},
])
def test_bad_config_is_a_config_error(changes):
    with pytest.raises(ConfigError):
        DenseCrfRefiner(DenseCrfRefiner.Config(**changes))


def test_dense_crf_on_a_synthetic_view(synthetic_view):
    """Speckled ground-truth labels of a generated room (mild cue corruption) get cleaner."""
    view = synthetic_view
    gt = view.gt_labels
    rng = np.random.default_rng(0)
    num = int(gt.max())
    noisy = np.where(rng.random(gt.shape) < 0.15, rng.integers(0, num + 1, gt.shape), gt)
    rec = Reconstruction(frame=view.frame, labels=noisy.astype(np.int32),
                         planes=np.tile([0.0, 0.0, -1.0, 1.0], (num, 1)))
    # The speckle includes label 0 as an observed label, so 0 keeps the paper's unary here.
    cfg = DenseCrfRefiner.Config(min_area=0, uniform_nonplanar=False)
    out = DenseCrfRefiner(cfg).refine(rec, PARAMS)
    # Splitting renumbers labels: map each output label to its majority ground-truth label.
    majority = np.zeros(out.num_planes + 1, dtype=np.int64)
    for k in range(1, out.num_planes + 1):
        majority[k] = np.bincount(gt[out.labels == k]).argmax()
    assert (noisy == gt).mean() < 0.87
    assert (majority[out.labels] == gt).mean() > 0.98  # measured 0.998


def test_nonplanar_pixels_are_filled_but_do_not_bend_the_planes():
    """RANSAC left a 10-px band of the back wall non-planar. Without the fill gate the CRF
    (uniform unary on label 0) gives the band back to the wall, and the wall is fit on its RANSAC
    inliers only, so a non-planar object in the band does not tilt it. With the default gate
    (0.1 of the scene radius) the band stays non-planar where the object is, and is filled where
    its points lie on the wall."""
    frame, gt = room()
    labels = gt.copy()
    cols = np.arange(gt.shape[1])[None, :]
    band = (gt == 3) & (cols >= 56) & (cols < 66)
    labels[band] = 0
    obj = band & (np.arange(gt.shape[0])[:, None] < 48)
    depth = frame.depth.copy()
    depth[obj] *= 0.5                   # a non-planar object in front of the upper wall
    rec = Reconstruction(frame=frame.with_(depth=depth), labels=labels, planes=ROOM)
    ungated = DenseCrfRefiner(DenseCrfRefiner.Config(fill_distance=float("inf"))).refine(
        rec, PARAMS)
    assert ungated.num_planes == 5
    assert np.all(ungated.labels[band] == 3)
    np.testing.assert_allclose(ungated.planes[2], ROOM[2], atol=1e-4)
    gated = DenseCrfRefiner().refine(rec, PARAMS)
    assert not np.any(gated.labels[obj])
    assert np.all(gated.labels[band & ~obj] == 3)
    np.testing.assert_array_equal(gated.labels[~band], ungated.labels[~band])
    np.testing.assert_allclose(gated.planes[2], ROOM[2], atol=1e-4)
