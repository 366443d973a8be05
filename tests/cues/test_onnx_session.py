"""Loading tiny ONNX networks through onnxruntime: signatures, clear errors, real inference."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnx")

from monoplane.cues import ModelSpec, OnnxModel, get_profile  # noqa: E402
from monoplane.cues.tiny_models import tiny_depth_model, tiny_normals_model  # noqa: E402
from monoplane.datamodel import default_intrinsics  # noqa: E402
from monoplane.errors import InvalidInput  # noqa: E402


def grey(h: int, w: int, value: int) -> np.ndarray:
    return np.full((h, w, 3), value, np.uint8)


def test_missing_file_names_file_and_expectation(tmp_path: Path) -> None:
    path = tmp_path / "nope.onnx"
    with pytest.raises(InvalidInput) as err:
        OnnxModel(path, get_profile("midas").depth, label="midas depth model")
    msg = str(err.value)
    assert "\n" not in msg and str(path) in msg and "not found" in msg
    assert "inverse depth" in msg


def test_corrupt_file_is_one_line_error(tmp_path: Path) -> None:
    path = tmp_path / "broken.onnx"
    path.write_bytes(b"\x08\x07 definitely not a protobuf model \xff\xfe")
    with pytest.raises(InvalidInput) as err:
        OnnxModel(path, get_profile("midas").depth)
    msg = str(err.value)
    assert "\n" not in msg and str(path) in msg and "cannot load" in msg


def test_wrong_channel_count_is_reported(tmp_path: Path) -> None:
    path = tiny_depth_model(tmp_path / "gray.onnx", channels=1)
    with pytest.raises(InvalidInput, match=r"gray\.onnx.*not \(N, 3, H, W\).*image\(batch, 1"):
        OnnxModel(path, get_profile("midas").depth)


def test_normals_model_where_depth_is_expected(tmp_path: Path) -> None:
    path = tiny_normals_model(tmp_path / "normals.onnx", (0.0, 0.0, -1.0))
    with pytest.raises(InvalidInput, match="does not match its profile.*output 'normals'"):
        OnnxModel(path, get_profile("midas").depth)


def test_missing_intrinsics_input(tmp_path: Path) -> None:
    path = tiny_depth_model(tmp_path / "plain.onnx", image_input="rgb")
    with pytest.raises(InvalidInput, match="no input named 'intrinsics'"):
        OnnxModel(path, get_profile("zerodepth").depth)


def test_extra_input_is_reported(tmp_path: Path) -> None:
    path = tiny_depth_model(tmp_path / "two.onnx", intrinsics_input="K")
    with pytest.raises(InvalidInput, match="2 candidate image inputs"):
        OnnxModel(path, get_profile("midas").depth)


def test_depth_model_runs_on_a_non_aligned_image(tmp_path: Path) -> None:
    path = tiny_depth_model(tmp_path / "d.onnx", scale=1.0, offset=3.0)
    spec = ModelSpec(output="inverse_depth", size=(40, 40), multiple_of=14)
    model = OnnxModel(path, spec, threads=1)
    out = model.predict(grey(30, 50, 255), default_intrinsics(50, 30))
    assert out.shape == (30, 50) and out.dtype == np.float32
    # mean of the normalised white image is (1 - .5) / .5 = 1, plus 3.
    np.testing.assert_allclose(out, 4.0, rtol=1e-6)


def test_fixed_size_model_gets_exactly_its_size(tmp_path: Path) -> None:
    path = tiny_depth_model(tmp_path / "fixed.onnx", size=(64, 64), squeeze_channel=True)
    model = OnnxModel(path, get_profile("midas").depth)
    assert model.fixed_size == (64, 64)
    out = model.predict(grey(48, 80, 0), default_intrinsics(80, 48))
    assert out.shape == (48, 80)
    np.testing.assert_allclose(out, -1.0)


def test_intrinsics_reach_camera_aware_models_rescaled(tmp_path: Path) -> None:
    path = tiny_depth_model(tmp_path / "zd.onnx", scale=0.0, image_input="rgb",
                            intrinsics_input="intrinsics", fx_coefficient=0.01)
    spec = get_profile("zerodepth").depth             # box (480, 640)
    model = OnnxModel(path, spec)
    K = default_intrinsics(320, 240)                  # fx = 277.1; resized x2 -> 554.3
    out = model.predict(grey(240, 320, 10), K)
    np.testing.assert_allclose(out, 0.01 * 2 * K[0, 0], rtol=1e-5)
