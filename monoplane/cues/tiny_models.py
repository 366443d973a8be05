"""Tiny stand-in ONNX networks with known outputs, for tests of cue providers and plugins.

They have the input/output signatures of real monocular networks but compute closed-form
functions of their input, so a test can run the real loading, pre-processing, onnxruntime
inference and post-processing and still know the exact answer. Building them needs the
``onnx`` package (a development dependency); nothing is downloaded.

Models are saved with opset 17 and IR version 8, which every onnxruntime since 1.14 loads.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _save(nodes: list, inputs: list, output, initializers: list, path: str | Path) -> Path:
    from onnx import helper, save_model

    graph = helper.make_graph(nodes, "monoplane_tiny", inputs, [output], initializer=initializers)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)],
                              producer_name="monoplane-tests")
    model.ir_version = 8
    path = Path(path)
    save_model(model, str(path))
    return path


def _image_input(name: str, size: tuple[int, int] | None, channels: int = 3):
    from onnx import TensorProto, helper

    h, w = size if size is not None else ("height", "width")
    return helper.make_tensor_value_info(name, TensorProto.FLOAT, ["batch", channels, h, w])


def tiny_depth_model(path: str | Path, *, scale: float = 1.0, offset: float = 0.0,
                     image_input: str = "image", output_name: str = "depth",
                     intrinsics_input: str | None = None, fx_coefficient: float = 0.0,
                     size: tuple[int, int] | None = None, channels: int = 3,
                     squeeze_channel: bool = False) -> Path:
    """Save a depth-like network: ``out = scale * mean_c(x) + offset [+ fx_coefficient * fx]``.

    Parameters
    ----------
    path : str or pathlib.Path
        Where to write the ``.onnx`` file.
    scale, offset : float
        Affine map of the channel mean of the (normalised) input.
    image_input, output_name : str
        Tensor names.
    intrinsics_input : str or None
        Add a (N, 3, 3) intrinsics input; its ``fx`` (element [0, 0]) times
        ``fx_coefficient`` is added to the output.
    size : tuple of int or None
        Fixed ``(h, w)`` input size; ``None`` exports dynamic spatial axes.
    channels : int
        Input channels (3 for real images; other values make a mismatching model).
    squeeze_channel : bool
        Output (N, H, W) instead of (N, 1, H, W).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    from onnx import TensorProto, helper, numpy_helper

    inputs = [_image_input(image_input, size, channels)]
    inits = [numpy_helper.from_array(np.array(scale, np.float32), "scale"),
             numpy_helper.from_array(np.array(offset, np.float32), "offset")]
    nodes = [helper.make_node("ReduceMean", [image_input], ["mean"], axes=[1], keepdims=1),
             helper.make_node("Mul", ["mean", "scale"], ["scaled"]),
             helper.make_node("Add", ["scaled", "offset"], ["affine"])]
    last = "affine"
    if intrinsics_input is not None:
        inputs.append(helper.make_tensor_value_info(intrinsics_input, TensorProto.FLOAT,
                                                    ["batch", 3, 3]))
        inits += [numpy_helper.from_array(np.array(0, np.int64), "zero"),
                  numpy_helper.from_array(np.array([-1, 1, 1, 1], np.int64), "shape4"),
                  numpy_helper.from_array(np.array(fx_coefficient, np.float32), "fx_coef")]
        nodes += [helper.make_node("Gather", [intrinsics_input, "zero"], ["row0"], axis=1),
                  helper.make_node("Gather", ["row0", "zero"], ["fx"], axis=1),
                  helper.make_node("Reshape", ["fx", "shape4"], ["fx4"]),
                  helper.make_node("Mul", ["fx4", "fx_coef"], ["fx_term"]),
                  helper.make_node("Add", [last, "fx_term"], ["with_fx"])]
        last = "with_fx"
    if squeeze_channel:
        inits.append(numpy_helper.from_array(np.array([1], np.int64), "axis1"))
        nodes.append(helper.make_node("Squeeze", [last, "axis1"], [output_name]))
        out_shape: list[str | int] = ["batch", "h_out", "w_out"]
    else:
        nodes.append(helper.make_node("Identity", [last], [output_name]))
        out_shape = ["batch", 1, "h_out", "w_out"]
    output = helper.make_tensor_value_info(output_name, TensorProto.FLOAT, out_shape)
    return _save(nodes, inputs, output, inits, path)


def tiny_normals_model(path: str | Path, value: tuple[float, float, float], *,
                       image_input: str = "image", output_name: str = "normals",
                       size: tuple[int, int] | None = None) -> Path:
    """Save a normals network whose output is ``value`` at every pixel, (N, 3, H, W).

    ``value`` is the raw output (already in the network's encoding and axis convention).
    """
    from onnx import TensorProto, helper, numpy_helper

    inits = [numpy_helper.from_array(np.zeros((), np.float32), "zero"),
             numpy_helper.from_array(np.asarray(value, np.float32).reshape(1, 3, 1, 1), "value")]
    nodes = [helper.make_node("Mul", [image_input, "zero"], ["zeros"]),
             helper.make_node("Add", ["zeros", "value"], [output_name])]
    output = helper.make_tensor_value_info(output_name, TensorProto.FLOAT,
                                           ["batch", 3, "h_out", "w_out"])
    return _save(nodes, [_image_input(image_input, size)], output, inits, path)
