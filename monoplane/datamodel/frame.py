"""One image with its geometric cues: :class:`Frame`.

Conventions: see :mod:`monoplane.datamodel`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from monoplane.datamodel.pinhole import _check_K, pixel_rays
from monoplane.errors import InvalidInput
from monoplane.jit import kernel

DepthKind = Literal["metric", "relative"]
DEPTH_KINDS: tuple[str, ...] = ("metric", "relative")


@dataclass
class Frame:
    """One image with its geometric cues.

    Attributes
    ----------
    rgb : numpy.ndarray or None
        (H, W, 3) uint8 colour image, RGB order. ``None`` for depth-only input (range images),
        in which case colour terms are dropped downstream.
    K : numpy.ndarray
        (3, 3) float64 pinhole intrinsics in pixels.
    depth : numpy.ndarray or None
        (H, W) float32 z-depth in ``depth_units``; 0 marks invalid pixels. ``None`` until a cue
        provider fills it.
    normals : numpy.ndarray or None
        (H, W, 3) float32 unit surface normals in the camera frame (x right, y down, z forward),
        facing the camera; all-zero rows mark invalid pixels.
    depth_kind : {"metric", "relative"}
        ``"relative"`` means depth is right only up to an unknown scale.
    depth_units : str
        Human-readable unit of ``depth`` (``"m"``, ``"mm"`` or ``"relative"``).
    confidence : numpy.ndarray or None
        (H, W) float32 in [0, 1], optional per-pixel cue confidence.
    name : str
        Identifier used in messages and outputs (usually the image file stem).
    notes : list of str
        Provenance remarks, e.g. that intrinsics were assumed. Written to ``planes.json``.
    normals_from_depth : bool
        True when ``normals`` were estimated from this frame's own ``depth`` (no normal cue of
        their own): they then carry no evidence that the depth does not, and the planarity
        test (:mod:`monoplane.algorithm.planarity`) judges curvature by the depth alone. With
        a measured depth (:attr:`normals_from_sensor_depth`) the proximity labeler's normal
        gate also applies to them, and the default ``ransac.sampling = "auto"`` searches the
        frame's pixel lattice.
    depth_predicted : bool
        True when a network predicted ``depth`` from the image. Even a metric network's depth
        warps by several percent, so registration treats its scale and shape as estimates, as
        it does relative depth, and takes poses from feature matches instead.
    """

    rgb: np.ndarray | None
    K: np.ndarray
    depth: np.ndarray | None = None
    normals: np.ndarray | None = None
    depth_kind: DepthKind = "metric"
    depth_units: str = "m"
    confidence: np.ndarray | None = None
    name: str = "frame"
    notes: list[str] = field(default_factory=list)
    normals_from_depth: bool = False
    depth_predicted: bool = False
    _shape: tuple[int, int] = field(init=False, repr=False, default=(0, 0))

    def __post_init__(self) -> None:
        shape: tuple[int, int] | None = None
        if self.rgb is not None:
            rgb = np.asarray(self.rgb)
            if rgb.ndim != 3 or rgb.shape[2] != 3:
                raise InvalidInput(f"{self.name}: rgb must have shape (H, W, 3), got {rgb.shape}")
            if rgb.dtype != np.uint8:
                raise InvalidInput(f"{self.name}: rgb must be uint8, got {rgb.dtype}")
            self.rgb = np.ascontiguousarray(rgb)
            shape = rgb.shape[:2]
        if self.depth is not None:
            depth = np.asarray(self.depth)
            if depth.ndim != 2:
                raise InvalidInput(f"{self.name}: depth must have shape (H, W), got {depth.shape}")
            if shape is not None and depth.shape != shape:
                raise InvalidInput(
                    f"{self.name}: depth size {depth.shape[1]}x{depth.shape[0]} differs from "
                    f"image size {shape[1]}x{shape[0]}"
                )
            depth = np.ascontiguousarray(depth, dtype=np.float32)
            nonfinite, negative, positive = _depth_counts(depth)
            if nonfinite:
                raise InvalidInput(
                    f"{self.name}: depth contains NaN or inf; mark invalid pixels with 0"
                )
            if negative:
                raise InvalidInput(f"{self.name}: depth has negative values")
            if not positive:
                raise InvalidInput(f"{self.name}: depth has no valid (positive) pixel")
            self.depth = depth
            shape = shape or depth.shape
        if self.normals is not None:
            normals = np.asarray(self.normals)
            if normals.ndim != 3 or normals.shape[2] != 3:
                raise InvalidInput(
                    f"{self.name}: normals must have shape (H, W, 3), got {normals.shape}"
                )
            if shape is not None and normals.shape[:2] != shape:
                raise InvalidInput(
                    f"{self.name}: normals size {normals.shape[1]}x{normals.shape[0]} differs "
                    f"from image size {shape[1]}x{shape[0]}"
                )
            normals = np.ascontiguousarray(normals, dtype=np.float32)
            nonfinite, bad = _normal_counts(normals)
            if nonfinite:
                raise InvalidInput(f"{self.name}: normals contain NaN or inf")
            if bad:
                raise InvalidInput(
                    f"{self.name}: normals must be unit length (or all-zero where invalid); "
                    f"{bad} pixels are not"
                )
            self.normals = normals
            shape = shape or normals.shape[:2]
        if self.confidence is not None:
            conf = np.asarray(self.confidence, dtype=np.float32)
            if shape is not None and conf.shape != shape:
                raise InvalidInput(f"{self.name}: confidence must have shape {shape}")
            self.confidence = conf
        if shape is None:
            raise InvalidInput(f"{self.name}: a frame needs at least an image or a depth map")
        self._shape = (int(shape[0]), int(shape[1]))
        self.K = _check_K(self.K, f"{self.name}: K")
        if self.depth_kind not in DEPTH_KINDS:
            raise InvalidInput(
                f"{self.name}: depth_kind must be one of {', '.join(DEPTH_KINDS)}, "
                f"got {self.depth_kind!r}"
            )

    @property
    def height(self) -> int:
        """Image height H in pixels."""
        return self._shape[0]

    @property
    def width(self) -> int:
        """Image width W in pixels."""
        return self._shape[1]

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self._shape

    @property
    def depth_measured(self) -> bool:
        """True when ``depth`` is a sensor's metric measurement: neither predicted by a network
        (``depth_predicted``) nor relative (a relative depth comes from a network or a
        simulation of one, never from a range sensor). False without depth."""
        return self.depth is not None and self.depth_kind == "metric" and not self.depth_predicted

    @property
    def normals_from_sensor_depth(self) -> bool:
        """True when ``normals`` were estimated from a measured depth (``normals_from_depth``
        and :attr:`depth_measured`): an organised sensor frame, which the defaults search on
        its pixel lattice with the normal gate (docs/design.md, "Depth-only sensor frames")."""
        return self.normals_from_depth and self.depth_measured

    @property
    def has_color(self) -> bool:
        """True when the frame has an RGB image that is not grey (all channels equal)."""
        if self.rgb is None:
            return False
        rgb = self.rgb
        return bool(np.any(rgb[..., 0] != rgb[..., 1]) or np.any(rgb[..., 1] != rgb[..., 2]))

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool mask of pixels with a valid depth (and normal, when normals exist)."""
        if self.depth is None:
            raise InvalidInput(f"{self.name}: frame has no depth yet")
        # One compiled pass: numpy's any over the normals' axis of 3 costs ~9 ms at 640x480.
        # The arrays are float32 and C-contiguous unless a field was reassigned; asarray then
        # converts (positive and non-zero are kept by a float32 cast of float64 only above
        # ~1e-45, which no depth or unit normal reaches).
        depth = np.ascontiguousarray(self.depth, dtype=np.float32)
        if self.normals is None:
            return depth > 0
        return _valid_mask(depth, np.ascontiguousarray(self.normals, dtype=np.float32))

    def points(self) -> np.ndarray:
        """Unproject the depth map.

        Returns
        -------
        numpy.ndarray
            (H, W, 3) float64 camera-frame points (OpenCV axes) in depth units; invalid pixels
            are at the origin.
        """
        if self.depth is None:
            raise InvalidInput(f"{self.name}: frame has no depth yet")
        return pixel_rays(self.K, *self.shape) * self.depth[..., None].astype(np.float64)

    def with_(self, **changes: object) -> Frame:
        """Return a validated copy with some fields replaced."""
        return replace(self, **changes)  # type: ignore[arg-type]


# Frame validation runs on every frame (and every ``with_``); one compiled pass per array
# replaces the half-dozen numpy passes of the checks (6 ms at 640x480).


@kernel
def _depth_counts(depth: np.ndarray) -> tuple[int, int, int]:
    """(non-finite, negative, positive) pixel counts of a (H, W) float32 depth map (C order).

    Counted without branches (``d - d == 0`` only for finite ``d``), so the compiler
    vectorises the loop: about a fifth of the time of one branch per pixel at 640x480.
    """
    flat = depth.ravel()
    nonfinite = negative = positive = 0
    for i in range(flat.shape[0]):
        d = flat[i]
        finite = d - d == 0
        nonfinite += 0 if finite else 1
        negative += 1 if finite & (d < 0) else 0
        positive += 1 if finite & (d > 0) else 0
    return nonfinite, negative, positive


@kernel
def _normal_counts(normals: np.ndarray) -> tuple[int, int]:
    """(H, W, 3) float32 normals (C order): pixels with a non-finite component, and non-zero
    normals whose length differs from 1 by more than 1e-2 (computed in float32, as numpy's
    norm is). Branch-free like :func:`_depth_counts`."""
    flat = normals.ravel()
    nonfinite = bad = 0
    tol, one = np.float32(1e-2), np.float32(1.0)
    for i in range(flat.shape[0] // 3):
        x, y, z = flat[3 * i], flat[3 * i + 1], flat[3 * i + 2]
        norm = np.sqrt(x * x + y * y + z * z)
        finite = (x - x == 0) & (y - y == 0) & (z - z == 0)
        nonfinite += 0 if finite else 1
        bad += 1 if finite & (norm > 0) & (abs(norm - one) > tol) else 0
    return nonfinite, bad


@kernel
def _valid_mask(depth: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(H, W) bool: ``depth`` (H, W) float32 positive and ``normals`` (H, W, 3) float32 not
    all-zero, as ``(depth > 0) & np.any(normals != 0, axis=-1)`` gives."""
    h, w = depth.shape
    out = np.empty((h, w), dtype=np.bool_)
    for y in range(h):
        for x in range(w):
            out[y, x] = depth[y, x] > 0 and (normals[y, x, 0] != 0 or normals[y, x, 1] != 0
                                             or normals[y, x, 2] != 0)
    return out
