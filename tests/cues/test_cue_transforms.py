"""Letterboxing, normalisation and output decoding around monocular networks."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.cues import (
    IMAGENET_MEAN,
    IMAGENET_STD,
    ModelSpec,
    decode_normals,
    depth_from_disparity,
    face_camera,
    parse_axes,
    plan_letterbox,
    prepare_image,
    relative_depth_from_depth,
    restore_map,
    scaled_intrinsics,
)
from monoplane.datamodel import default_intrinsics, pixel_rays
from monoplane.errors import ConfigError, InvalidInput


def test_keep_aspect_pads_to_the_multiple() -> None:
    spec = ModelSpec(output="inverse_depth", size=(518, 518), multiple_of=14)
    box = plan_letterbox(480, 640, spec)
    assert box.resized == (388, 518)
    assert box.padded == (392, 518)            # 388 -> 392 = 28 * 14; 518 = 37 * 14
    assert all(p % 14 == 0 for p in box.padded)


def test_fixed_model_size_wins_and_stretch_ignores_aspect() -> None:
    spec = ModelSpec(output="relative_depth", size=(384, 384))
    box = plan_letterbox(480, 640, spec, fixed=(256, 256))
    assert box.resized == (192, 256) and box.padded == (256, 256)
    stretch = ModelSpec(output="relative_depth", size=(100, 100), resize="stretch")
    box = plan_letterbox(480, 640, stretch)
    assert box.resized == box.padded == (128, 128)


def test_prepare_image_normalises_and_pads_by_replication() -> None:
    rgb = np.zeros((10, 20, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 255, 128, 0
    spec = ModelSpec(output="inverse_depth", size=(10, 20), multiple_of=8,
                     mean=IMAGENET_MEAN, std=IMAGENET_STD)
    box = plan_letterbox(10, 20, spec)
    x = prepare_image(rgb, spec, box)
    assert x.shape == (1, 3, 16, 24) and x.dtype == np.float32
    expected = (np.array([1.0, 128 / 255, 0.0]) - IMAGENET_MEAN) / IMAGENET_STD
    np.testing.assert_allclose(x[0, :, 15, 23], expected, rtol=1e-5)
    np.testing.assert_allclose(x[0, :, 3, 4], expected, rtol=1e-5)


@pytest.mark.parametrize("layout", ["nchw", "nhwc", "chw"])
def test_restore_map_crops_padding_and_handles_layouts(layout: str) -> None:
    spec = ModelSpec(output="normals", size=(12, 16), multiple_of=8)
    box = plan_letterbox(12, 16, spec)          # resized (12, 16), padded (16, 16)
    img = np.zeros((16, 16, 3), np.float32)
    img[:12, :16] = [0.0, 0.0, -1.0]
    img[12:] = [1.0, 0.0, 0.0]                  # padding rows must be cropped away
    out = {"nchw": img.transpose(2, 0, 1)[None], "nhwc": img[None],
           "chw": img.transpose(2, 0, 1)}[layout]
    restored = restore_map(out, box, 3)
    assert restored.shape == (12, 16, 3)
    np.testing.assert_array_equal(restored, np.broadcast_to([0.0, 0.0, -1.0], (12, 16, 3)))


def test_restore_map_scales_a_half_resolution_output() -> None:
    spec = ModelSpec(output="metric_depth", size=(24, 32), multiple_of=16)
    box = plan_letterbox(24, 32, spec)          # padded (32, 32)
    half = np.zeros((1, 1, 16, 16), np.float32)
    half[0, 0, :12] = 5.0                       # 12 of 16 rows are image (24 of 32)
    restored = restore_map(half, box, 1)
    assert restored.shape == (24, 32)
    np.testing.assert_array_equal(restored, 5.0)
    with pytest.raises(InvalidInput):
        restore_map(np.zeros((1, 2, 16, 16)), box, 1)


def test_scaled_intrinsics_maps_pixels_consistently() -> None:
    K = default_intrinsics(640, 480)
    spec = ModelSpec(output="metric_depth", size=(240, 320))
    box = plan_letterbox(480, 640, spec)
    K2 = scaled_intrinsics(K, box)[0].astype(np.float64)
    assert K2.shape == (3, 3)
    # A ray through original pixel (u, v) passes through resized pixel ((u+.5)s - .5, ...).
    u, v = 100.0, 50.0
    ray = np.linalg.inv(K) @ [u, v, 1.0]
    proj = K2 @ ray
    np.testing.assert_allclose(proj[:2] / proj[2], [(u + 0.5) * 0.5 - 0.5, (v + 0.5) * 0.5 - 0.5],
                               atol=1e-4)


def test_depth_from_disparity_is_inverse_up_to_scale() -> None:
    disp = np.array([[1.0, 2.0, 4.0], [0.5, 0.0, -1.0]], np.float32)
    depth = depth_from_disparity(disp, floor=0.01)
    valid = disp > 0
    ratio = depth[valid] * disp[valid]
    np.testing.assert_allclose(ratio, ratio[0], rtol=1e-6)
    assert np.all(depth[~valid] == 0)
    # A floor drops disparities below a fraction of the median (here median = 1).
    assert depth_from_disparity(disp, floor=0.6)[1, 0] == 0
    with pytest.raises(InvalidInput):
        depth_from_disparity(np.zeros((2, 2)))


def test_relative_depth_has_median_one() -> None:
    d = relative_depth_from_depth(np.array([[2.0, 4.0, 6.0], [-1.0, np.nan, 4.0]]))
    assert np.median(d[d > 0]) == pytest.approx(1.0)
    assert d[1, 0] == 0 and d[1, 1] == 0


def test_decode_unsigned_normals_with_axis_convention() -> None:
    K = default_intrinsics(8, 6)
    n_cv = np.array([0.0, -0.6, -0.8])                  # floor-ish, facing the camera
    # The model stores x right, y down, z towards the viewer, as (n + 1) / 2.
    model_n = n_cv * [1, 1, -1]
    raw = np.broadcast_to((model_n + 1) / 2, (6, 8, 3)).astype(np.float32)
    spec = ModelSpec(output="normals", normal_encoding="unsigned", normal_axes="x,y,-z")
    out = decode_normals(raw, spec, K)
    np.testing.assert_allclose(out, np.broadcast_to(n_cv, (6, 8, 3)), atol=1e-6)


def test_decode_flips_normals_that_face_away() -> None:
    K = default_intrinsics(8, 6)
    raw = np.broadcast_to([0.0, 0.0, 1.0], (6, 8, 3)).astype(np.float32)
    out = decode_normals(raw, ModelSpec(output="normals"), K)
    assert np.all(out[..., 2] == -1.0)
    rays = pixel_rays(K, 6, 8)
    tilted = face_camera(np.broadcast_to([0.0, 1.0, 0.0], (6, 8, 3)), K)
    assert np.all(np.sum(tilted * rays, axis=-1) <= 0)


def test_face_camera_matches_the_ray_image_reference() -> None:
    # Reference: dot products with the full (H, W, 3) float32 ray image; random normals and
    # intrinsics with skew.
    rng = np.random.default_rng(0)
    K = default_intrinsics(40, 30)
    K[0, 1] = 3.0
    normals = rng.normal(size=(30, 40, 3)).astype(np.float32)
    rays = pixel_rays(K, 30, 40).astype(np.float32)
    away = np.sum(normals * rays, axis=-1, keepdims=True) > 0
    out = face_camera(normals, K)
    assert out.dtype == np.float32
    np.testing.assert_array_equal(out, np.where(away, -normals, normals))


@pytest.mark.parametrize("axes", ["x,y", "x,x,z", "a,b,c", "x;y;z"])
def test_bad_axes_are_config_errors(axes: str) -> None:
    with pytest.raises(ConfigError):
        parse_axes(axes)


def test_axes_parse() -> None:
    assert parse_axes("x,-y,-z") == ((0, 1.0), (1, -1.0), (2, -1.0))
    assert parse_axes(" -z , x, y") == ((2, -1.0), (0, 1.0), (1, 1.0))


def test_the_old_name_of_face_camera_still_works_with_a_warning() -> None:
    import monoplane.cues
    import monoplane.cues.transforms

    for module in (monoplane.cues, monoplane.cues.transforms):
        with pytest.warns(DeprecationWarning, match="face_camera"):
            assert module.orient_normals is face_camera

