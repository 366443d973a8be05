"""XFeat (Potje et al., CVPR 2024) keypoints and descriptors from its ONNX backbone.

The backbone takes a (1, 3, 640, 640) float image in [0, 1] (it converts to grey and
normalises itself) and returns, on an 80 x 80 grid of 8 x 8-pixel cells:

* ``descriptors``: (1, 64, 80, 80) dense descriptors, unit-normalised here and sampled
  bilinearly at each keypoint, then normalised again;
* ``keypoint logits``: (1, 65, 80, 80): per cell, 64 logits for its 64 pixels (row-major
  inside the cell) and one "no keypoint" bin; a softmax over the 65, the last dropped and each
  cell unfolded into its 8 x 8 pixels, gives a full-resolution keypoint heatmap;
* ``reliability``: (1, 1, 80, 80) in [0, 1], multiplied with the heatmap to rank keypoints.

An image is scaled so that its longer side is 640 px and padded at the bottom or right; pixel
centres stay at integers (``x_net = (x + 0.5) s - 0.5``). Keypoints are the 5 x 5 local maxima
of the heatmap above a threshold, strongest first; they are returned in the image's own pixels.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from monoplane.cues.session import open_session
from monoplane.errors import InvalidInput
from monoplane.features.correspondences import Keypoints

#: The backbone's fixed input side and its cell size, in pixels.
INPUT_SIDE = 640
CELL = 8
DESCRIPTOR_DIM = 64


def _first_line(exc: Exception) -> str:
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]


class XFeatNetwork:
    """The XFeat backbone loaded with onnxruntime (CPU).

    Parameters
    ----------
    path : str or pathlib.Path
        The ``.onnx`` file.
    threads : int
        onnxruntime intra-op threads.

    Raises
    ------
    InvalidInput
        One line naming the file when it is missing, cannot be loaded, or does not have one
        (1, 3, 640, 640) input and the three outputs described above (the message lists what
        the file has).
    """

    def __init__(self, path: str | Path, threads: int = 2) -> None:
        self.path = Path(path).expanduser()
        expected = ("one float input (1, 3, 640, 640) and outputs (1, 64, 80, 80) descriptors, "
                    "(1, 65, 80, 80) keypoint logits and (1, 1, 80, 80) reliability")
        self.session = open_session(self.path, max(1, int(threads)), "xfeat model",
                                    f"the XFeat ONNX backbone with {expected}; see "
                                    "docs/multiview.md")
        inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        by_channels = {tuple(o.shape[1:2]): o.name for o in outputs if len(o.shape) == 4}
        shape_ok = (len(inputs) == 1 and list(inputs[0].shape)[1:] == [3, INPUT_SIDE, INPUT_SIDE]
                    and "float" in inputs[0].type)
        if not shape_ok or not all((c,) in by_channels for c in (DESCRIPTOR_DIM, 65, 1)):
            ins = ", ".join(f"{i.name}{tuple(i.shape)}" for i in inputs)
            outs = ", ".join(f"{o.name}{tuple(o.shape)}" for o in outputs)
            raise InvalidInput(f"{self.path}: not an XFeat backbone: expected {expected}; the "
                               f"model has inputs [{ins}] and outputs [{outs}]")
        self.input_name = inputs[0].name
        self.outputs = [by_channels[(DESCRIPTOR_DIM,)], by_channels[(65,)], by_channels[(1,)]]

    def detect(self, rgb: np.ndarray, max_keypoints: int = 4096, threshold: float = 0.05
               ) -> Keypoints:
        """Keypoints and unit descriptors of one image.

        Parameters
        ----------
        rgb : numpy.ndarray
            (H, W, 3) uint8 RGB image.
        max_keypoints : int
            Keep at most this many, highest score first.
        threshold : float
            Smallest heatmap value of a keypoint (a probability, 0-1).

        Returns
        -------
        Keypoints
            Pixels in the image's own coordinates, (k, 64) float32 unit descriptors, and
            scores (heatmap times reliability).
        """
        h, w = rgb.shape[:2]
        s = INPUT_SIDE / max(h, w)
        size = (max(1, round(w * s)), max(1, round(h * s)))
        image = cv2.resize(rgb, size, interpolation=cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR)
        batch = np.zeros((1, 3, INPUT_SIDE, INPUT_SIDE), np.float32)
        batch[0, :, :size[1], :size[0]] = image.transpose(2, 0, 1).astype(np.float32) / 255.0
        try:
            dense, logits, reliability = self.session.run(self.outputs, {self.input_name: batch})
        except Exception as exc:  # shape errors inside the graph surface here
            raise InvalidInput(f"{self.path}: the xfeat model failed ({_first_line(exc)})"
                               ) from None
        heat = _heatmap(logits[0])
        # Only the image's own area; keypoints at the very border have clipped descriptors.
        valid = np.zeros_like(heat, bool)
        valid[2:size[1] - 2, 2:size[0] - 2] = True
        peaks = (heat == cv2.dilate(heat, np.ones((5, 5), np.uint8))) & (heat > threshold) & valid
        rows, cols = np.nonzero(peaks)
        net = np.c_[cols, rows] + _subpixel(heat, rows, cols)
        rel = _bilinear(reliability[0], _cell_coords(net))[0]
        scores = heat[rows, cols] * rel
        order = np.argsort(-scores, kind="stable")[:max_keypoints]
        net, scores = net[order], scores[order]
        norm = np.linalg.norm(dense[0], axis=0, keepdims=True)
        dense = dense[0] / np.maximum(norm, 1e-12)
        desc = _bilinear(dense, _cell_coords(net)).T
        desc /= np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
        pixels = (net + 0.5) / s - 0.5
        return Keypoints(pixels, desc.astype(np.float32), scores.astype(np.float32))


def _heatmap(logits: np.ndarray) -> np.ndarray:
    """(640, 640) keypoint probabilities from (65, 80, 80) cell logits."""
    z = logits - logits.max(axis=0, keepdims=True)
    p = np.exp(z)
    p /= p.sum(axis=0, keepdims=True)
    g = logits.shape[1]
    # Channel r * 8 + c of cell (Y, X) is pixel (8 Y + r, 8 X + c).
    return np.ascontiguousarray(
        p[:CELL * CELL].reshape(CELL, CELL, g, g).transpose(2, 0, 3, 1).reshape(g * CELL,
                                                                                g * CELL))


def _subpixel(heat: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """(n, 2) sub-pixel offsets ``(du, dv)`` of heatmap peaks, from a parabola through each
    peak and its two neighbours along each axis (clipped to half a pixel).

    The heatmap's pixel grid alone leaves up to half a pixel of error on each keypoint, which
    the essential matrix of a wide pair turns into degrees of rotation.
    """
    h, w = heat.shape
    r = np.clip(rows, 1, h - 2)
    c = np.clip(cols, 1, w - 2)
    centre = heat[r, c].astype(np.float64)
    offsets = []
    for lo, hi in ((heat[r, c - 1], heat[r, c + 1]), (heat[r - 1, c], heat[r + 1, c])):
        curvature = 2.0 * centre - lo - hi
        with np.errstate(divide="ignore", invalid="ignore"):
            d = np.where(curvature > 0, 0.5 * (hi - lo) / curvature, 0.0)
        offsets.append(np.clip(d, -0.5, 0.5))
    return np.stack(offsets, axis=1)


def _cell_coords(net: np.ndarray) -> np.ndarray:
    """Network-input pixels (centres at integers) to coordinates on the 80 x 80 cell grid."""
    return (net + 0.5) / CELL - 0.5


def _bilinear(grid: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """(C, n) bilinear samples of a (C, G, G) map at (n, 2) grid coordinates (clamped)."""
    c, gh, gw = grid.shape
    x = np.clip(xy[:, 0], 0, gw - 1)
    y = np.clip(xy[:, 1], 0, gh - 1)
    x0 = np.minimum(np.floor(x).astype(np.int64), gw - 2)
    y0 = np.minimum(np.floor(y).astype(np.int64), gh - 2)
    fx, fy = x - x0, y - y0
    return (grid[:, y0, x0] * ((1 - fx) * (1 - fy)) + grid[:, y0, x0 + 1] * (fx * (1 - fy))
            + grid[:, y0 + 1, x0] * ((1 - fx) * fy) + grid[:, y0 + 1, x0 + 1] * (fx * fy))
