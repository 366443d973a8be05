"""The ``colmap`` matcher on a rendered, textured two-view pair with a known relative pose."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from monoplane.datamodel import Frame, intrinsics_matrix
from monoplane.errors import InvalidInput
from monoplane.features import Correspondences
from monoplane.geometry.camera import look_at
from monoplane.stages.features import SiftFeatures
from monoplane.stages.matchers import ColmapMatcher, SfmError, monoplane_register_matchers

W, H, F = 480, 360, 380.0
K = intrinsics_matrix(F, F, (W - 1) / 2, (H - 1) / 2)
#: World up: the room's world frame has y down, like the camera.
UP = np.array([0.0, -1.0, 0.0])
# Room (world frame, y down): floor y = 1.5, back wall z = 6, side walls x = ±2.5, ceiling.
ROOM = np.array([[0, -1, 0, 1.5], [0, 0, -1, 6.0], [1, 0, 0, 2.5], [-1, 0, 0, 2.5],
                 [0, 1, 0, 1.5]], dtype=np.float64)


def render(R: np.ndarray, t: np.ndarray, seed: int = 0) -> np.ndarray:
    """Ray-cast the textured room: each plane carries its own blurred random texture."""
    rng = np.random.default_rng(seed)
    textures = [cv2.GaussianBlur(rng.integers(0, 256, (256, 256, 3), dtype=np.uint8), (0, 0), 1.2)
                for _ in ROOM]
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    rays = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T @ R  # world directions
    centre = -R.T @ t
    best = np.full((H, W), np.inf)
    label = np.zeros((H, W), int)
    for i, p in enumerate(ROOM):
        with np.errstate(divide="ignore", invalid="ignore"):
            s = -(p[:3] @ centre + p[3]) / (rays @ p[:3])
        hit = (s > 0) & (s < best)
        best[hit], label[hit] = s[hit], i
    points = centre + rays * best[..., None]
    img = np.zeros((H, W, 3), np.uint8)
    for i, p in enumerate(ROOM):
        a = np.array([1.0, 0, 0]) if abs(p[0]) < 0.9 else np.array([0, 0, 1.0])
        e1 = np.cross(p[:3], a)
        e2 = np.cross(p[:3], e1)
        mu = ((points @ e1) * 40.0 % 256).astype(np.float32)
        mv = ((points @ e2) * 40.0 % 256).astype(np.float32)
        warped = cv2.remap(textures[i], mu, mv, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        img[label == i] = warped[label == i]
    return img


@pytest.fixture(scope="module")
def pair() -> tuple[list[Frame], list[tuple[np.ndarray, np.ndarray]]]:
    poses = [look_at(np.array([0.0, 0.0, 0.0]), np.array([0.0, 0.3, 5.0]), UP),
             look_at(np.array([0.6, -0.1, 0.2]), np.array([0.2, 0.3, 5.0]), UP)]
    frames = [Frame(rgb=render(R, t), K=K, name=f"view{i}") for i, (R, t) in enumerate(poses)]
    return frames, poses


def relative_errors(cams, poses) -> tuple[float, float]:
    (R0, t0), (R1, t1) = poses
    R_gt = R1 @ R0.T
    t_gt = t1 - R_gt @ t0
    R = cams[1].R @ cams[0].R.T
    t = cams[1].t - R @ cams[0].t
    rot = np.degrees(np.arccos(np.clip((np.trace(R @ R_gt.T) - 1) / 2, -1, 1)))
    trans = np.degrees(np.arccos(np.clip(t @ t_gt / np.linalg.norm(t) / np.linalg.norm(t_gt),
                                         -1, 1)))
    return float(rot), float(trans)


def test_registered_through_hook() -> None:
    assert ColmapMatcher in monoplane_register_matchers()
    assert ColmapMatcher.name == "colmap"


def test_known_pose_recovered_with_fixed_intrinsics(pair) -> None:
    frames, poses = pair
    sfm = ColmapMatcher(ColmapMatcher.Config(fixed_intrinsics=True)).match(frames)
    assert [c.name for c in sfm.cameras] == ["view0", "view1"]
    np.testing.assert_allclose(sfm.cameras[0].K, K, atol=1e-9)
    rot, trans = relative_errors(sfm.cameras, poses)
    assert rot < 0.5 and trans < 2.0
    assert len(sfm.points) > 200
    matches = sfm.matches[(0, 1)]
    assert len(matches) >= len(sfm.points)
    # Observations reproject onto their keypoints (pixel centres at integers).
    for v, cam in enumerate(sfm.cameras):
        has = sfm.point_ids[v] >= 0
        x = sfm.points[sfm.point_ids[v][has]] @ cam.R.T + cam.t
        uv = x[:, :2] / x[:, 2:] * [F, F] + K[:2, 2]
        err = np.linalg.norm(uv - sfm.keypoints[v][has], axis=1)
        assert np.median(err) < 1.0


def test_estimated_focal_close_to_truth(pair) -> None:
    frames, poses = pair
    start = [f.with_(K=intrinsics_matrix(0.9 * F, 0.9 * F, *K[:2, 2])) for f in frames]
    sfm = ColmapMatcher().match(start)
    assert abs(sfm.cameras[0].K[0, 0] - F) / F < 0.05
    assert sfm.cameras[0].K[0, 0] == sfm.cameras[1].K[0, 0]  # shared intrinsics
    rot, _ = relative_errors(sfm.cameras, poses)
    assert rot < 1.0


def test_unrelated_images_fail_with_reason() -> None:
    rng = np.random.default_rng(1)
    frames = [Frame(rgb=cv2.GaussianBlur(rng.integers(0, 256, (240, 320, 3), dtype=np.uint8),
                                         (0, 0), 1.0), K=K, name=f"noise{i}") for i in range(2)]
    with pytest.raises(SfmError, match="too few verified matches"):
        ColmapMatcher().match(frames)


def test_textureless_image_fails_with_reason(pair) -> None:
    frames, _ = pair
    flat = Frame(rgb=np.full((H, W, 3), 127, np.uint8), K=K, name="flat")
    with pytest.raises(SfmError, match="flat: only 0 SIFT features"):
        ColmapMatcher().match([frames[0], flat])


def test_a_textureless_image_among_others_is_left_out(pair) -> None:
    frames, _ = pair
    flat = Frame(rgb=np.full((H, W, 3), 127, np.uint8), K=K, name="flat")
    sfm = ColmapMatcher().match([frames[0], flat, frames[1]])
    assert sfm.registered == [True, False, True]
    assert any("flat: only 0 SIFT features" in n for n in sfm.notes)


def test_needs_two_images(pair) -> None:
    with pytest.raises(InvalidInput, match="at least 2 images"):
        ColmapMatcher().match(pair[0][:1])


class _ImportedSift(SiftFeatures):
    """OpenCV's SIFT, written into COLMAP's database instead of COLMAP extracting its own."""

    name = "imported-sift"
    sfm_native = None


def test_imported_correspondences_recover_the_known_pose(pair) -> None:
    frames, poses = pair
    stage = _ImportedSift()
    found = Correspondences(stage, frames)
    sfm = ColmapMatcher(ColmapMatcher.Config(fixed_intrinsics=True)).match(frames, found)
    rot, trans = relative_errors(sfm.cameras, poses)
    assert rot < 0.5 and trans < 2.0
    assert any("'imported-sift' features stage" in n for n in sfm.notes)
    # The model's keypoints are the stage's own, in order, and its verified matches a subset
    # of the stage's matches.
    for v in range(2):
        np.testing.assert_allclose(sfm.keypoints[v], found.keypoints(v).pixels, atol=1e-3)
    raw = {tuple(m) for m in found.matches(0, 1)}
    verified = sfm.matches[(0, 1)]
    assert 0.5 * len(raw) < len(verified) <= len(raw)
    assert {tuple(m) for m in verified} <= raw


def test_sift_stage_lets_colmap_extract_its_own(pair) -> None:
    frames, poses = pair
    found = Correspondences(SiftFeatures(), frames)
    sfm = ColmapMatcher(ColmapMatcher.Config(fixed_intrinsics=True)).match(frames, found)
    assert not any("features stage" in n for n in sfm.notes)
    assert not found._keypoints  # nothing was detected: COLMAP ran its own SIFT
    assert relative_errors(sfm.cameras, poses)[0] < 0.5


def test_imported_features_of_a_textureless_image_are_named(pair) -> None:
    frames, _ = pair
    flat = Frame(rgb=np.full((H, W, 3), 127, np.uint8), K=K, name="flat")
    found = Correspondences(_ImportedSift(), [frames[0], flat])
    with pytest.raises(SfmError, match="flat: only 0 imported-sift keypoints"):
        ColmapMatcher().match([frames[0], flat], found)
