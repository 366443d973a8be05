"""Focal length and shift from affine point maps; joint-output networks through onnxruntime."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.cues import ModelSpec, OnnxModel
from monoplane.cues.pointmap import (
    centred_plane_coords,
    depth_from_point_map,
    focal_to_pixels,
    recover_focal_shift,
)
from monoplane.datamodel import default_intrinsics, pixel_rays
from monoplane.errors import InvalidInput


def corner_points(hfov: float, h: int = 60, w: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame points of a floor and a wall (exact), and K."""
    K = default_intrinsics(w, h, hfov)
    rays = pixel_rays(K, h, w)
    z = np.full((h, w), np.inf)
    for n, d in (([0, -1, 0], 1.2), ([0.5, 0, -0.85], 3.0)):
        zi = -d / (rays @ np.asarray(n, float))
        z = np.minimum(z, np.where(zi > 0, zi, np.inf))
    return rays * z[..., None], K


def test_centred_coordinates_span_the_half_diagonal() -> None:
    uv = centred_plane_coords(3, 4)
    assert uv[1, 0] == pytest.approx([-1.5 / 2.5, 0.0])
    assert uv[2, 3] == pytest.approx([1.5 / 2.5, 1 / 2.5])


@pytest.mark.parametrize("hfov", [40.0, 60.0, 90.0])
@pytest.mark.parametrize("shift", [-0.7, 0.0, 1.3])
def test_focal_and_shift_are_recovered_exactly(hfov: float, shift: float) -> None:
    points, K = corner_points(hfov)
    affine = points.copy()
    affine[..., 2] -= shift
    valid = np.ones(points.shape[:2], bool)
    f, s = recover_focal_shift(affine, valid)
    assert s == pytest.approx(shift, abs=1e-4)
    assert focal_to_pixels(f, *points.shape[:2]) == pytest.approx(K[0, 0], rel=1e-4)
    f_known, s_known = recover_focal_shift(affine, valid, focal=f)
    assert f_known == f and s_known == pytest.approx(shift, abs=1e-4)


def test_depth_from_point_map_applies_shift_scale_and_mask() -> None:
    points, _ = corner_points(55.0)
    affine = points / 2.0
    affine[..., 2] -= 0.4
    mask = np.full(points.shape[:2], 0.9)
    mask[:5] = 0.1
    depth, _ = depth_from_point_map(affine, mask, 2.0)
    assert np.all(depth[:5] == 0)
    assert depth[5:] == pytest.approx(points[5:, :, 2], rel=1e-4)
    with pytest.raises(InvalidInput, match="valid"):
        depth_from_point_map(affine, np.zeros_like(mask), 2.0)


def _joint_model(path, normal_channels: int, with_tokens: bool = True):
    from onnx import TensorProto, helper, numpy_helper, save_model

    inits = [numpy_helper.from_array(np.zeros((), np.float32), "zero"),
             numpy_helper.from_array(np.array([0.0, 0.0, -1.0, 0.5][:normal_channels],
                                              np.float32).reshape(1, -1, 1, 1), "n")]
    nodes = [helper.make_node("ReduceMean", ["image"], ["depth"], axes=[1], keepdims=1),
             helper.make_node("ReduceMean", ["image"], ["m"], axes=[1], keepdims=1),
             helper.make_node("Mul", ["m", "zero"], ["z"]),
             helper.make_node("Add", ["z", "n"], ["normals"])]
    inputs = [helper.make_tensor_value_info("image", TensorProto.FLOAT, ["b", 3, "h", "w"])]
    if with_tokens:
        inputs.append(helper.make_tensor_value_info("num_tokens", TensorProto.INT64, []))
        nodes.append(helper.make_node("Identity", ["num_tokens"], ["tokens_out"]))
    outputs = [helper.make_tensor_value_info("depth", TensorProto.FLOAT, ["b", 1, "h", "w"]),
               helper.make_tensor_value_info("normals", TensorProto.FLOAT,
                                             ["b", normal_channels, "h", "w"])]
    if with_tokens:
        outputs.append(helper.make_tensor_value_info("tokens_out", TensorProto.INT64, []))
    graph = helper.make_graph(nodes, "joint", inputs, outputs, initializer=inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    save_model(model, str(path))
    return path


def test_joint_outputs_come_from_one_run_and_confidence_is_dropped(tmp_path) -> None:
    pytest.importorskip("onnx")
    spec = ModelSpec(output="metric_depth", output_name="depth", normals_output="normals",
                     constant_inputs=(("num_tokens", 1800),))
    model = OnnxModel(_joint_model(tmp_path / "j.onnx", 4), spec)
    out = model.run(np.full((20, 30, 3), 128, np.uint8), default_intrinsics(30, 20))
    assert out["depth"].shape == (20, 30)
    assert out["normals"].shape == (20, 30, 3)
    assert out["normals"][0, 0] == pytest.approx([0, 0, -1])
    with pytest.raises(InvalidInput, match="no input named 'num_tokens'"):
        OnnxModel(_joint_model(tmp_path / "n.onnx", 3, with_tokens=False), spec)
    with pytest.raises(InvalidInput, match="no output named 'normal'"):
        OnnxModel(tmp_path / "j.onnx", ModelSpec(output="metric_depth", output_name="depth",
                                                 normals_output="normal",
                                                 constant_inputs=(("num_tokens", 1),)))
