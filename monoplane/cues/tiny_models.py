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

    outputs = output if isinstance(output, list) else [output]
    graph = helper.make_graph(nodes, "monoplane_tiny", inputs, outputs, initializer=initializers)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)],
                              producer_name="monoplane-tests")
    model.ir_version = 8
    path = Path(path)
    save_model(model, str(path))
    return path


def _image_input(name: str, size: tuple[int, int] | None, channels: int = 3,
                 layout: str = "NCHW"):
    from onnx import TensorProto, helper

    h, w = size if size is not None else ("height", "width")
    dims = ["batch", channels, h, w] if layout == "NCHW" else ["batch", h, w, channels]
    return helper.make_tensor_value_info(name, TensorProto.FLOAT, dims)


def tiny_depth_model(path: str | Path, *, scale: float = 1.0, offset: float = 0.0,
                     image_input: str = "image", output_name: str = "depth",
                     intrinsics_input: str | None = None, fx_coefficient: float = 0.0,
                     size: tuple[int, int] | None = None, channels: int = 3,
                     squeeze_channel: bool = False, layout: str = "NCHW",
                     channel_weights: tuple[float, float, float] | None = None) -> Path:
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
    layout : str
        ``"NCHW"`` or ``"NHWC"`` (channels last) input; the output is (N, 1, H, W) either way.
    channel_weights : tuple of float or None
        Replace the channel mean by ``sum_c w_c x_c`` (input channel order), so a test can tell
        the channels apart (colour order).

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    from onnx import TensorProto, helper, numpy_helper

    inputs = [_image_input(image_input, size, channels, layout)]
    inits = [numpy_helper.from_array(np.array(scale, np.float32), "scale"),
             numpy_helper.from_array(np.array(offset, np.float32), "offset")]
    axis = 1 if layout == "NCHW" else 3
    if channel_weights is None:
        nodes = [helper.make_node("ReduceMean", [image_input], ["reduced"], axes=[axis],
                                  keepdims=1)]
    else:
        shape = (1, 3, 1, 1) if layout == "NCHW" else (1, 1, 1, 3)
        inits += [numpy_helper.from_array(np.asarray(channel_weights, np.float32).reshape(shape),
                                          "weights"),
                  numpy_helper.from_array(np.array([axis], np.int64), "channel_axis")]
        nodes = [helper.make_node("Mul", [image_input, "weights"], ["weighted"]),
                 helper.make_node("ReduceSum", ["weighted", "channel_axis"], ["reduced"],
                                  keepdims=1)]
    if layout == "NCHW":
        nodes.append(helper.make_node("Identity", ["reduced"], ["mean"]))
    else:
        nodes.append(helper.make_node("Transpose", ["reduced"], ["mean"], perm=[0, 3, 1, 2]))
    nodes += [helper.make_node("Mul", ["mean", "scale"], ["scaled"]),
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


def tiny_joint_model(path: str | Path, normal_value: tuple[float, float, float], *,
                     image_input: str = "pixel_values", depth_output: str = "predicted_depth",
                     normals_output: str = "predicted_normal", scale: float = 1.0,
                     offset: float = 0.0, reciprocal: bool = False) -> Path:
    """Save a joint depth-and-normals network (Metric3D v2 signature).

    Outputs ``depth_output`` (N, H, W) = ``scale * mean_c(x) + offset``, or its reciprocal, and
    ``normals_output`` (N, 3, H, W) = ``normal_value`` at every pixel.

    Parameters
    ----------
    path : str or pathlib.Path
        Where to write the ``.onnx`` file.
    normal_value : tuple of float
        The raw normal output (network encoding and axes).
    reciprocal : bool
        Output ``1 / (scale * mean + offset)``: a depth whose inverse is affine in the input, so
        an input whose value is affine in pixel coordinates gives an exact plane.
    """
    from onnx import TensorProto, helper, numpy_helper

    inits = [numpy_helper.from_array(np.array(scale, np.float32), "scale"),
             numpy_helper.from_array(np.array(offset, np.float32), "offset"),
             numpy_helper.from_array(np.array([1], np.int64), "axis1"),
             numpy_helper.from_array(np.zeros((), np.float32), "zero"),
             numpy_helper.from_array(np.asarray(normal_value, np.float32).reshape(1, 3, 1, 1),
                                     "value")]
    nodes = [helper.make_node("ReduceMean", [image_input], ["mean"], axes=[1], keepdims=1),
             helper.make_node("Mul", ["mean", "scale"], ["scaled"]),
             helper.make_node("Add", ["scaled", "offset"], ["affine"])]
    last = "affine"
    if reciprocal:
        nodes.append(helper.make_node("Reciprocal", ["affine"], ["inverse"]))
        last = "inverse"
    nodes += [helper.make_node("Squeeze", [last, "axis1"], [depth_output]),
              helper.make_node("Mul", [image_input, "zero"], ["zeros"]),
              helper.make_node("Add", ["zeros", "value"], [normals_output])]
    outputs = [helper.make_tensor_value_info(depth_output, TensorProto.FLOAT,
                                             ["batch", "h_out", "w_out"]),
               helper.make_tensor_value_info(normals_output, TensorProto.FLOAT,
                                             ["batch", 3, "h_out", "w_out"])]
    return _save(nodes, [_image_input(image_input, None)], outputs, inits, path)


def tiny_point_map_model(path: str | Path, low: tuple[float, float, float],
                         high: tuple[float, float, float],
                         normal_value: tuple[float, float, float], *,
                         metric_scale: float = 1.0, mask_value: float = 0.9) -> Path:
    """Save a point-map network with MoGe-2's ONNX signature.

    Inputs ``image`` (N, 3, H, W) in [0, 1] and ``num_tokens`` (int64 scalar); outputs
    ``points`` (N, H, W, 3) = ``low + image * (high - low)`` per channel (so a test encodes a
    known point map in an RGB image), ``normal`` (N, H, W, 3) = ``normal_value``, ``mask``
    (N, H, W) = ``mask_value`` and ``metric_scale`` (N,) = ``metric_scale``.
    """
    from onnx import TensorProto, helper, numpy_helper

    lo = np.asarray(low, np.float32).reshape(1, 3, 1, 1)
    span = (np.asarray(high, np.float32) - np.asarray(low, np.float32)).reshape(1, 3, 1, 1)
    inits = [numpy_helper.from_array(lo, "low"), numpy_helper.from_array(span, "span"),
             numpy_helper.from_array(np.zeros((), np.float32), "zero"),
             numpy_helper.from_array(np.asarray(normal_value, np.float32), "normal_value"),
             numpy_helper.from_array(np.array(mask_value, np.float32), "mask_value"),
             numpy_helper.from_array(np.array(metric_scale, np.float32), "scale_value")]
    nodes = [helper.make_node("Mul", ["image", "span"], ["spanned"]),
             helper.make_node("Add", ["spanned", "low"], ["points_nchw"]),
             helper.make_node("Transpose", ["points_nchw"], ["points"], perm=[0, 2, 3, 1]),
             helper.make_node("Mul", ["points", "zero"], ["zeros_nhwc"]),
             helper.make_node("Add", ["zeros_nhwc", "normal_value"], ["normal"]),
             helper.make_node("ReduceMean", ["zeros_nhwc"], ["zeros_nhw"], axes=[3],
                              keepdims=0),
             helper.make_node("Add", ["zeros_nhw", "mask_value"], ["mask"]),
             # num_tokens only steers the real network's resolution; use it so it stays an input
             helper.make_node("Cast", ["num_tokens"], ["tokens_f"], to=TensorProto.FLOAT),
             helper.make_node("Mul", ["tokens_f", "zero"], ["tokens_zero"]),
             helper.make_node("ReduceMean", ["zeros_nhw"], ["zeros_n"], axes=[1, 2],
                              keepdims=0),
             helper.make_node("Add", ["zeros_n", "tokens_zero"], ["zeros_n_t"]),
             helper.make_node("Add", ["zeros_n_t", "scale_value"], ["metric_scale"])]
    inputs = [_image_input("image", None),
              helper.make_tensor_value_info("num_tokens", TensorProto.INT64, [])]
    outputs = [
        helper.make_tensor_value_info("points", TensorProto.FLOAT, ["batch", "h", "w", 3]),
        helper.make_tensor_value_info("normal", TensorProto.FLOAT, ["batch", "h", "w", 3]),
        helper.make_tensor_value_info("mask", TensorProto.FLOAT, ["batch", "h", "w"]),
        helper.make_tensor_value_info("metric_scale", TensorProto.FLOAT, ["batch"])]
    return _save(nodes, inputs, outputs, inits, path)
