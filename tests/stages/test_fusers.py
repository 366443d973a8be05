"""Plane matching and the ``average`` fuser: closed forms and exact synthetic ground truth."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.datamodel import Reconstruction, orient_towards_camera, plane_to_camera
from monoplane.evaluation.twoview import ground_truth_sfm
from monoplane.geometry.plane_matching import (
    fuse_planes,
    keypoint_counts,
    keypoint_plane_matches,
    reprojection_iou,
    reprojection_plane_matches,
)
from monoplane.stages.fusers import AverageFuser, monoplane_register_fusers
from monoplane.synth import generate


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def test_two_normals_fuse_to_their_bisector() -> None:
    n1, n2 = _unit([0, 0.2, 1]), _unit([0.3, -0.1, 1])
    fused = fuse_planes([[*n1, 2.0], [*n2, 3.0]])
    np.testing.assert_allclose(fused[:3], _unit(n1 + n2), atol=1e-12)
    assert fused[3] == pytest.approx(2.5)


def test_n_normals_on_a_cone_fuse_to_the_axis() -> None:
    axis = _unit([1, 2, 3])
    e1 = _unit(np.cross(axis, [1, 0, 0]))
    e2 = np.cross(axis, e1)
    angles = np.linspace(0, 2 * np.pi, 7, endpoint=False)
    normals = [np.cos(0.3) * axis + np.sin(0.3) * (np.cos(a) * e1 + np.sin(a) * e2)
               for a in angles]
    offsets = np.arange(7, dtype=float)
    fused = fuse_planes(np.c_[normals, offsets])
    np.testing.assert_allclose(fused[:3], axis, atol=1e-12)
    assert fused[3] == pytest.approx(3.0)


def test_fusion_ignores_each_plane_sign_and_maximises_objective() -> None:
    rng = np.random.default_rng(0)
    normals = np.array([_unit([0, 0, 1] + 0.2 * rng.standard_normal(3)) for _ in range(5)])
    planes = np.c_[normals, np.full(5, 1.5)]
    flipped = planes.copy()
    flipped[[1, 3]] *= -1
    a, b = fuse_planes(planes), fuse_planes(flipped)
    np.testing.assert_allclose(a, b, atol=1e-12)
    objective = lambda n: np.sum((normals @ n) ** 2)  # noqa: E731
    for _ in range(200):
        assert objective(a[:3]) >= objective(_unit(a[:3] + 0.05 * rng.standard_normal(3)))


def test_keypoint_criterion_thresholds_and_mutual_check() -> None:
    labels_i = np.repeat(np.array([[1, 2, 0]]), 4, axis=0)  # columns 0, 1, 2
    labels_j = np.repeat(np.array([[2, 1, 1]]), 4, axis=0)
    kp_i = np.array([[0, 0], [1, 0], [2, 0]], dtype=float)
    kp_j = np.array([[0, 0], [1, 0], [2, 0]], dtype=float)
    # 11 matches plane1(i) -> plane2(j); 5 matches plane2(i) -> plane1(j); 3 plane2(i) -> 2(j).
    pairs = np.array([[0, 0]] * 11 + [[1, 1]] * 5 + [[1, 0]] * 3 + [[2, 2]] * 4)
    counts = keypoint_counts(labels_i, labels_j, kp_i, kp_j, pairs)
    assert counts[1, 2] == 11 and counts[2, 1] == 5 and counts[2, 2] == 3 and counts[0, 1] == 4
    np.testing.assert_array_equal(keypoint_plane_matches(counts), [[1, 2]])
    # The mutual check: plane 2 of j gets 11 of 14 from plane 1 of i (78 %), passes at 0.6,
    # fails at 0.8.
    assert len(keypoint_plane_matches(counts, mutual_ratio=0.8)) == 0
    assert len(keypoint_plane_matches(counts, min_matches=11)) == 0  # "more than"


def test_reprojection_iou_identity_and_shift() -> None:
    K = np.array([[100.0, 0, 31.5], [0, 100.0, 23.5], [0, 0, 1]])
    labels = np.zeros((48, 64), np.int32)
    labels[:, :32] = 1
    labels[:, 32:] = 2
    params = np.array([[0, 0, -1, 2.0], [0, 0, -1, 2.0]])  # fronto-parallel plane z = 2
    iou = reprojection_iou(labels, params, K, labels, K, np.eye(3), np.zeros(3))
    np.testing.assert_allclose(iou, np.eye(2))
    # Moving the camera 0.16 m along +x shifts the image by 8 px to the left.
    shifted = reprojection_iou(labels, params, K, labels, K, np.eye(3), np.array([-0.16, 0, 0]))
    # Plane 1 of i appears in columns 0..23 of j, fully visible: IoU with plane 1 = 24/32.
    assert shifted[0, 0] == pytest.approx(24 / 32)
    np.testing.assert_array_equal(reprojection_plane_matches(shifted, shifted.T), [[1, 1],
                                                                                    [2, 2]])


@pytest.mark.parametrize("n_views", [2, 3])
def test_exact_planes_fuse_to_ground_truth(n_views: int) -> None:
    synth = generate(3, level="clean", n_views=n_views)
    sfm = ground_truth_sfm(synth, seed=0)
    views = [Reconstruction(frame=v.frame, labels=v.gt_labels, planes=v.gt_params)
             for v in synth.views]
    scene = AverageFuser().fuse(views, sfm)
    gt = synth.gt_planes_world
    # Every global plane's members are one true plane, and it equals that plane.
    for g, plane in enumerate(scene.planes):
        true_ids = {synth.view_to_global[v][local] for v, t in enumerate(scene.links)
                    for local, glob in t.items() if glob == g}
        assert len(true_ids) == 1
        ref = gt[true_ids.pop()]
        a = orient_towards_camera(plane_to_camera(plane, synth.views[0].R, synth.views[0].t))
        b = orient_towards_camera(plane_to_camera(ref, synth.views[0].R, synth.views[0].t))
        np.testing.assert_allclose(a, b, atol=1e-6)
    # Most true planes seen by several views were merged into one global plane.
    assert scene.planes.shape[0] <= gt.shape[0] + 2


def test_registered_through_hook() -> None:
    assert AverageFuser in monoplane_register_fusers()


def _merge_into_neighbour(rec: Reconstruction, local: int) -> Reconstruction:
    """``rec`` with plane ``local`` swallowed by the neighbour it borders most (ids shifted)."""
    import cv2

    mask = rec.labels == local
    ring = cv2.dilate(mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool) & ~mask
    around = rec.labels[ring]
    neighbour = int(np.bincount(around[around > 0]).argmax())
    labels = rec.labels.copy()
    labels[mask] = neighbour
    labels[labels > local] -= 1
    params = np.delete(rec.planes, local - 1, axis=0)
    return Reconstruction(frame=rec.frame, labels=labels, planes=params)


def test_a_plane_merged_away_in_one_view_is_recovered_from_the_others() -> None:
    from monoplane.synth.sequence import generate_sequence

    synth = generate_sequence(2, 3, "walk", level="clean")
    sfm = ground_truth_sfm(synth, seed=0)
    views = [Reconstruction(frame=v.frame, labels=v.gt_labels, planes=v.gt_params)
             for v in synth.views]
    # A true plane every view sees, small in view 0: view 0 merges it into a neighbour.
    seen_by_all = set.intersection(*[set(t.values()) for t in synth.view_to_global])
    areas = {t: (synth.views[0].gt_labels == local).mean()
             for local, t in synth.view_to_global[0].items() if t in seen_by_all}
    true_id = min((t for t, a in areas.items() if a > 0.005), key=areas.get)
    local = next(k for k, t in synth.view_to_global[0].items() if t == true_id)
    truth_mask = synth.views[0].gt_labels == local
    views[0] = _merge_into_neighbour(views[0], local)

    kept = AverageFuser(AverageFuser.Config(recover_planes=False)).fuse(views, sfm)
    scene = AverageFuser().fuse(views, sfm)
    assert kept.views[0].num_planes == views[0].num_planes
    assert scene.views[0].num_planes == views[0].num_planes + 1
    new = views[0].num_planes + 1
    recovered = scene.views[0].labels == new
    iou = (recovered & truth_mask).sum() / (recovered | truth_mask).sum()
    assert iou > 0.9
    # It joins the global plane the other views give that true plane.
    other = next(k for k, t in synth.view_to_global[1].items() if t == true_id)
    assert scene.links[0][new] == scene.links[1][other]
    # The other views' labels and the global planes are left as they were.
    for v in (1, 2):
        np.testing.assert_array_equal(scene.views[v].labels, kept.views[v].labels)
    np.testing.assert_allclose(scene.planes, kept.planes)


def test_no_recovery_without_enough_views_or_on_exact_segmentations() -> None:
    from monoplane.synth.sequence import generate_sequence

    synth = generate_sequence(2, 3, "walk", level="clean")
    sfm = ground_truth_sfm(synth, seed=0)
    views = [Reconstruction(frame=v.frame, labels=v.gt_labels, planes=v.gt_params)
             for v in synth.views]
    exact = AverageFuser().fuse(views, sfm)
    assert [r.num_planes for r in exact.views] == [r.num_planes for r in views]
    strict = AverageFuser(AverageFuser.Config(recover_min_views=3))
    merged = [_merge_into_neighbour(views[0], 1), *views[1:]]
    assert strict.fuse(merged, sfm).views[0].num_planes == merged[0].num_planes
