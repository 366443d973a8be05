"""The Depth Anything cue provider registers with monoplane and runs a tiny ONNX stand-in."""

from __future__ import annotations

import dataclasses
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnx", reason="building the tiny test model needs the onnx package")

from monoplane_depth_anything import stages  # noqa: E402
from monoplane_depth_anything.stages import (  # noqa: E402
    PROFILE,
    DepthAnythingConfig,
    DepthAnythingCues,
)

from monoplane.plugin import (  # noqa: E402
    ConfigError,
    Frame,
    InvalidInput,
    default_intrinsics,
    get_plugin_manager,
    get_registry,
    param,
    plan_letterbox,
)
from monoplane.testing import check_stage_contract, tiny_depth_model  # noqa: E402


def ramp_frame(h: int = 50, w: int = 70) -> tuple[Frame, np.ndarray]:
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    value = u + 2 * v + 20
    rgb = np.repeat(value.astype(np.uint8)[..., None], 3, axis=2)
    return Frame(rgb=rgb, K=default_intrinsics(w, h)), value


def test_registers_through_the_hook() -> None:
    registry = get_registry(get_plugin_manager(autoload=False, extra_plugins=(stages,)))
    assert "depth-anything" in registry.names("cues")
    assert registry.get("cues", "depth-anything").cls is DepthAnythingCues


def test_entry_point_is_declared() -> None:
    try:
        eps = metadata.entry_points(group="monoplane")
    except metadata.PackageNotFoundError:
        pytest.skip("package not installed")
    names = {ep.name: ep.value for ep in eps}
    if "depth_anything" not in names:
        pytest.skip("monoplane-depth-anything is not installed (pip install -e .)")
    assert names["depth_anything"] == "monoplane_depth_anything.stages"


def test_inputs_are_padded_to_multiples_of_14() -> None:
    box = plan_letterbox(480, 640, PROFILE.depth)
    assert box.resized == (388, 518)
    assert box.padded[0] % 14 == 0 and box.padded[1] % 14 == 0


def test_relative_depth_and_normals_from_a_tiny_model(tmp_path: Path) -> None:
    # The stand-in returns the channel mean of the ImageNet-normalised input plus 5: a
    # positive disparity that is an affine function of the grey value.
    model = tiny_depth_model(tmp_path / "depth_anything.onnx", offset=5.0)
    frame, value = ramp_frame()
    out = DepthAnythingCues(DepthAnythingConfig(model=str(model), input_size=70)).provide(frame)
    mean, std = np.asarray(PROFILE.depth.mean), np.asarray(PROFILE.depth.std)
    disparity = np.mean((value[..., None] / 255 - mean) / std, axis=-1) + 5
    assert out.depth_kind == "relative"
    np.testing.assert_allclose(out.depth * disparity, np.median(disparity), rtol=1e-4)
    # Linear disparity means a plane: all normals agree and face the camera.
    n = out.normals.reshape(-1, 3)
    assert np.all(n @ n[0] > np.cos(np.deg2rad(0.5)))
    assert n[0, 2] < 0


@pytest.mark.parametrize(("kind", "method"), [("metric", "box"), ("relative", "gated")])
def test_given_depth_gets_the_default_normals_fit(kind: str, method: str) -> None:
    # No model runs on a frame with depth; the normals come from that depth with the default
    # "auto" fit: box on a sensor's metric depth, gated on a relative one.
    frame, value = ramp_frame()
    noise = np.random.default_rng(5).normal(1.0, 0.01, value.shape)
    frame = frame.with_(depth=(100.0 / value * noise).astype(np.float32), depth_kind=kind)
    out = DepthAnythingCues(DepthAnythingConfig()).provide(frame)
    assert out.notes[-1].endswith(f"fits, {method})")
    given = get_registry(get_plugin_manager(autoload=False)).get("cues", "given").cls()
    np.testing.assert_array_equal(out.normals, given.provide(frame).normals)


def test_missing_model_is_a_clear_error(tmp_path: Path) -> None:
    frame, _ = ramp_frame()
    with pytest.raises(InvalidInput, match=r"needs a depth model file \(cues.model ="):
        DepthAnythingCues().provide(frame)
    with pytest.raises(InvalidInput, match="not found: .*gone.onnx"):
        DepthAnythingCues(DepthAnythingConfig(model=str(tmp_path / "gone.onnx"))).provide(frame)


def test_config_is_validated() -> None:
    with pytest.raises(ConfigError):
        DepthAnythingConfig(input_size=7)


def test_stage_contract(tmp_path: Path) -> None:
    model = tiny_depth_model(tmp_path / "m.onnx", offset=5.0)
    config = dataclasses.make_dataclass(
        "TinyConfig", [("model", str, param(str(model), "tiny stand-in model")),
                       ("input_size", int, param(98, "small input"))],
        bases=(DepthAnythingConfig,))
    stage = type("TinyDepthAnything", (DepthAnythingCues,), {"Config": config})
    frame, _ = ramp_frame()
    check_stage_contract(stage, frame.with_(depth=None))
