"""Cue profiles declared in TOML: every layout, output kind and normal encoding on tiny
networks with closed-form outputs, the config paths that select them, and the errors."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnx")

from monoplane.cues import BUILTIN_PROFILES, CueNetwork  # noqa: E402
from monoplane.cues.profile_files import (  # noqa: E402
    load_profile_file,
    profile_from_table,
    profile_to_toml,
)
from monoplane.cues.tiny_models import (  # noqa: E402
    tiny_depth_model,
    tiny_joint_model,
    tiny_normals_model,
)
from monoplane.datamodel import Frame, default_intrinsics  # noqa: E402
from monoplane.errors import ConfigError, InvalidInput  # noqa: E402
from monoplane.host import config  # noqa: E402
from monoplane.stages.cue_providers import OnnxCues, OnnxCuesConfig  # noqa: E402

H, W = 48, 64


def ramp() -> np.ndarray:
    """(H, W) grey value linear in (u, v), 10..183."""
    u, v = np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))
    return 2 * u + v + 10


def grey(value: np.ndarray) -> np.ndarray:
    return np.repeat(value.astype(np.uint8)[..., None], 3, axis=2)


def exact_input(**keys) -> dict:
    """An input table that feeds the image at its own size (no resampling)."""
    return {"size": [H, W], "multiple_of": 1, "resize": "stretch", **keys}


def run(table: dict, rgb: np.ndarray, model: Path, normal_model: Path | None = None) -> Frame:
    profile = profile_from_table(table, "test profile").profile
    net = CueNetwork(profile, model, normal_model)
    return net.provide(Frame(rgb=rgb, K=default_intrinsics(W, H)))


def unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


@pytest.mark.parametrize("name", sorted(BUILTIN_PROFILES))
def test_builtin_profiles_are_the_same_structure(name: str) -> None:
    text = profile_to_toml(BUILTIN_PROFILES[name])
    assert profile_from_table(tomllib.loads(text), name).profile == BUILTIN_PROFILES[name]


def test_nhwc_input_value_range_and_normalisation(tmp_path: Path) -> None:
    # x = (g * 255 / 255 - 10) / 2 per channel, out = 0.01 * mean_c(x) + 1 (metres).
    model = tiny_depth_model(tmp_path / "nhwc.onnx", layout="NHWC", image_input="input_nhwc",
                             scale=0.01, offset=1.0)
    table = {"model": {"input": exact_input(name="input_nhwc", layout="NHWC",
                                            value_range=[0, 255], mean=[10, 10, 10],
                                            std=[2, 2, 2]),
                       "depth": {"name": "depth", "kind": "metric_depth"}}}
    out = run(table, grey(ramp()), model)
    assert out.depth_kind == "metric" and out.depth_units == "m"
    np.testing.assert_allclose(out.depth, 0.01 * (ramp() - 10) / 2 + 1, rtol=1e-5)


def test_depth_scale_turns_millimetres_into_metres(tmp_path: Path) -> None:
    model = tiny_depth_model(tmp_path / "mm.onnx", scale=0.0, offset=1500.0)
    table = {"model": {"input": exact_input(), "depth": {"kind": "metric_depth",
                                                         "depth_scale": 0.001}}}
    np.testing.assert_allclose(run(table, grey(ramp()), model).depth, 1.5, rtol=1e-6)


@pytest.mark.parametrize(("order", "expected"), [("RGB", 30.0), ("BGR", 200.0)])
def test_colour_order(tmp_path: Path, order: str, expected: float) -> None:
    # The network reads its first channel only: R for RGB, B for BGR networks.
    model = tiny_depth_model(tmp_path / "first.onnx", channel_weights=(1.0, 0.0, 0.0))
    rgb = np.zeros((H, W, 3), np.uint8)
    rgb[...] = (30, 90, 200)
    table = {"model": {"input": exact_input(colour_order=order, value_range=[0, 255]),
                       "depth": {"kind": "metric_depth"}}}
    np.testing.assert_allclose(run(table, rgb, model).depth, expected, rtol=1e-6)


def test_relative_depth_is_divided_by_its_median(tmp_path: Path) -> None:
    model = tiny_depth_model(tmp_path / "rel.onnx", scale=3.0, offset=0.5)
    out = run({"model": {"input": exact_input(), "depth": {"kind": "relative_depth"}}},
              grey(ramp()), model)
    raw = 3.0 * ramp() / 255 + 0.5
    assert out.depth_kind == "relative"
    np.testing.assert_allclose(out.depth, raw / np.median(raw), rtol=1e-5)


def test_inverse_depth_is_inverted(tmp_path: Path) -> None:
    model = tiny_depth_model(tmp_path / "disp.onnx", offset=2.0)
    out = run({"model": {"input": exact_input(), "depth": {"kind": "inverse_depth"}}},
              grey(ramp()), model)
    disparity = ramp() / 255 + 2.0
    np.testing.assert_allclose(out.depth, np.median(disparity) / disparity, rtol=1e-5)


N_CV = unit([0.3, -0.5, -0.8])   # OpenCV camera frame, facing the camera at every pixel


@pytest.mark.parametrize(("encoding", "axes", "raw"), [
    ("signed", "x,y,z", N_CV),                                  # OpenCV itself
    ("unsigned", "x,y,-z", (N_CV * [1, 1, -1] + 1) / 2),        # Omnidata (2D3DS) axes
    ("signed", "x,-y,-z", N_CV * [1, -1, -1]),                  # OpenGL axes
    ("unsigned", "y,x,z", (N_CV[[1, 0, 2]] + 1) / 2),           # channels swapped
])
def test_normals_network_encoding_and_axes(tmp_path: Path, encoding: str, axes: str,
                                           raw: np.ndarray) -> None:
    depth = tiny_depth_model(tmp_path / "d.onnx", scale=0.0, offset=2.0)
    normals = tiny_normals_model(tmp_path / "n.onnx", tuple(raw), output_name="normal")
    table = {"model": {"input": exact_input(), "depth": {"kind": "metric_depth"}},
             "normals_model": {"input": exact_input(),
                               "normals": {"name": "normal", "encoding": encoding,
                                           "axes": axes}}}
    out = run(table, grey(ramp()), depth, normals)
    np.testing.assert_allclose(out.normals, np.broadcast_to(N_CV, out.normals.shape),
                               atol=1e-5)
    assert any("n.onnx" in note for note in out.notes)


def test_one_network_with_depth_and_normals_outputs(tmp_path: Path) -> None:
    raw = (N_CV * [1, -1, -1] + 1) / 2
    model = tiny_joint_model(tmp_path / "joint.onnx", tuple(raw), image_input="img",
                             depth_output="z", normals_output="nrm", scale=0.0, offset=3.0)
    table = {"model": {"input": exact_input(name="img"),
                       "depth": {"name": "z", "kind": "metric_depth"},
                       "normals": {"name": "nrm", "encoding": "unsigned",
                                   "axes": "x,-y,-z"}}}
    profile = profile_from_table(table, "joint").profile
    assert profile.task == "both"
    out = run(table, grey(ramp()), model)
    np.testing.assert_allclose(out.depth, 3.0, rtol=1e-6)
    np.testing.assert_allclose(out.normals, np.broadcast_to(N_CV, out.normals.shape),
                               atol=1e-5)


PROFILE_FILE = """
name = "tiny"
[model]
file = "nets/tiny.onnx"
[model.input]
name = "input_nhwc"
layout = "NHWC"
size = [48, 64]
multiple_of = 1
resize = "stretch"
[model.depth]
name = "depth"
kind = "metric_depth"
"""


def write_profile(tmp_path: Path, text: str = PROFILE_FILE) -> Path:
    (tmp_path / "nets").mkdir(exist_ok=True)
    # Fixed spatial dimensions, as real exports have: a layout mix-up is then detectable.
    tiny_depth_model(tmp_path / "nets" / "tiny.onnx", layout="NHWC", size=(H, W),
                     image_input="input_nhwc", scale=0.0, offset=2.5)
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    return path


def test_profile_file_from_config_alone(tmp_path: Path) -> None:
    path = write_profile(tmp_path)
    resolved = config.load(overrides=["cues.plugin=onnx", f"cues.profile={path}"])
    _, cfg = resolved.stages["cues"]
    stage = OnnxCues(cfg)
    # The model file is relative to the profile file, not to the working directory.
    assert stage.network.depth_path == tmp_path / "nets" / "tiny.onnx"
    out = stage.provide(Frame(rgb=grey(ramp()), K=default_intrinsics(W, H)))
    np.testing.assert_allclose(out.depth, 2.5, rtol=1e-6)
    assert any("tiny network tiny.onnx" in note for note in out.notes)
    # cues.depth_model still overrides the file the profile names.
    other = tiny_depth_model(tmp_path / "other.onnx", layout="NHWC", image_input="input_nhwc",
                             scale=0.0, offset=4.0)
    cfg = OnnxCuesConfig(profile=str(path), depth_model=str(other))
    assert OnnxCues(cfg).network.depth_path == other


def test_cues_option_takes_a_profile_file(tmp_path: Path) -> None:
    from monoplane.host.config import cue_model_overrides

    path = write_profile(tmp_path)
    assert cue_model_overrides(str(path)) == {"cues": {"profile": str(path)}}
    assert cue_model_overrides("depth-anything-v2-small") == {
        "cues": {"model": "depth-anything-v2-small"}}


def test_inline_custom_profile(tmp_path: Path) -> None:
    model = tiny_depth_model(tmp_path / "m.onnx", scale=0.0, offset=1.25)
    resolved = config.load(overrides=[
        "cues.plugin=onnx", "cues.profile=custom",
        f'cues.custom={{model = {{file = "{model}", input = {{size = [48, 64], '
        f'resize = "stretch", multiple_of = 1}}, depth = {{kind = "metric_depth"}}}}}}'])
    out = OnnxCues(resolved.stages["cues"][1]).provide(
        Frame(rgb=grey(ramp()), K=default_intrinsics(W, H)))
    np.testing.assert_allclose(out.depth, 1.25, rtol=1e-6)
    with pytest.raises(ConfigError, match="set profile = \"custom\""):
        OnnxCuesConfig(profile="midas", custom={"model": {}})
    with pytest.raises(ConfigError, match=r"needs a \[cues.custom\] table"):
        OnnxCuesConfig(profile="custom")


@pytest.mark.parametrize(("edit", "message"), [
    (('layout = "NHWC"', 'layot = "NHWC"'),
     r"tiny\.toml: unknown key 'layot' in model\.input; valid keys: colour_order, "),
    (('kind = "metric_depth"', 'kind = "depth"'),
     r"tiny\.toml.*model\.depth\.kind must be one of metric_depth, relative_depth, "
     r"inverse_depth, point_map"),
    (('layout = "NHWC"', 'layout = "HWC"'), r"layout must be one of NCHW, NHWC"),
    (('size = [48, 64]', 'size = [48]'), r"model\.input\.size needs 2 values"),
    (('[model.depth]\nname = "depth"\nkind = "metric_depth"', ''),
     r"tiny\.toml: model needs a \[model\.depth\] table"),
])
def test_bad_profile_files_are_one_line_config_errors(tmp_path: Path, edit: tuple[str, str],
                                                      message: str) -> None:
    path = write_profile(tmp_path, PROFILE_FILE.replace(*edit))
    with pytest.raises(ConfigError, match=message) as err:
        OnnxCuesConfig(profile=str(path))
    assert "\n" not in str(err.value)


def test_missing_profile_file_and_missing_model_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"cue profile file not found: .*nope\.toml"):
        OnnxCuesConfig(profile=str(tmp_path / "nope.toml"))
    path = tmp_path / "lonely.toml"
    path.write_text(PROFILE_FILE)
    declared = load_profile_file(path)
    with pytest.raises(InvalidInput) as err:
        CueNetwork(declared.profile, declared.depth_model).load()
    msg = str(err.value)
    assert "\n" not in msg and str(tmp_path / "nets" / "tiny.onnx") in msg
    assert "not found" in msg and "(1, H, W, 3) float32 named input_nhwc" in msg
    assert "metric depth output" in msg and "named depth" in msg


@pytest.mark.parametrize(("edit", "what"), [
    (('name = "input_nhwc"', 'name = "image"'), "no input named 'image'"),
    (('layout = "NHWC"', 'layout = "NCHW"'), r"input 'input_nhwc' is not \(N, 3, H, W\) "
                                              r"\(layout NCHW, it looks like layout NHWC\)"),
    (('name = "depth"', 'name = "disparity"'), "no output named 'disparity'"),
])
def test_model_mismatch_lists_what_the_file_has(tmp_path: Path, edit: tuple[str, str],
                                                what: str) -> None:
    path = write_profile(tmp_path, PROFILE_FILE.replace(*edit))
    declared = load_profile_file(path)
    with pytest.raises(InvalidInput) as err:
        CueNetwork(declared.profile, declared.depth_model).load()
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(str(tmp_path / "nets" / "tiny.onnx"))
    assert re.search(what, msg), msg
    assert ("the model has inputs [input_nhwc(batch, 48, 64, 3) float32] and outputs "
            "[depth(batch, 1, 48, 64) float32]") in msg


def test_models_cli_prints_profiles_and_says_how_to_bring_your_own(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    from monoplane.cli import main

    assert main(["models", "profile", "metric3d-v2-small"]) == 0   # a catalogue name
    printed = tomllib.loads(capsys.readouterr().out)
    assert profile_from_table(printed, "out").profile == BUILTIN_PROFILES["metric3d-v2"]
    assert printed["model"]["input"]["value_range"] == [0.0, 255.0]
    path = write_profile(tmp_path)
    assert main(["models", "profile", str(path)]) == 0               # a file, defaults filled
    assert 'colour_order = "RGB"' in capsys.readouterr().out
    monkeypatch.setenv("MONOPLANE_CACHE", str(tmp_path / "cache"))
    assert main(["models", "list"]) == 0
    assert "--set cues.profile=my_model.toml" in capsys.readouterr().out
