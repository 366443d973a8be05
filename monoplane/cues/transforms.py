"""Pre- and post-processing around a monocular network: letterboxing, normalisation, and
turning raw outputs into z-depth and camera-frame normals.

Every function is pure numpy/OpenCV so plugins can reuse them with their own sessions.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from monoplane.cues.profiles import ModelSpec, parse_axes
from monoplane.deprecation import renamed_names
from monoplane.errors import InvalidInput


@dataclass(frozen=True)
class Letterbox:
    """Where the image sits inside the network input.

    Attributes
    ----------
    original : tuple of int
        ``(H, W)`` of the input image.
    resized : tuple of int
        ``(h, w)`` of the resized image, placed at the top-left of the input.
    padded : tuple of int
        ``(h_in, w_in)`` of the network input (resized plus bottom/right padding).
    """

    original: tuple[int, int]
    resized: tuple[int, int]
    padded: tuple[int, int]

    @property
    def scale(self) -> tuple[float, float]:
        """``(sx, sy)`` factors from original to resized pixel coordinates."""
        return (self.resized[1] / self.original[1], self.resized[0] / self.original[0])


def _round_up(x: int, m: int) -> int:
    return -(-x // m) * m


def plan_letterbox(height: int, width: int, spec: ModelSpec,
                   fixed: tuple[int, int] | None = None) -> Letterbox:
    """Choose the resized and padded sizes for an image.

    Parameters
    ----------
    height, width : int
        Image size in pixels.
    spec : ModelSpec
        Resize policy, input box and multiple.
    fixed : tuple of int, optional
        ``(h, w)`` when the model was exported with fixed spatial input dimensions; the input is
        then exactly that size.
    """
    box_h, box_w = fixed or spec.size
    if spec.resize == "stretch":
        h_in, w_in = fixed or (_round_up(box_h, spec.multiple_of),
                               _round_up(box_w, spec.multiple_of))
        return Letterbox((height, width), (h_in, w_in), (h_in, w_in))
    s = min(box_h / height, box_w / width)
    rh, rw = max(1, round(height * s)), max(1, round(width * s))
    if fixed is None:
        padded = (_round_up(rh, spec.multiple_of), _round_up(rw, spec.multiple_of))
    else:
        padded = fixed
    return Letterbox((height, width), (rh, rw), padded)


def prepare_image(rgb: np.ndarray, spec: ModelSpec, box: Letterbox) -> np.ndarray:
    """Resize, pad and normalise an image into a network input tensor.

    Parameters
    ----------
    rgb : numpy.ndarray
        (H, W, 3) uint8 RGB image.
    spec : ModelSpec
        Channel order, value range, normalisation (``mean``, ``std`` on values in
        ``value_range``) and layout.
    box : Letterbox
        From :func:`plan_letterbox`.

    Returns
    -------
    numpy.ndarray
        (1, 3, h_in, w_in) float32 for ``layout = "NCHW"``, (1, h_in, w_in, 3) for ``"NHWC"``.
    """
    low, high = spec.value_range
    img: np.ndarray = rgb.astype(np.float32) * np.float32((high - low) / 255.0) + np.float32(low)
    if spec.colour_order == "BGR":
        img = img[..., ::-1]
    rh, rw = box.resized
    shrink = rh * rw < rgb.shape[0] * rgb.shape[1]
    img = cv2.resize(np.ascontiguousarray(img), (rw, rh),
                     interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR)
    ph, pw = box.padded
    img = cv2.copyMakeBorder(img, 0, ph - rh, 0, pw - rw, cv2.BORDER_REPLICATE)
    x = (img - np.asarray(spec.mean, np.float32)) / np.asarray(spec.std, np.float32)
    if spec.layout == "NCHW":
        x = x.transpose(2, 0, 1)
    return np.ascontiguousarray(x[None]).astype(np.float32)


def scaled_intrinsics(K: np.ndarray, box: Letterbox) -> np.ndarray:
    """Intrinsics of the resized image inside the network input.

    Returns
    -------
    numpy.ndarray
        (1, 3, 3) float32, pixel centres at integer coordinates (as in ``K``).
    """
    sx, sy = box.scale
    S = np.array([[sx, 0, 0.5 * sx - 0.5], [0, sy, 0.5 * sy - 0.5], [0, 0, 1]])
    return (S @ np.asarray(K, dtype=np.float64)).astype(np.float32)[None]


def restore_map(out: np.ndarray, box: Letterbox, channels: int) -> np.ndarray:
    """Crop a network output to the image region and resize it to the original size.

    Parameters
    ----------
    out : numpy.ndarray
        Raw output: (1, 1, h, w), (1, h, w) or (h, w) when ``channels == 1``; (1, 3, h, w),
        (1, h, w, 3) or (3, h, w) when ``channels == 3``. ``(h, w)`` may differ from the input
        size (decoders at half resolution); the image region is scaled accordingly.
    box : Letterbox
        The letterbox used for the input.
    channels : int
        1 for depth-like outputs, 3 for normals.

    Returns
    -------
    numpy.ndarray
        (H, W) or (H, W, 3) float32 at the original resolution (bilinear).
    """
    a = np.asarray(out, dtype=np.float32)
    while a.ndim > (2 if channels == 1 else 3) and a.shape[0] == 1:
        a = a[0]
    if channels == 1 and a.ndim != 2:
        raise InvalidInput(f"expected a single-channel output map, got shape {out.shape}")
    if channels == 3:
        if a.ndim == 3 and a.shape[0] == 3 and a.shape[2] != 3:
            a = a.transpose(1, 2, 0)
        if a.ndim != 3 or a.shape[2] != 3:
            raise InvalidInput(f"expected a 3-channel normal map, got shape {out.shape}")
    oh, ow = a.shape[:2]
    ch = max(1, round(box.resized[0] * oh / box.padded[0]))
    cw = max(1, round(box.resized[1] * ow / box.padded[1]))
    a = np.ascontiguousarray(a[:ch, :cw])
    H, W = box.original
    return cv2.resize(a, (W, H), interpolation=cv2.INTER_LINEAR)


def relative_depth_from_depth(depth: np.ndarray) -> np.ndarray:
    """Normalise a relative depth map to median 1.

    Affine-invariant networks (Omnidata) predict depth up to scale *and shift*; the shift is
    assumed to be zero here. Non-positive values become 0 (invalid).

    Returns
    -------
    numpy.ndarray
        (H, W) float32 relative z-depth, median of the valid pixels 1.
    """
    d = np.where(np.isfinite(depth) & (depth > 0), depth, 0).astype(np.float32)
    if not np.any(d > 0):
        raise InvalidInput("the depth network returned no positive depth")
    return d / np.float32(np.median(d[d > 0]))


def depth_from_disparity(disparity: np.ndarray, floor: float = 0.01) -> np.ndarray:
    """Relative z-depth from a relative inverse-depth (disparity) map.

    ``depth = 1 / (disparity / median(disparity))`` where the normalised disparity exceeds
    ``floor``; below it (sky, far background, negative outputs) the pixel is invalid (0). The
    network's unknown shift is assumed zero. A shift in disparity keeps planes planar (inverse
    depth of a plane is linear in pixel coordinates), so plane detection is unaffected, but it
    changes the angles between planes.

    Parameters
    ----------
    disparity : numpy.ndarray
        (H, W) relative inverse depth, larger = closer.
    floor : float
        Smallest usable disparity as a fraction of the median; depth is at most ``1 / floor``
        times the median depth.

    Returns
    -------
    numpy.ndarray
        (H, W) float32 relative z-depth, median about 1.
    """
    disp = np.where(np.isfinite(disparity), disparity, 0).astype(np.float32)
    pos = disp[disp > 0]
    if pos.size == 0:
        raise InvalidInput("the inverse-depth network returned no positive disparity")
    disp = disp / np.float32(np.median(pos))
    return np.where(disp > floor, 1.0 / np.maximum(disp, floor), 0).astype(np.float32)


def decode_normals(raw: np.ndarray, spec: ModelSpec, K: np.ndarray) -> np.ndarray:
    """Turn a raw normal map into unit camera-frame normals facing the camera.

    Parameters
    ----------
    raw : numpy.ndarray
        (H, W, 3) float32 network output at the original resolution.
    spec : ModelSpec
        ``normal_encoding`` and ``normal_axes`` of the network.
    K : numpy.ndarray
        (3, 3) intrinsics, used to orient normals towards the camera.

    Returns
    -------
    numpy.ndarray
        (H, W, 3) float32, OpenCV camera frame (x right, y down, z forward), ``n · ray <= 0``;
        all-zero where the output has (near-)zero length.
    """
    v = raw.astype(np.float32)
    if spec.normal_encoding == "unsigned":
        v = 2.0 * v - 1.0
    axes = parse_axes(spec.normal_axes)
    n = np.stack([sign * v[..., ch] for ch, sign in axes], axis=-1)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    n = np.where(norm > 1e-6, n / np.maximum(norm, 1e-6), 0.0).astype(np.float32)
    return face_camera(n, K)


def face_camera(normals: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Flip normals that point away from the camera, pixel by pixel.

    (Formerly ``orient_normals``, a name :func:`monoplane.geometry.orientation.orient_normals`
    keeps for orienting a cloud's normals consistently.)

    Parameters
    ----------
    normals : numpy.ndarray
        (H, W, 3) camera-frame normals (OpenCV axes).
    K : numpy.ndarray
        (3, 3) intrinsics.

    Returns
    -------
    numpy.ndarray
        (H, W, 3) float32 with ``n · K^-1 [u, v, 1] <= 0`` at every pixel.
    """
    normals = np.asarray(normals, dtype=np.float32)
    h, w = normals.shape[:2]
    # n · K^-1 [u, v, 1] per axis on broadcast rows and columns: no (H, W, 3) ray image.
    k_inv = np.linalg.inv(K).astype(np.float32)
    u = np.arange(w, dtype=np.float32)
    v = np.arange(h, dtype=np.float32)[:, None]
    dot = normals[..., 0] * (k_inv[0, 0] * u + k_inv[0, 1] * v + k_inv[0, 2])
    dot += normals[..., 1] * (k_inv[1, 0] * u + k_inv[1, 1] * v + k_inv[1, 2])
    dot += normals[..., 2] * (k_inv[2, 0] * u + k_inv[2, 1] * v + k_inv[2, 2])
    return np.where((dot > 0)[..., None], -normals, normals)


# The old name of face_camera, which also named the cloud orientation of geometry.
__getattr__ = renamed_names(__name__, {"orient_normals": "monoplane.cues.transforms:face_camera"})
