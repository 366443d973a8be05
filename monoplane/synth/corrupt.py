"""Corrupt exact depth and normals the way monocular networks err.

The corrupted cues are what an algorithm sees; ground truth stays separate. Depth goes through,
in this order:

1. an unknown global scale ``s`` (log-uniform), so the depth is relative;
2. a range distortion ``z -> z^(1+g)`` (``g`` uniform in ``[-gamma, gamma]``), the residual
   non-linearity of affine-invariant depth;
3. a smooth multiplicative warp ``exp(w(u, v))``: ``w`` is a random quadratic polynomial plus a
   few Gaussian bumps in image space, zero-mean and rescaled so ``max |w| = warp``;
4. blurred discontinuities: within ``edge_width`` px of an occlusion boundary (a jump of more
   than 4 % in log-depth between neighbours) the depth fades into its Gaussian blur of
   ``edge_sigma`` px, which smears foreground and background together as networks do;
5. additive Gaussian noise with standard deviation ``depth_noise`` x the median depth.

Normals are Gaussian-blurred by ``normal_sigma`` px and renormalised, rotated by one random
global rotation of ``normal_rotation_deg`` (angle uniform in ``[0.5, 1]`` x that value, random
axis), perturbed by per-pixel Gaussian noise of ``normal_noise`` per component, renormalised,
and flipped where needed to face the camera.

Pixel sizes are given for a 256-pixel-wide image and scale with the width.

=====================  =======  ===========  ===========
parameter              clean    mild         strong
=====================  =======  ===========  ===========
scale range            1        0.25 - 4     0.25 - 4
gamma                  0        0.02         0.06
warp (max abs log)     0        0.03         0.10
warp bumps             0        2            4
edge_sigma (px)        0        1.5          3.5
edge_width (px)        0        2            5
depth_noise            0        0.002        0.006
normal_sigma (px)      0        1.0          2.5
normal_rotation_deg    0        2            6
normal_noise           0        0.02         0.06
=====================  =======  ===========  ===========

``clean`` returns the ground truth unchanged (metric depth).

The depth steps are :func:`corrupt_depth` and the normal steps :func:`corrupt_normals`, which
other evaluations reuse on real data (``monoplane eval --multiview --data``, see
:mod:`monoplane.evaluation.posed_sequences`): both keep holes (depth 0, all-zero normals) as
holes and never mix them into valid pixels. :func:`corrupt` draws the depth's random numbers
first, then the normals', from one generator.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from monoplane.datamodel import pixel_rays
from monoplane.errors import InvalidInput


@dataclass(frozen=True)
class CorruptionParams:
    """Strength of each corruption; see the module docstring for their meaning."""

    scale_range: tuple[float, float]
    gamma: float
    warp: float
    warp_bumps: int
    edge_sigma: float
    edge_width: float
    depth_noise: float
    normal_sigma: float
    normal_rotation_deg: float
    normal_noise: float


LEVEL_PARAMS: dict[str, CorruptionParams] = {
    "clean": CorruptionParams((1.0, 1.0), 0.0, 0.0, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    "mild": CorruptionParams((0.25, 4.0), 0.02, 0.03, 2, 1.5, 2.0, 0.002, 1.0, 2.0, 0.02),
    "strong": CorruptionParams((0.25, 4.0), 0.06, 0.10, 4, 3.5, 5.0, 0.006, 2.5, 6.0, 0.06),
}

_REFERENCE_WIDTH = 256.0
_EDGE_JUMP = 0.04  # log-depth jump between neighbours that counts as an occlusion boundary


@dataclass
class CorruptedCues:
    """Corrupted cues of one view.

    Attributes
    ----------
    depth : numpy.ndarray
        (H, W) float32, positive, ``scale`` x metres up to the warp and noise.
    normals : numpy.ndarray
        (H, W, 3) float32 unit normals, camera frame, facing the camera.
    scale : float
        The global factor applied (1 for ``clean``).
    """

    depth: np.ndarray
    normals: np.ndarray
    scale: float


def smooth_warp(height: int, width: int, n_bumps: int, amplitude: float,
                rng: np.random.Generator) -> np.ndarray:
    """Random smooth zero-mean field with ``max |w| = amplitude``.

    Returns
    -------
    numpy.ndarray
        (H, W) float64 log-depth warp.
    """
    if amplitude == 0.0:
        return np.zeros((height, width))
    x = np.linspace(-1.0, 1.0, width)
    y = np.linspace(-1.0, 1.0, height) * (height / width)
    X, Y = np.meshgrid(x, y)
    c = rng.normal(size=5)
    w = c[0] * X + c[1] * Y + c[2] * X**2 + c[3] * X * Y + c[4] * Y**2
    for _ in range(n_bumps):
        cx, cy = rng.uniform(-1, 1), rng.uniform(-1, 1) * (height / width)
        sigma = rng.uniform(0.2, 0.5)
        w += rng.normal() * 1.5 * np.exp(-((X - cx) ** 2 + (Y - cy) ** 2) / (2 * sigma**2))
    w -= w.mean()
    peak = np.abs(w).max()
    return w * (amplitude / peak) if peak > 0 else w


def occlusion_edges(depth: np.ndarray) -> np.ndarray:
    """(H, W) bool mask of pixels next to a depth jump of more than 4 % (log-depth).

    Only jumps between two valid (positive) pixels count: a hole's rim is not an edge.
    """
    valid = depth > 0
    logd = np.log(np.where(valid, depth, 1.0))
    edges = np.zeros(depth.shape, dtype=bool)
    jump_x = (np.abs(np.diff(logd, axis=1)) > _EDGE_JUMP) & valid[:, 1:] & valid[:, :-1]
    jump_y = (np.abs(np.diff(logd, axis=0)) > _EDGE_JUMP) & valid[1:, :] & valid[:-1, :]
    edges[:, 1:] |= jump_x
    edges[:, :-1] |= jump_x
    edges[1:, :] |= jump_y
    edges[:-1, :] |= jump_y
    return edges


def blur_discontinuities(depth: np.ndarray, edges: np.ndarray, sigma: float, width: float,
                         valid: np.ndarray | None = None) -> np.ndarray:
    """Fade depth into its Gaussian blur within ``width`` px of ``edges``.

    Parameters
    ----------
    depth : numpy.ndarray
        (H, W) float64 positive depth (any value where ``valid`` is False).
    edges : numpy.ndarray
        (H, W) bool occlusion-boundary pixels.
    sigma, width : float
        Blur standard deviation and band half-width in pixels.
    valid : numpy.ndarray, optional
        (H, W) bool pixels with a depth; the blur averages these only (normalised
        convolution). Default: every pixel.

    Returns
    -------
    numpy.ndarray
        (H, W) float64; pixels outside ``valid`` hold meaningless values.
    """
    if sigma <= 0 or width <= 0 or not edges.any():
        return depth
    dist = cv2.distanceTransform((~edges).astype(np.uint8), cv2.DIST_L2, 3)
    weight = np.clip(1.0 - dist / width, 0.0, 1.0)
    if valid is None or valid.all():
        blurred = cv2.GaussianBlur(depth, (0, 0), sigma, borderType=cv2.BORDER_REFLECT)
    else:
        mask = valid.astype(np.float64)
        blurred = (cv2.GaussianBlur(np.where(valid, depth, 0.0), (0, 0), sigma,
                                    borderType=cv2.BORDER_REFLECT)
                   / np.maximum(cv2.GaussianBlur(mask, (0, 0), sigma,
                                                 borderType=cv2.BORDER_REFLECT), 1e-12))
    return (1.0 - weight) * depth + weight * blurred


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _unit(n: np.ndarray) -> np.ndarray:
    """Rows of (..., 3) ``n`` scaled to unit length; zero rows stay zero."""
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    return n / np.where(norm > 0, norm, 1.0)


def corrupt_depth(gt_depth: np.ndarray, params: CorruptionParams, rng: np.random.Generator
                  ) -> tuple[np.ndarray, float]:
    """Depth steps 1-5 of the module docstring: scale, range distortion, warp, blurred
    discontinuities, noise.

    Parameters
    ----------
    gt_depth : numpy.ndarray
        (H, W) exact z-depth in metres; 0 marks a hole (no measurement), which stays 0.
    params : CorruptionParams
        Strengths (e.g. ``LEVEL_PARAMS["mild"]``); pixel sizes are for a 256-pixel-wide image
        and scale with ``W``.
    rng : numpy.random.Generator
        Source of the draws: scale, range exponent, warp, noise, in that order.

    Returns
    -------
    (numpy.ndarray, float)
        (H, W) float32 corrupted depth (positive where ``gt_depth`` is, else 0) in
        ``scale`` x metres, and the global scale drawn.

    Raises
    ------
    InvalidInput
        When the depth has no positive pixel.
    """
    z = gt_depth.astype(np.float64)
    valid = z > 0
    if not valid.any():
        raise InvalidInput("cannot corrupt a depth map without a positive pixel")
    h, w = z.shape
    px = w / _REFERENCE_WIDTH
    lo, hi = np.log(params.scale_range[0]), np.log(params.scale_range[1])
    scale = float(np.exp(rng.uniform(lo, hi)))
    gamma = rng.uniform(-params.gamma, params.gamma)

    median = float(np.median(z[valid]))
    # Holes take the median so every step stays finite; they are zeroed at the end.
    filled = np.where(valid, z, median)
    # Range distortion about the median keeps the scale factor meaningful.
    depth = scale * median * (filled / median) ** (1.0 + gamma)
    depth *= np.exp(smooth_warp(h, w, params.warp_bumps, params.warp, rng))
    depth = blur_discontinuities(depth, occlusion_edges(z), params.edge_sigma * px,
                                 params.edge_width * px, valid)
    depth += rng.normal(0.0, params.depth_noise * scale * median, depth.shape)
    depth = np.maximum(depth, 1e-3 * scale * median)
    return np.where(valid, depth, 0.0).astype(np.float32), scale


def corrupt_normals(gt_normals: np.ndarray, K: np.ndarray, params: CorruptionParams,
                    rng: np.random.Generator) -> np.ndarray:
    """Normal steps of the module docstring: blur (across creases), one global rotation,
    per-pixel noise, facing the camera.

    Parameters
    ----------
    gt_normals : numpy.ndarray
        (H, W, 3) unit normals, camera frame (x right, y down, z forward); all-zero rows mark
        pixels without a normal, which stay zero and do not enter their neighbours' blur
        beyond shortening it.
    K : numpy.ndarray
        (3, 3) intrinsics (to orient normals towards the camera).
    params : CorruptionParams
        Strengths; ``normal_sigma`` is for a 256-pixel-wide image and scales with ``W``.
    rng : numpy.random.Generator
        Source of the draws: rotation angle, rotation axis, noise, in that order.

    Returns
    -------
    numpy.ndarray
        (H, W, 3) float32 unit normals facing the camera (zero where the input is).
    """
    n = gt_normals.astype(np.float64)
    valid = np.any(n != 0, axis=-1)
    h, w = valid.shape
    if params.normal_sigma > 0:
        n = _unit(np.asarray(cv2.GaussianBlur(n, (0, 0), params.normal_sigma * w
                                              / _REFERENCE_WIDTH,
                                              borderType=cv2.BORDER_REFLECT), dtype=np.float64))
    angle = np.deg2rad(params.normal_rotation_deg) * rng.uniform(0.5, 1.0)
    n = n @ _rotation(rng.normal(size=3), angle).T
    n += rng.normal(0.0, params.normal_noise, n.shape)
    n = _unit(n)
    rays = pixel_rays(K, h, w)
    n *= np.where(np.sum(n * rays, axis=-1, keepdims=True) > 0, -1.0, 1.0)
    return np.where(valid[..., None], n, 0.0).astype(np.float32)


def corrupt(gt_depth: np.ndarray, gt_normals: np.ndarray, K: np.ndarray, level: str,
            rng: np.random.Generator) -> CorruptedCues:
    """Apply the corruptions of ``level`` (see the module docstring).

    Parameters
    ----------
    gt_depth : numpy.ndarray
        (H, W) float32 exact z-depth in metres, all positive.
    gt_normals : numpy.ndarray
        (H, W, 3) float32 exact unit normals, camera frame (x right, y down, z forward).
    K : numpy.ndarray
        (3, 3) intrinsics (to orient normals towards the camera).
    level : {"clean", "mild", "strong"}
    rng : numpy.random.Generator
        Source of every random draw (the depth's first, then the normals').

    Returns
    -------
    CorruptedCues
    """
    p = LEVEL_PARAMS[level]
    if level == "clean":
        return CorruptedCues(gt_depth.astype(np.float32).copy(),
                             gt_normals.astype(np.float32).copy(), 1.0)
    depth, scale = corrupt_depth(gt_depth, p, rng)
    return CorruptedCues(depth, corrupt_normals(gt_normals, K, p, rng), scale)
