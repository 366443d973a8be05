"""N-view metrics on exact predictions."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from monoplane.datamodel import Reconstruction
from monoplane.evaluation.sequences import consistency, plane_errors, similarity_to_truth
from monoplane.evaluation.twoview import ground_truth_sfm
from monoplane.stages.fusers import AverageFuser
from monoplane.synth.sequence import generate_sequence


def test_similarity_recovers_a_known_transform() -> None:
    rng = np.random.default_rng(0)
    R_gt = Rotation.random(4, random_state=1).as_matrix()
    c_gt = rng.normal(size=(4, 3))
    A = Rotation.random(random_state=2).as_matrix()
    s, b = 2.5, np.array([1.0, -2.0, 0.5])
    # Predicted world y with x_gt = s A y + b: y = Aᵀ (x_gt − b) / s; R_pred = R_gt A.
    c_pred = (c_gt - b) @ A / s
    R_pred = R_gt @ A
    s_fit, A_fit, b_fit = similarity_to_truth(R_pred, c_pred, R_gt, c_gt)
    assert abs(s_fit - s) < 1e-9
    np.testing.assert_allclose(A_fit, A, atol=1e-9)
    np.testing.assert_allclose(b_fit, b, atol=1e-9)


def test_exact_scene_is_consistent_with_zero_plane_error() -> None:
    synth = generate_sequence(3, 3, "star", level="clean", width=128, height=96)
    sfm = ground_truth_sfm(synth)
    views = [Reconstruction(frame=v.frame, labels=v.gt_labels, planes=v.gt_params)
             for v in synth.views]
    scene = AverageFuser().fuse(views, sfm)
    good, total = consistency(scene, synth.views, synth.view_to_global)
    assert total > 0 and good / total >= 0.9
    normal, offset = plane_errors(scene, synth.views, synth.gt_planes_world,
                                  synth.view_to_global)
    assert np.median(normal) < 0.5 and np.median(offset) < 0.01


def test_planes_seen_and_curved_global_planes_on_known_labels() -> None:
    from types import SimpleNamespace

    from monoplane.datamodel import Camera, Frame, Scene
    from monoplane.evaluation.sequences import curved_global_planes, true_planes_seen

    gt = [np.zeros((10, 10), np.int32), np.zeros((10, 10), np.int32)]
    gt[0][:6] = 1           # 60 px of true plane 0
    gt[0][9, :3] = 2        # 3 px of true plane 1
    gt[1][:3] = 1           # 30 px of true plane 2
    views = [SimpleNamespace(gt_labels=g) for g in gt]
    links = [{1: 0, 2: 1}, {1: 2}]
    assert true_planes_seen(views, links, min_area=0.05) == {0, 2}
    assert true_planes_seen(views, links) == {0, 1, 2}

    # Global plane 0 lies on true plane 0; global plane 1 on non-planar truth in both views.
    K = np.array([[10.0, 0, 4.5], [0, 10.0, 4.5], [0, 0, 1]])
    recs = []
    for g in gt:
        labels = np.where(g > 0, 1, 2).astype(np.int32)
        labels[9, 3:] = 0
        recs.append(Reconstruction(frame=Frame(rgb=None, K=K, depth=np.ones((10, 10))),
                                   labels=labels, planes=[[0, 0, -1, 1.0]] * 2))
    cams = [Camera(K=K, R=np.eye(3), t=np.zeros(3), width=10, height=10) for _ in gt]
    scene = Scene(cameras=cams, views=recs, planes=[[0, 0, -1, 1.0]] * 2,
                  links=[{1: 0, 2: 1}, {1: 0, 2: 1}])
    assert curved_global_planes(scene, views) == 1
