"""Load an ONNX network with onnxruntime (CPU), check it against a :class:`ModelSpec`, run it.

Errors a user can cause (a missing or corrupt file, a model whose inputs or outputs do not match
the profile) are one-line :class:`~monoplane.errors.InvalidInput` messages that name the file
and what was expected.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from monoplane.cues.profiles import ModelSpec
from monoplane.cues.transforms import (
    Letterbox,
    plan_letterbox,
    prepare_image,
    restore_map,
    scaled_intrinsics,
)
from monoplane.errors import InvalidInput

if TYPE_CHECKING:
    import onnxruntime


def _shape_text(shape: list) -> str:
    return "(" + ", ".join(str(d) if d is not None else "?" for d in shape) + ")"


#: onnxruntime's tensor type names, spelled as numpy dtypes in messages.
_DTYPES = {"tensor(float)": "float32", "tensor(float16)": "float16", "tensor(double)": "float64",
           "tensor(int64)": "int64", "tensor(int32)": "int32", "tensor(uint8)": "uint8",
           "tensor(int8)": "int8", "tensor(bool)": "bool"}


def _tensor_text(arg: object) -> str:
    """``name(1, 224, 224, 3) float32`` for an onnxruntime input or output description."""
    dtype = _DTYPES.get(arg.type, arg.type)  # type: ignore[attr-defined]
    return f"{arg.name}{_shape_text(arg.shape)} {dtype}"  # type: ignore[attr-defined]


def _static(dim: object) -> int | None:
    """A fixed dimension as an int; symbolic or unknown dimensions as ``None``."""
    return dim if isinstance(dim, int) and dim > 0 else None


def open_session(path: Path, threads: int, label: str, expected: str
                 ) -> onnxruntime.InferenceSession:
    """An onnxruntime CPU session of an ONNX file, or a one-line error naming the file.

    Parameters
    ----------
    path : pathlib.Path
        The ``.onnx`` file.
    threads : int
        Intra-op threads (at least 1).
    label : str
        How to name the model in messages, e.g. ``"xfeat model"``.
    expected : str
        What the file should hold, for the missing-file message.

    Raises
    ------
    InvalidInput
        When the file is missing or onnxruntime cannot load it, or ``threads`` < 1.
    """
    import onnxruntime as ort

    if not path.is_file():
        raise InvalidInput(f"{label} file not found: {path} (expected {expected})")
    if threads < 1:
        raise InvalidInput(f"threads must be >= 1, got {threads}")
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = threads
    opts.inter_op_num_threads = 1
    opts.log_severity_level = 3
    try:
        return ort.InferenceSession(str(path), sess_options=opts,
                                    providers=["CPUExecutionProvider"])
    except Exception as exc:  # onnxruntime raises several unrelated types for bad files
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise InvalidInput(f"{path}: cannot load {label} as ONNX ({first})") from None


class OnnxModel:
    """One ONNX network, loaded once and run on many images.

    Parameters
    ----------
    path : str or pathlib.Path
        The ``.onnx`` file.
    spec : ModelSpec
        What the network expects and returns.
    threads : int
        onnxruntime intra-op threads (CPU execution provider).
    label : str
        How to name the model in messages, e.g. ``"midas depth model"``.

    Raises
    ------
    InvalidInput
        When the file is missing, cannot be loaded, or its signature does not match ``spec``.
    """

    def __init__(self, path: str | Path, spec: ModelSpec, *, threads: int = 2,
                 label: str = "model") -> None:
        self.path = Path(path).expanduser()
        self.spec = spec
        self.label = label
        self.session = open_session(self.path, threads, label,
                                    f"an ONNX file with {spec.describe()}")
        self._bind()

    def _mismatch(self, what: str) -> InvalidInput:
        ins = ", ".join(_tensor_text(i) for i in self.session.get_inputs())
        outs = ", ".join(_tensor_text(o) for o in self.session.get_outputs())
        return InvalidInput(
            f"{self.path}: {self.label} does not match its profile: {what}; expected "
            f"{self.spec.describe()}; the model has inputs [{ins}] and outputs [{outs}]"
        )

    def _bind(self) -> None:
        """Find the image, intrinsics and output tensors and check their ranks and sizes."""
        spec = self.spec
        inputs = {i.name: i for i in self.session.get_inputs()}
        if spec.intrinsics_input is not None:
            intr = inputs.get(spec.intrinsics_input)
            if intr is None:
                raise self._mismatch(f"no input named {spec.intrinsics_input!r}")
            if len(intr.shape) != 3 or any(_static(d) not in (None, 3) for d in intr.shape[1:]):
                raise self._mismatch(f"input {intr.name!r} is not (N, 3, 3)")
        constants = {name for name, _ in spec.constant_inputs}
        for name in constants:
            if name not in inputs:
                raise self._mismatch(f"no input named {name!r}")
            if "int" not in inputs[name].type or len(inputs[name].shape) > 1:
                raise self._mismatch(f"input {name!r} is not an integer scalar")
        others = [n for n in inputs if n != spec.intrinsics_input and n not in constants]
        if spec.image_input is not None:
            if spec.image_input not in inputs:
                raise self._mismatch(f"no input named {spec.image_input!r}")
            self.image_input = spec.image_input
        elif len(others) == 1:
            self.image_input = others[0]
        else:
            raise self._mismatch(f"{len(others)} candidate image inputs")
        extra = set(others) - {self.image_input}
        if extra:
            raise self._mismatch(f"unexpected inputs {sorted(extra)}")
        img = inputs[self.image_input]
        # Axis positions of channels, height and width in the declared layout.
        c_ax, h_ax, w_ax = (1, 2, 3) if spec.layout == "NCHW" else (3, 1, 2)
        if len(img.shape) != 4 or _static(img.shape[c_ax]) not in (None, 3):
            box = "(N, 3, H, W)" if spec.layout == "NCHW" else "(N, H, W, 3)"
            other, o_ax = ("NHWC", 3) if spec.layout == "NCHW" else ("NCHW", 1)
            hint = (f", it looks like layout {other}" if len(img.shape) == 4
                    and _static(img.shape[o_ax]) == 3 else "")
            raise self._mismatch(f"input {img.name!r} is not {box} (layout {spec.layout}"
                                 f"{hint})")
        if "float" not in img.type:
            raise self._mismatch(f"input {img.name!r} has type {img.type}, not float")
        h, w = _static(img.shape[h_ax]), _static(img.shape[w_ax])
        self.fixed_size = (h, w) if h and w else None

        outputs = {o.name: o for o in self.session.get_outputs()}
        name = spec.output_name or next(iter(outputs))
        if name not in outputs:
            raise self._mismatch(f"no output named {name!r}")
        self.output_name = name
        shape = outputs[name].shape
        if spec.output == "point_map" or not spec.is_depth:
            ok = _three_channels(shape)
        else:
            ok = 2 <= len(shape) <= 4 and (len(shape) < 4 or _static(shape[1]) in (None, 1))
        if not ok:
            raise self._mismatch(f"output {name!r} has shape {_shape_text(shape)}")
        # Further outputs of joint networks: name -> channels of the restored map (0: scalar).
        self.extra_outputs: dict[str, int] = {}
        for out_name, channels in ((spec.normals_output, 3), (spec.mask_output, 1),
                                   (spec.scale_output, 0)):
            if out_name is None:
                continue
            if out_name not in outputs:
                raise self._mismatch(f"no output named {out_name!r}")
            if channels == 3 and not _three_channels(outputs[out_name].shape):
                raise self._mismatch(f"output {out_name!r} has shape "
                                     f"{_shape_text(outputs[out_name].shape)}")
            self.extra_outputs[out_name] = channels

    def letterbox(self, height: int, width: int) -> Letterbox:
        """Where an image of this size sits inside the network input."""
        return plan_letterbox(height, width, self.spec, self.fixed_size)

    def predict(self, rgb: np.ndarray, K: np.ndarray) -> np.ndarray:
        """Run the network on one image and bring the output back to the image's size.

        Parameters
        ----------
        rgb : numpy.ndarray
            (H, W, 3) uint8 RGB image.
        K : numpy.ndarray
            (3, 3) intrinsics of the image; passed (rescaled) to camera-aware networks.

        Returns
        -------
        numpy.ndarray
            (H, W) float32 raw depth-like values, or (H, W, 3) float32 raw normal channels,
            not yet decoded (see :mod:`monoplane.cues.transforms`).
        """
        return self.run(rgb, K)[self.output_name]

    def run(self, rgb: np.ndarray, K: np.ndarray) -> dict[str, np.ndarray]:
        """Run the network once and return every output the spec names.

        Parameters
        ----------
        rgb : numpy.ndarray
            (H, W, 3) uint8 RGB image.
        K : numpy.ndarray
            (3, 3) intrinsics of the image.

        Returns
        -------
        dict
            Output name to array: maps come back at the image's size, (H, W) or (H, W, 3)
            float32 raw values; scalar outputs (``scale_output``) as a float32 array of shape
            (1,).
        """
        box = self.letterbox(rgb.shape[0], rgb.shape[1])
        feeds = {self.image_input: prepare_image(rgb, self.spec, box)}
        if self.spec.intrinsics_input is not None:
            feeds[self.spec.intrinsics_input] = scaled_intrinsics(K, box)
        for name, value in self.spec.constant_inputs:
            feeds[name] = np.array(value, dtype=np.int64)
        wanted = {self.output_name: 1 if self.spec.output not in ("normals", "point_map") else 3,
                  **self.extra_outputs}
        names = list(wanted)
        try:
            raw = self.session.run(names, feeds)
        except Exception as exc:  # shape errors inside the graph surface here
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise InvalidInput(f"{self.path}: {self.label} failed on a "
                               f"{box.padded[1]}x{box.padded[0]} input ({first})") from None
        result: dict[str, np.ndarray] = {}
        for name, out in zip(names, raw, strict=True):
            try:
                if wanted[name] == 0:
                    result[name] = np.asarray(out, dtype=np.float32).reshape(-1)[:1]
                else:
                    result[name] = restore_map(_first_three(out, wanted[name]), box,
                                               wanted[name])
            except InvalidInput as exc:
                raise self._mismatch(f"output {name!r}: {exc}") from None
        return result


def _three_channels(shape: list) -> bool:
    """Whether a declared output shape can hold a 3-vector map, channels first or last.

    Channels-first maps may carry a fourth channel (Metric3D appends a confidence to its
    normals); :func:`_first_three` drops it.
    """
    if len(shape) not in (3, 4):
        return False
    return _static(shape[-1]) in (None, 3) or _static(shape[-3]) in (None, 3, 4)


def _first_three(out: np.ndarray, channels: int) -> np.ndarray:
    """The first three channels of a channels-first (N, 4, H, W) map; other arrays unchanged."""
    a = np.asarray(out)
    if channels == 3 and a.ndim == 4 and a.shape[1] == 4 and a.shape[-1] != 3:
        return a[:, :3]
    return a
