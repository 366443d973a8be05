"""Load an ONNX network with onnxruntime (CPU), check it against a :class:`ModelSpec`, run it.

Errors a user can cause (a missing or corrupt file, a model whose inputs or outputs do not match
the profile) are one-line :class:`~monoplane.errors.InvalidInput` messages that name the file
and what was expected.
"""

from __future__ import annotations

from pathlib import Path

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


def _shape_text(shape: list) -> str:
    return "(" + ", ".join(str(d) if d is not None else "?" for d in shape) + ")"


def _static(dim: object) -> int | None:
    """A fixed dimension as an int; symbolic or unknown dimensions as ``None``."""
    return dim if isinstance(dim, int) and dim > 0 else None


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
        import onnxruntime as ort

        self.path = Path(path).expanduser()
        self.spec = spec
        self.label = label
        if not self.path.is_file():
            raise InvalidInput(f"{label} file not found: {self.path} (expected an ONNX file "
                               f"with {spec.describe()})")
        if threads < 1:
            raise InvalidInput(f"threads must be >= 1, got {threads}")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads
        opts.inter_op_num_threads = 1
        opts.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(self.path), sess_options=opts,
                                                providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises several unrelated types for bad files
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise InvalidInput(f"{self.path}: cannot load {label} as ONNX ({first})") from None
        self._bind()

    def _mismatch(self, what: str) -> InvalidInput:
        ins = ", ".join(f"{i.name}{_shape_text(i.shape)}" for i in self.session.get_inputs())
        outs = ", ".join(f"{o.name}{_shape_text(o.shape)}" for o in self.session.get_outputs())
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
        others = [n for n in inputs if n != spec.intrinsics_input]
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
        if len(img.shape) != 4 or _static(img.shape[1]) not in (None, 3):
            raise self._mismatch(f"input {img.name!r} is not (N, 3, H, W)")
        if "float" not in img.type:
            raise self._mismatch(f"input {img.name!r} has type {img.type}, not float")
        h, w = _static(img.shape[2]), _static(img.shape[3])
        self.fixed_size = (h, w) if h and w else None

        outputs = {o.name: o for o in self.session.get_outputs()}
        name = spec.output_name or next(iter(outputs))
        if name not in outputs:
            raise self._mismatch(f"no output named {name!r}")
        self.output_name = name
        shape = outputs[name].shape
        if spec.is_depth:
            ok = 2 <= len(shape) <= 4 and (len(shape) < 4 or _static(shape[1]) in (None, 1))
        else:
            # Channels first or last: (N, 3, H, W), (N, H, W, 3), (3, H, W) or (H, W, 3).
            ends = (shape[-3], shape[-1]) if len(shape) in (3, 4) else ()
            ok = any(_static(d) in (None, 3) for d in ends)
        if not ok:
            raise self._mismatch(f"output {name!r} has shape {_shape_text(shape)}")

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
        box: Letterbox = plan_letterbox(rgb.shape[0], rgb.shape[1], self.spec, self.fixed_size)
        feeds = {self.image_input: prepare_image(rgb, self.spec, box)}
        if self.spec.intrinsics_input is not None:
            feeds[self.spec.intrinsics_input] = scaled_intrinsics(K, box)
        try:
            out = self.session.run([self.output_name], feeds)[0]
        except Exception as exc:  # shape errors inside the graph surface here
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise InvalidInput(f"{self.path}: {self.label} failed on a "
                               f"{box.padded[1]}x{box.padded[0]} input ({first})") from None
        try:
            return restore_map(out, box, 1 if self.spec.is_depth else 3)
        except InvalidInput as exc:
            raise self._mismatch(str(exc)) from None
