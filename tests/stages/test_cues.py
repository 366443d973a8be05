"""Cue providers ``given`` and ``onnx`` (every built-in profile, through onnxruntime)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from monoplane.contracts import param
from monoplane.cues import assume_intrinsics, intrinsics_assumed
from monoplane.datamodel import Frame, default_intrinsics, intrinsics_matrix, pixel_rays
from monoplane.errors import ConfigError, InvalidInput
from monoplane.stages.cue_providers import GivenCues, GivenCuesConfig, OnnxCues, OnnxCuesConfig
from monoplane.testing import check_stage_contract

LIVINGROOM = Path("/work/shared/data/rgbd-livingroom")


def unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def max_angle_deg(normals: np.ndarray, n: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(normals.reshape(-1, 3) @ n, -1, 1))).max())


def ramp_image(h: int = 48, w: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """A grey image whose value is linear in (u, v); returns it and the value as float."""
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    value = 2 * u + v + 10
    return np.repeat(value.astype(np.uint8)[..., None], 3, axis=2), value


def plane_frame(h: int = 48, w: int = 64) -> tuple[Frame, np.ndarray]:
    K = default_intrinsics(w, h)
    n = unit([0.2, -0.5, -0.8])
    depth = (-2.0 / (pixel_rays(K, h, w) @ n)).astype(np.float32)
    rgb = np.full((h, w, 3), 128, np.uint8)
    return Frame(rgb=rgb, K=K, depth=depth), n


# --- given -----------------------------------------------------------------------------------

def test_given_estimates_missing_normals() -> None:
    frame, n = plane_frame()
    depth = frame.depth.copy()
    depth[5:9, 5:9] = 0
    out = GivenCues().provide(frame.with_(depth=depth))
    assert out.normals is not None and out.depth is not None
    assert np.all(out.normals[5:9, 5:9] == 0)
    assert max_angle_deg(out.normals[depth > 0], n) < 0.5
    assert any("estimated from depth" in note for note in out.notes)


def test_given_keeps_normals_but_orients_them() -> None:
    frame, n = plane_frame()
    given = np.broadcast_to(-n, frame.depth.shape + (3,)).astype(np.float32)  # facing away
    out = GivenCues().provide(frame.with_(normals=given))
    np.testing.assert_allclose(out.normals, np.broadcast_to(n, given.shape), atol=1e-6)
    assert any("flipped" in note for note in out.notes)
    recomputed = GivenCues(GivenCuesConfig(recompute_normals=True)).provide(
        frame.with_(normals=given))
    assert max_angle_deg(recomputed.normals, n) < 0.5


def noisy_plane_frame(kind: str) -> Frame:
    """:func:`plane_frame` with 1 % depth noise, so the box and gated fits differ."""
    frame, _ = plane_frame()
    noise = np.random.default_rng(3).normal(1.0, 0.01, frame.depth.shape)
    return frame.with_(depth=(frame.depth * noise).astype(np.float32), depth_kind=kind)


@pytest.mark.parametrize(("kind", "method"), [("metric", "box"), ("relative", "gated")])
def test_network_cues_without_normals_options_resolve_auto(kind: str, method: str) -> None:
    # A CueNetwork built without normals_options (the depth-anything plugin's, a third-party
    # provider's) follows the same "auto" as the built-in providers: box normals on a
    # sensor's metric depth, gated ones on a relative depth.
    from monoplane.cues import CueNetwork
    from monoplane.cues.profile_files import get_profile
    from monoplane.geometry.normals import normals_from_depth

    frame = noisy_plane_frame(kind)
    out = CueNetwork(get_profile("midas")).provide(frame)
    other = "gated" if method == "box" else "box"
    expected = normals_from_depth(frame.depth, frame.K, method=method)
    np.testing.assert_array_equal(out.normals, expected)
    assert not np.array_equal(expected, normals_from_depth(frame.depth, frame.K, method=other))
    assert out.notes[-1].endswith(f"fits, {method})")
    given = GivenCues().provide(frame)
    np.testing.assert_array_equal(given.normals, out.normals)
    assert given.notes[-1] == out.notes[-1]


def test_given_without_depth_is_a_clear_error() -> None:
    frame, _ = plane_frame()
    with pytest.raises(InvalidInput, match="needs a depth map"):
        GivenCues().provide(frame.with_(depth=None))


def test_given_config_is_validated() -> None:
    with pytest.raises(ConfigError):
        GivenCuesConfig(normals_radius=2, normals_stride=3)
    with pytest.raises(ConfigError):
        GivenCuesConfig(normals_radius=-1)
    with pytest.raises(ConfigError, match="gated, box"):
        GivenCuesConfig(normals_method="integral")


def test_given_on_real_rgbd_frame() -> None:
    from monoplane.io.frames import load_frame

    image = LIVINGROOM / "color_00000.jpg"
    if not image.is_file():
        pytest.skip(f"{image} not available")
    # README: 640x480, depth in millimetres, fx = fy = 525, cx = 319.5, cy = 239.5.
    frame = load_frame(image, depth=LIVINGROOM / "depth_00000.png", depth_scale=1000.0,
                       intrinsics="525,525,319.5,239.5")
    out = GivenCues().provide(frame)
    valid = out.depth > 0
    has_normal = np.any(out.normals != 0, axis=-1)
    assert 0.8 < valid.mean() < 0.95                 # the README's ~13 % holes
    assert not np.any(has_normal & ~valid)
    assert has_normal.sum() > 0.99 * valid.sum()
    assert out.normals[450, 320, 1] < -0.95          # floor faces up
    rays = pixel_rays(out.K, *out.shape)
    assert np.all(np.sum(out.normals * rays, axis=-1) <= 1e-6)


# --- onnx ------------------------------------------------------------------------------------

onnx = pytest.importorskip("onnx")
from monoplane.cues.tiny_models import tiny_depth_model, tiny_normals_model  # noqa: E402


def test_unknown_profile_is_config_error() -> None:
    with pytest.raises(ConfigError, match="valid profiles: depth-anything-v2, metric3d-v2, midas"):
        OnnxCuesConfig(profile="dpt-large")


@pytest.mark.parametrize("kwargs", [{"threads": 0}, {"input_size": [384]}, {"mean": [0.5]},
                                    {"normal_axes": "x,y"}, {"hfov_deg": 190.0}])
def test_onnx_config_is_validated(kwargs: dict) -> None:
    with pytest.raises(ConfigError):
        OnnxCuesConfig(**kwargs)


def test_midas_profile_planar_disparity_gives_a_plane(tmp_path: Path) -> None:
    # Network output = channel mean of the normalised image + 2 = 2 * value / 255 + 1: a
    # disparity linear in (u, v), which is exactly the inverse depth of a plane.
    model = tiny_depth_model(tmp_path / "midas.onnx", offset=2.0)
    rgb, value = ramp_image()
    K = default_intrinsics(64, 48)
    stage = OnnxCues(OnnxCuesConfig(profile="midas", depth_model=str(model),
                                    input_size=[48, 64]))
    out = stage.provide(Frame(rgb=rgb, K=K))
    disparity = 2 * value / 255 + 1
    assert out.depth_kind == "relative" and out.depth_units == "relative"
    product = out.depth * disparity                  # depth = median(disp) / disp
    np.testing.assert_allclose(product, np.median(disparity), rtol=1e-5)
    g = np.array([4 / 255, 2 / 255, 20 / 255 + 1])   # disparity = g . [u, v, 1]
    n = unit(-K.T @ g)
    assert max_angle_deg(out.normals, n) < 0.5
    assert any("shift assumed zero" in note for note in out.notes)


def test_midas_profile_with_resizing(tmp_path: Path) -> None:
    model = tiny_depth_model(tmp_path / "midas.onnx", offset=2.0)
    rgb, value = ramp_image()
    stage = OnnxCues(OnnxCuesConfig(profile="midas", depth_model=str(model)))  # 384 box
    out = stage.provide(Frame(rgb=rgb, K=default_intrinsics(64, 48)))
    disparity = 2 * value / 255 + 1
    product = (out.depth * disparity)[2:-2, 2:-2]    # resampling is exact away from borders
    np.testing.assert_allclose(product, np.median(disparity), rtol=2e-3)


def test_omnidata_profile_two_models(tmp_path: Path) -> None:
    depth_model = tiny_depth_model(tmp_path / "omni_depth.onnx", scale=0.0, offset=0.4)
    n_cv = unit([0.0, -0.6, -0.8])
    raw = (n_cv * [1, 1, -1] + 1) / 2                # 2D3DS axes, (n + 1) / 2 encoding
    normal_model = tiny_normals_model(tmp_path / "omni_normal.onnx", tuple(raw))
    stage = OnnxCues(OnnxCuesConfig(profile="omnidata", depth_model=str(depth_model),
                                    normal_model=str(normal_model)))
    rgb, _ = ramp_image()
    out = stage.provide(Frame(rgb=rgb, K=default_intrinsics(64, 48)))
    np.testing.assert_allclose(out.depth, 1.0, rtol=1e-5)    # relative depth, median 1
    assert out.depth_kind == "relative"
    np.testing.assert_allclose(out.normals, np.broadcast_to(n_cv, out.normals.shape),
                               atol=1e-5)
    assert any("omni_normal.onnx" in note for note in out.notes)


def test_zerodepth_profile_metric_depth_uses_intrinsics(tmp_path: Path) -> None:
    model = tiny_depth_model(tmp_path / "zerodepth.onnx", scale=0.0, image_input="rgb",
                             intrinsics_input="intrinsics", fx_coefficient=0.001)
    K = intrinsics_matrix(500.0, 500.0, 31.5, 23.5)
    stage = OnnxCues(OnnxCuesConfig(profile="zerodepth", depth_model=str(model),
                                    input_size=[48, 64]))
    rgb, _ = ramp_image()
    out = stage.provide(Frame(rgb=rgb, K=K))
    assert out.depth_kind == "metric" and out.depth_units == "m"
    # Metric, but a network's: registration takes it as an estimate (Frame.depth_predicted).
    assert out.depth_predicted
    np.testing.assert_allclose(out.depth, 0.5, rtol=1e-5)   # 0.001 * fx at input resolution
    # A fronto-parallel constant depth: normals from depth face straight at the camera.
    assert max_angle_deg(out.normals, np.array([0.0, 0.0, -1.0])) < 0.5


def test_given_cues_are_kept_and_no_model_is_needed() -> None:
    frame, n = plane_frame()
    out = OnnxCues(OnnxCuesConfig(profile="midas")).provide(frame)
    np.testing.assert_array_equal(out.depth, frame.depth)
    assert not out.depth_predicted  # a sensor's depth stays a measurement
    assert max_angle_deg(out.normals, n) < 0.5


def test_missing_model_path_and_file_are_clear(tmp_path: Path) -> None:
    rgb, _ = ramp_image()
    frame = Frame(rgb=rgb, K=default_intrinsics(64, 48))
    with pytest.raises(InvalidInput, match="needs a depth model file"):
        OnnxCues(OnnxCuesConfig(profile="midas")).provide(frame)
    missing = tmp_path / "nowhere.onnx"
    with pytest.raises(InvalidInput, match="nowhere.onnx"):
        OnnxCues(OnnxCuesConfig(profile="midas", depth_model=str(missing))).provide(frame)


def test_assumed_intrinsics_can_be_replaced_and_are_noted(tmp_path: Path) -> None:
    model = tiny_depth_model(tmp_path / "m.onnx", offset=2.0)
    rgb, _ = ramp_image()
    K, note = assume_intrinsics(64, 48)
    frame = Frame(rgb=rgb, K=K, notes=[note])
    assert intrinsics_assumed(frame)
    out = OnnxCues(OnnxCuesConfig(profile="midas", depth_model=str(model),
                                  hfov_deg=90.0)).provide(frame)
    assert out.K[0, 0] == pytest.approx(32.0)               # 64 px over 90 degrees
    assert sum("intrinsics not given" in s for s in out.notes) == 1
    assert any("90° horizontal field of view (cues.hfov_deg)" in s for s in out.notes)
    # Given intrinsics are never replaced.
    given = Frame(rgb=rgb, K=intrinsics_matrix(70, 70, 31.5, 23.5))
    out = OnnxCues(OnnxCuesConfig(profile="midas", depth_model=str(model),
                                  hfov_deg=90.0)).provide(given)
    assert out.K[0, 0] == 70


def test_contract(tmp_path: Path) -> None:
    from monoplane.synth import generate

    view = generate(0, level="mild", width=128, height=96).views[0]
    model = tiny_depth_model(tmp_path / "m.onnx", offset=2.0)

    config = dataclasses.make_dataclass(
        "TinyMidasConfig", [("profile", str, param("midas", "profile")),
                            ("depth_model", str, param(str(model), "tiny model"))],
        bases=(OnnxCuesConfig,))
    tiny = type("TinyMidas", (OnnxCues,), {"Config": config})
    check_stage_contract(tiny, view.frame)
    check_stage_contract(GivenCues)


def test_profile_is_chosen_by_config_overrides() -> None:
    from monoplane.host import config

    preset = sorted(config.list_presets())[0]
    resolved = config.load(preset=preset, config={"cues": {"plugin": "onnx"}},
                           overrides=["cues.profile=zerodepth", "cues.input_size=[240, 320]",
                                      "cues.threads=1"])
    name, cfg = resolved.stages["cues"]
    assert name == "onnx" and cfg.profile == "zerodepth" and cfg.threads == 1
    assert cfg.resolved_profile().depth.size == (240, 320)
    with pytest.raises(ConfigError, match="valid profiles"):
        config.load(preset=preset, config={"cues": {"plugin": "onnx"}},
                    overrides=["cues.profile=nope"])
