"""Registration maths against closed-form answers: minimal solvers, plane-pair rotations, plane
offsets, the dense check, the epipolar refinement and the feature-based estimators."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from monoplane.evaluation.twoview import rotation_error_deg, translation_angle_deg
from monoplane.geometry.epipolar import (
    depth_disagreement,
    epipolar_support,
    refine_epipolar,
)
from monoplane.geometry.pose_hypotheses import (
    feature_hypotheses,
    rotation_hypotheses,
    translation_from_matches,
    translation_from_planes,
)
from monoplane.geometry.relative_pose import (
    essential_pose,
    guided_matches,
    match_features,
    sift_features,
)
from monoplane.geometry.view_agreement import Hypothesis, agreement, view_geometry
from monoplane.synth import generate

R_TRUE = Rotation.from_euler("xyz", [4.0, 28.0, -3.0], degrees=True).as_matrix()
T_TRUE = np.array([0.6, -0.1, 0.25])


def _points(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.c_[rng.uniform(-1.5, 1.5, n), rng.uniform(-1, 1, n), rng.uniform(2, 5, n)]


def _other(x_ref: np.ndarray, s: float) -> np.ndarray:
    """Points of the other view in its own units: s x_o = R x_r + t."""
    return (x_ref @ R_TRUE.T + T_TRUE) / s


@pytest.mark.parametrize("fixed", [True, False])
def test_feature_ransac_recovers_the_pose_among_outliers(fixed: bool) -> None:
    x_ref = _points(60)
    s = 1.0 if fixed else 2.5
    x_other = _other(x_ref, s)
    x_other[:25] = _points(25, seed=2) / s  # 40 % outliers
    hyps = feature_hypotheses(x_ref, x_other, 1.0 if fixed else None, tol=0.02)
    best = hyps[0]
    assert best.support == 35
    np.testing.assert_allclose(best.R, R_TRUE, atol=1e-9)
    np.testing.assert_allclose(best.t, T_TRUE, atol=1e-9)
    assert best.s == pytest.approx(s, rel=1e-9)


@pytest.mark.parametrize("fixed", [1.0, None])
def test_translation_of_a_known_rotation_needs_one_or_two_matches(fixed: float | None) -> None:
    x_ref = _points(2 if fixed is None else 1)
    s = 1.0 if fixed else 0.4
    found = translation_from_matches(R_TRUE, np.r_[x_ref, x_ref + 0.5],
                                     np.r_[_other(x_ref, s), _other(x_ref + 0.5, s)], fixed,
                                     tol=0.01)
    assert found is not None
    t, s_fit, inliers = found
    np.testing.assert_allclose(t, T_TRUE, atol=1e-9)
    assert s_fit == pytest.approx(s, rel=1e-9)
    assert inliers == 2 * len(x_ref)


def _box_view(R_wc: np.ndarray, t_wc: np.ndarray, scale: float = 1.0):
    """A camera's planes of an axis-aligned room 4 x 3 x 6 m: floor, ceiling, three walls, a
    table top, with areas; ``scale`` divides the offsets (relative depth)."""
    world = np.array([[0, -1, 0, 1.5], [0, 1, 0, 1.5], [1, 0, 0, 2.0], [-1, 0, 0, 2.0],
                      [0, 0, -1, 4.0], [0, -1, 0, 0.8]], float)
    areas = np.array([9000, 4000, 6000, 3000, 12000, 1500], float)
    # n_c = R n_w, d_c = d_w - n_c . t
    n_c = world[:, :3] @ R_wc.T
    d_c = world[:, 3] - n_c @ t_wc
    planes = np.c_[n_c, d_c / scale]
    # Normals face the camera (d > 0 with the camera inside the room).
    return planes, areas


def _geometry(planes: np.ndarray, areas: np.ndarray, metric: bool = True):
    depth = np.ones((8, 8), np.float32)
    normals = np.zeros((8, 8, 3), np.float32)
    normals[..., 2] = -1
    return view_geometry(np.eye(3), depth, normals, None, planes, areas, metric, grid=8)


def test_plane_pairs_give_the_rotation_and_the_offsets_the_translation() -> None:
    R_r = Rotation.from_euler("y", 10, degrees=True).as_matrix()
    R_o = R_TRUE @ R_r
    t_r = np.array([0.1, 0.2, -0.5])
    t_o = R_TRUE @ t_r + T_TRUE
    ref = _geometry(*_box_view(R_r, t_r))
    for s, metric in ((1.0, True), (2.0, False)):
        other = _geometry(*_box_view(R_o, t_o, scale=s), metric=metric)
        rotations = rotation_hypotheses(ref, other)
        assert rotation_error_deg(rotations[0][0], R_TRUE) < 1e-6
        found = translation_from_planes(rotations[0][0], ref, other, 1.0 if metric else None)
        t, s_fit, support = found[0]
        np.testing.assert_allclose(t, T_TRUE, atol=1e-9)
        assert s_fit == pytest.approx(s, rel=1e-9)
        assert support == 6


def _synth_pair():
    synth = generate(6, level="clean", width=320, height=240, n_views=2)
    v0, v1 = synth.views
    R = v1.R @ v0.R.T
    return v0, v1, R, v1.t - R @ v0.t


def _view(v, depth_factor: float = 1.0):
    f = v.frame
    return view_geometry(f.K, v.gt_depth * depth_factor, f.normals, f.rgb, v.gt_params,
                         np.bincount(v.gt_labels.ravel())[1:], True)


def test_dense_check_tells_the_true_pose_from_a_wrong_one() -> None:
    v0, v1, R, t = _synth_pair()
    ref, other = _view(v0), _view(v1)
    right = agreement(ref, other, Hypothesis(R, t, 1.0, "test"), tol=0.02)
    assert right.overlap > 0.4 and right.violation < 0.01 and right.colour > 0.9
    turned = Rotation.from_euler("y", 8, degrees=True).as_matrix() @ R
    wrong = agreement(ref, other, Hypothesis(turned, t, 1.0, "test"), tol=0.02)
    assert wrong.score < 0.5 * right.score


def test_epipolar_refinement_reduces_a_small_error() -> None:
    v0, v1, R, t = _synth_pair()
    pi, pj = match_features(sift_features(v0.frame.rgb), sift_features(v1.frame.rgb))
    start = Rotation.from_euler("x", 1.5, degrees=True).as_matrix() @ R
    found = refine_epipolar(Hypothesis(start, t, 1.0, "test"), pi, pj, v0.frame.K,
                            v1.frame.K, threshold_px=8.0)
    assert found is not None
    hyp, inliers = found
    assert inliers >= 15
    # The epipolar cost is flat along a rotation-translation trade-off on a narrow view (at
    # 0.9 degrees its median Sampson distance is within 0.02 px of the truth's): the error
    # shrinks but does not vanish.
    assert rotation_error_deg(hyp.R, R) < 1.0
    assert translation_angle_deg(hyp.t, t) < 6.0
    assert np.linalg.norm(hyp.t) == pytest.approx(np.linalg.norm(t))


def test_essential_pose_of_a_known_pair() -> None:
    v0, v1, R, t = _synth_pair()
    pi, pj = match_features(sift_features(v0.frame.rgb), sift_features(v1.frame.rgb))
    fb = essential_pose(pi, pj, v0.frame.K, v0.gt_depth, v1.frame.K, 0.5 * v1.gt_depth, 15)
    assert fb is not None and fb.inliers >= 15
    assert rotation_error_deg(fb.R, R) < 1.0
    # Metric baseline from view 0's depth; view 1's depth was halved, so its scale is 2.
    assert translation_angle_deg(fb.t, t) < 5.0
    assert abs(np.linalg.norm(fb.t) / np.linalg.norm(t) - 1.0) < 0.1
    assert abs(fb.depth_scale_j - 2.0) < 0.1


def test_guided_matching_finds_more_correct_matches_than_the_ratio_test() -> None:
    v0, v1, R, t = _synth_pair()
    f0, f1 = sift_features(v0.frame.rgb), sift_features(v1.frame.rgb)
    plain, _ = match_features(f0, f1)
    # Predict every keypoint of view 0 in view 1 with the true pose and view 0's depth.
    d = v0.gt_depth[np.clip(np.rint(f0.pixels[:, 1]).astype(int), 0, 239),
                    np.clip(np.rint(f0.pixels[:, 0]).astype(int), 0, 319)]
    x = np.linalg.solve(v0.frame.K, np.c_[f0.pixels, np.ones(len(f0.pixels))].T).T * d[:, None]
    q = x @ R.T + t
    pred = (q @ v1.frame.K.T)[:, :2] / q[:, 2:]
    pred[d <= 0] = np.nan
    pi, pj = guided_matches(f0, f1, pred, radius=8.0)
    ui = np.rint(pi).astype(int)
    z = v0.gt_depth[ui[:, 1], ui[:, 0]]
    xi = np.linalg.solve(v0.frame.K, np.c_[pi, np.ones(len(pi))].T).T * z[:, None]
    qi = xi @ R.T + t
    err = np.linalg.norm((qi @ v1.frame.K.T)[:, :2] / qi[:, 2:] - pj, axis=1)
    # More correct guided matches than unguided matches of any kind.
    assert np.sum(err < 3.0) > 1.2 * len(plain)


def _projected_pair(n: int = 200, seed: int = 5):
    """Exact matches of random 3D points in two pinhole views, with their depth maps."""
    from monoplane.datamodel import intrinsics_matrix

    K = intrinsics_matrix(500.0, 500.0, 319.5, 239.5)
    x_ref = _points(n, seed)
    x_oth = x_ref @ R_TRUE.T + T_TRUE
    keep = x_oth[:, 2] > 0.5
    x_ref, x_oth = x_ref[keep], x_oth[keep]
    p_ref = x_ref[:, :2] / x_ref[:, 2:] * 500.0 + [319.5, 239.5]
    p_oth = x_oth[:, :2] / x_oth[:, 2:] * 500.0 + [319.5, 239.5]
    inside = np.all((p_ref > 0) & (p_ref < [639, 479]) & (p_oth > 0) & (p_oth < [639, 479]),
                    axis=1)
    x_ref, x_oth, p_ref, p_oth = x_ref[inside], x_oth[inside], p_ref[inside], p_oth[inside]

    def depth_map(p: np.ndarray, z: np.ndarray) -> np.ndarray:
        d = np.zeros((480, 640), np.float32)
        d[np.rint(p[:, 1]).astype(int), np.rint(p[:, 0]).astype(int)] = z
        return d

    class _G:  # what depth_disagreement reads of a ViewGeometry
        def __init__(self, depth: np.ndarray) -> None:
            self.K, self.depth = K, depth

    # Keypoints sit on integer pixels so that the depth lookup is exact.
    p_ref, p_oth = np.rint(p_ref), np.rint(p_oth)
    return K, p_ref, p_oth, _G(depth_map(p_ref, x_ref[:, 2])), _G(depth_map(p_oth, x_oth[:, 2]))


def test_epipolar_support_counts_the_matches_within_the_threshold() -> None:
    K, p_ref, p_oth, _, _ = _projected_pair()
    true = Hypothesis(R_TRUE, 3.0 * T_TRUE, 1.0, "test")  # the length does not matter
    assert epipolar_support(true, p_ref, p_oth, K, K, 1.0) == len(p_ref)
    # Every other match moved 40 px off its epipolar line (F = K^-T [t]x R K^-1).
    tx = np.array([[0, -T_TRUE[2], T_TRUE[1]], [T_TRUE[2], 0, -T_TRUE[0]],
                   [-T_TRUE[1], T_TRUE[0], 0]])
    F = np.linalg.inv(K).T @ tx @ R_TRUE @ np.linalg.inv(K)
    lines = np.c_[p_ref, np.ones(len(p_ref))] @ F.T
    off = lines[:, :2] / np.linalg.norm(lines[:, :2], axis=1, keepdims=True)
    shifted = p_oth + 40.0 * off
    shifted[::2] = p_oth[::2]
    assert epipolar_support(true, p_ref, shifted, K, K, 1.0) == len(p_ref[::2])
    turned = Rotation.from_euler("x", 3, degrees=True).as_matrix() @ R_TRUE
    assert epipolar_support(Hypothesis(turned, T_TRUE, 1.0, "t"), p_ref, p_oth, K, K, 1.0) == 0


def test_depth_disagreement_is_zero_for_the_true_pose_and_any_scale() -> None:
    K, p_ref, p_oth, ref, other = _projected_pair()
    true = Hypothesis(R_TRUE, T_TRUE, 1.0, "test")
    # Rounding the keypoints to pixels leaves a little: the ratio is constant to 1 %.
    assert depth_disagreement(true, p_ref, p_oth, ref, other, 2.0) < 0.02
    other.depth = other.depth * 7.0  # relative depth: the view's scale is free
    assert depth_disagreement(true, p_ref, p_oth, ref, other, 2.0) < 0.02
    # A pose 2 degrees off, all matches taken as its inliers: the triangulated depths bend
    # away from the views' own (0.14 here against 0.007).
    turned = Rotation.from_euler("y", 2.0, degrees=True).as_matrix() @ R_TRUE
    assert depth_disagreement(Hypothesis(turned, T_TRUE, 1.0, "t"), p_ref, p_oth, ref, other,
                              1e9) > 0.1
    assert depth_disagreement(true, p_ref[:5], p_oth[:5], ref, other, 2.0) == float("inf")


def test_the_old_module_still_gathers_the_registration_names() -> None:
    import monoplane.geometry.epipolar as epipolar
    import monoplane.geometry.view_registration as old

    assert old.refine_epipolar is epipolar.refine_epipolar
    assert all(hasattr(old, name) for name in old.__all__)
