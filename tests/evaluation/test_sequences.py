"""N-view metrics on exact predictions, and the fallback relative pose on a known pair."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from monoplane.datamodel import Reconstruction
from monoplane.evaluation.sequences import consistency, plane_errors, similarity_to_truth
from monoplane.evaluation.twoview import (
    ground_truth_sfm,
    rotation_error_deg,
    translation_angle_deg,
)
from monoplane.geometry.relative_pose import fallback_relative_pose
from monoplane.stages.fusers import AverageFuser
from monoplane.synth import generate
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
    views = [Reconstruction(frame=v.frame, labels=v.gt_labels, params=v.gt_params)
             for v in synth.views]
    scene = AverageFuser().fuse(views, sfm)
    good, total = consistency(scene, synth.views, synth.view_to_global)
    assert total > 0 and good / total >= 0.9
    normal, offset = plane_errors(scene, synth.views, synth.gt_planes_world,
                                  synth.view_to_global)
    assert np.median(normal) < 0.5 and np.median(offset) < 0.01


def test_fallback_pose_of_a_known_pair() -> None:
    synth = generate(6, level="clean", width=320, height=240, n_views=2)
    v0, v1 = synth.views
    fb = fallback_relative_pose(v0.frame.rgb, v0.frame.K, v0.gt_depth, v1.frame.rgb,
                                v1.frame.K, 0.5 * v1.gt_depth)
    assert fb is not None and fb.inliers >= 15
    R_true = v1.R @ v0.R.T
    t_true = v1.t - R_true @ v0.t
    assert rotation_error_deg(fb.R, R_true) < 1.0
    # Metric baseline from view 0's depth; view 1's depth was halved, so its scale is 2.
    assert translation_angle_deg(fb.t, t_true) < 5.0
    assert abs(np.linalg.norm(fb.t) / np.linalg.norm(t_true) - 1.0) < 0.1
    assert abs(fb.depth_scale_j - 2.0) < 0.1
