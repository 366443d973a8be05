"""ONNX model profiles: how to feed a monocular network and how to read what it returns.

A :class:`ModelSpec` describes one network (input box, resize policy, normalisation, output
kind and encoding); an :class:`OnnxProfile` pairs a depth network with an optional normals
network. Profiles carry no weights and no file paths: users export their own models (see
``docs/cues.md``) and point the config at them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Literal

from monoplane.errors import ConfigError

OutputKind = Literal["metric_depth", "relative_depth", "inverse_depth", "point_map", "normals"]
#: What a network's output means.
#:
#: * ``metric_depth``: z-depth in metres (times ``ModelSpec.depth_scale``).
#: * ``relative_depth``: z-depth up to an unknown scale (affine-invariant networks are treated
#:   as shift-free).
#: * ``inverse_depth``: relative disparity ``∝ 1/z`` (MiDaS, Depth Anything).
#: * ``point_map``: an affine-invariant camera-frame point map (N, H, W, 3) whose z is known up
#:   to a shift, with the principal point at the image centre (MoGe); focal length and shift are
#:   recovered by :mod:`monoplane.cues.pointmap`, the metric scale read from ``scale_output``.
#: * ``normals``: a 3-channel normal map, see ``normal_encoding`` and ``normal_axes``.
OUTPUT_KINDS: tuple[str, ...] = ("metric_depth", "relative_depth", "inverse_depth", "point_map",
                                 "normals")
RESIZE_POLICIES: tuple[str, ...] = ("keep_aspect", "stretch")
NORMAL_ENCODINGS: tuple[str, ...] = ("signed", "unsigned")
LAYOUTS: tuple[str, ...] = ("NCHW", "NHWC")
COLOUR_ORDERS: tuple[str, ...] = ("RGB", "BGR")

IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


def parse_axes(axes: str) -> tuple[tuple[int, float], ...]:
    """Parse a normal axis convention such as ``"x,-y,-z"``.

    Entry ``i`` names the model output channel (and sign) that becomes camera axis ``i`` of
    OpenCV's frame (x right, y down, z forward). ``"x,y,z"`` is OpenCV itself; ``"x,-y,-z"`` is
    OpenGL's (y up, z backwards).

    Returns
    -------
    tuple
        Three ``(channel index, sign)`` pairs.
    """
    parts = [p.strip().lower() for p in axes.split(",")]
    out = []
    for p in parts:
        sign = -1.0 if p.startswith("-") else 1.0
        name = p.lstrip("+-")
        if name not in ("x", "y", "z"):
            break
        out.append(("xyz".index(name), sign))
    if len(parts) != 3 or len(out) != 3 or len({c for c, _ in out}) != 3:
        raise ConfigError(
            f"normal axes must map camera x,y,z to a permutation of the model's x,y,z with "
            f"optional signs, e.g. 'x,-y,-z'; got {axes!r}"
        )
    return tuple(out)


@dataclass(frozen=True)
class ModelSpec:
    """How to run one ONNX network and interpret its output.

    Attributes
    ----------
    output : str
        One of :data:`OUTPUT_KINDS`.
    size : tuple of int
        ``(height, width)`` input box in pixels. A model exported with fixed spatial input
        dimensions overrides it with its own.
    resize : str
        ``"keep_aspect"``: scale the image to fit the box, then pad bottom/right by edge
        replication up to a multiple of ``multiple_of`` (or to the fixed input size);
        ``"stretch"``: resize to the box (rounded to the multiple), ignoring the aspect ratio.
    multiple_of : int
        The padded input height and width are multiples of this (32 for DPT/CNN decoders,
        14 for ViT-14 backbones such as DINOv2).
    layout : str
        Axis order of the image input: ``"NCHW"`` (channels first, PyTorch exports) or
        ``"NHWC"`` (channels last, TensorFlow/TFLite exports).
    colour_order : str
        Channel order the network expects: ``"RGB"`` or ``"BGR"`` (OpenCV/Caffe-trained).
    value_range : tuple of float
        ``(low, high)``: pixel values 0..255 are mapped linearly onto this range before the
        normalisation, e.g. ``(0, 1)`` or ``(0, 255)``.
    mean, std : tuple of float
        Per-channel normalisation ``(x - mean) / std`` applied to values in ``value_range``, in
        the network's channel order.
    normal_encoding : str
        ``"signed"`` (components in [-1, 1]) or ``"unsigned"`` (``(n + 1) / 2`` in [0, 1]).
    normal_axes : str
        Axis convention of the normals, see :func:`parse_axes`.
    depth_scale : float
        Factor turning a metric output into metres (e.g. 0.001 for millimetres).
    image_input : str or None
        Name of the image input (N, 3, H, W) float32; ``None`` takes the only other input.
    intrinsics_input : str or None
        Name of a (N, 3, 3) float32 intrinsics input (camera-aware networks such as ZeroDepth);
        the intrinsics are rescaled to the network's input resolution.
    output_name : str or None
        Output to read; ``None`` reads the first.
    normals_output : str or None
        A normals output of this same network (joint depth-and-normals networks such as
        Metric3D v2 and MoGe-2), decoded with ``normal_encoding`` and ``normal_axes``; one
        inference gives both cues.
    canonical_focal : float or None
        Metric networks trained on a canonical camera (Metric3D): the output is depth for a
        focal length of ``canonical_focal`` pixels and is multiplied by ``fx / canonical_focal``,
        ``fx`` being the focal length at the network's input resolution.
    mask_output, scale_output : str or None
        ``point_map`` networks: a (N, H, W) validity probability and a (N,) metric scale.
    constant_inputs : tuple of (str, int)
        Extra scalar int64 inputs fed with a fixed value (MoGe's ``num_tokens``).
    """

    output: str
    size: tuple[int, int] = (384, 384)
    resize: str = "keep_aspect"
    multiple_of: int = 32
    layout: str = "NCHW"
    colour_order: str = "RGB"
    value_range: tuple[float, float] = (0.0, 1.0)
    mean: tuple[float, float, float] = (0.5, 0.5, 0.5)
    std: tuple[float, float, float] = (0.5, 0.5, 0.5)
    normal_encoding: str = "signed"
    normal_axes: str = "x,y,z"
    depth_scale: float = 1.0
    image_input: str | None = None
    intrinsics_input: str | None = None
    output_name: str | None = None
    normals_output: str | None = None
    canonical_focal: float | None = None
    mask_output: str | None = None
    scale_output: str | None = None
    constant_inputs: tuple[tuple[str, int], ...] = ()

    def __post_init__(self) -> None:
        if self.output not in OUTPUT_KINDS:
            raise ConfigError(
                f"model output must be one of {', '.join(OUTPUT_KINDS)}, got {self.output!r}")
        if self.resize not in RESIZE_POLICIES:
            raise ConfigError(
                f"resize must be one of {', '.join(RESIZE_POLICIES)}, got {self.resize!r}")
        if self.normal_encoding not in NORMAL_ENCODINGS:
            raise ConfigError(f"normal_encoding must be one of {', '.join(NORMAL_ENCODINGS)}, "
                              f"got {self.normal_encoding!r}")
        if self.layout not in LAYOUTS:
            raise ConfigError(f"layout must be one of {', '.join(LAYOUTS)}, got {self.layout!r}")
        if self.colour_order not in COLOUR_ORDERS:
            raise ConfigError(f"colour_order must be one of {', '.join(COLOUR_ORDERS)}, got "
                              f"{self.colour_order!r}")
        if len(self.value_range) != 2 or not self.value_range[0] < self.value_range[1]:
            raise ConfigError(f"value_range must be [low, high] with low < high, got "
                              f"{list(self.value_range)}")
        if len(self.size) != 2 or min(self.size) < 1:
            raise ConfigError(f"input size must be (height, width) > 0, got {self.size}")
        if self.multiple_of < 1:
            raise ConfigError(f"multiple_of must be >= 1, got {self.multiple_of}")
        if len(self.mean) != 3 or len(self.std) != 3 or min(self.std) <= 0:
            raise ConfigError(f"mean and std need 3 values, std > 0; got {self.mean}, {self.std}")
        if self.depth_scale <= 0:
            raise ConfigError(f"depth_scale must be positive, got {self.depth_scale}")
        if self.canonical_focal is not None and (self.canonical_focal <= 0
                                                 or self.output != "metric_depth"):
            raise ConfigError("canonical_focal needs a metric_depth output and a positive value, "
                              f"got {self.canonical_focal} for {self.output}")
        if (self.mask_output or self.scale_output) and self.output != "point_map":
            raise ConfigError("mask_output and scale_output belong to point_map networks")
        parse_axes(self.normal_axes)

    @property
    def joint_normals(self) -> bool:
        """True when this network also predicts normals (one inference, both cues)."""
        return self.normals_output is not None

    @property
    def is_depth(self) -> bool:
        """True for the three depth-like output kinds."""
        return self.output != "normals"

    def describe(self) -> str:
        """One line naming the expected signature, used in error messages."""
        box = "(1, 3, H, W)" if self.layout == "NCHW" else "(1, H, W, 3)"
        inputs = f"image input {box} float32 named {self.image_input or '<any>'}"
        if self.intrinsics_input:
            inputs += f" and intrinsics input (1, 3, 3) float32 named {self.intrinsics_input}"
        for name, _ in self.constant_inputs:
            inputs += f" and int64 scalar input {name}"
        if self.output == "point_map":
            out = f"a point map output (1, H, W, 3) named {self.output_name or '<first>'}"
            extra = [n for n in (self.mask_output, self.scale_output) if n]
            if extra:
                out += f" and outputs {', '.join(extra)}"
        elif self.is_depth:
            out = f"one {self.output.replace('_', ' ')} output (1, 1, H, W) or (1, H, W)"
            if self.output_name:
                out += f" named {self.output_name}"
        else:
            out = "one normals output (1, 3, H, W) or (1, H, W, 3)"
        if self.normals_output:
            out += f" and a normals output (1, 3, H, W) or (1, H, W, 3) named {self.normals_output}"
        return f"{inputs}; {out}"


@dataclass(frozen=True)
class OnnxProfile:
    """A depth network and an optional normals network that together provide cues.

    Attributes
    ----------
    name : str
        Profile name used in configs (``cues.profile``).
    depth : ModelSpec
        The depth network (any depth-like output kind).
    normals : ModelSpec or None
        The normals network, when the model family has one; without it (or without a model
        file), normals are estimated from the predicted depth.
    hfov_deg : float or None
        Horizontal field of view to assume when the image comes without intrinsics; ``None``
        uses monoplane's default (60°).
    summary : str
        One line for listings and docs.
    """

    name: str
    depth: ModelSpec
    normals: ModelSpec | None = None
    hfov_deg: float | None = None
    summary: str = ""

    def __post_init__(self) -> None:
        if not self.depth.is_depth:
            raise ConfigError(f"profile {self.name!r}: the depth model must output depth")
        if self.normals is not None and self.normals.is_depth:
            raise ConfigError(f"profile {self.name!r}: the normals model must output normals")
        if self.normals is not None and self.depth.joint_normals:
            raise ConfigError(f"profile {self.name!r}: normals come from the depth network "
                              f"({self.depth.normals_output}) or from a second network, not both")

    @property
    def task(self) -> str:
        """``"both"`` when the networks predict normals too, else ``"depth"``."""
        return "both" if self.normals is not None or self.depth.joint_normals else "depth"

    def with_overrides(self, *, size: tuple[int, int] | None = None,
                       mean: tuple[float, float, float] | None = None,
                       std: tuple[float, float, float] | None = None,
                       normal_axes: str | None = None) -> OnnxProfile:
        """Copy with user overrides applied (``size``, ``mean``, ``std`` to both networks)."""
        changes: dict[str, Any] = {
            k: v for k, v in (("size", size), ("mean", mean), ("std", std)) if v}
        depth = replace(self.depth, **changes)
        if normal_axes and depth.joint_normals:
            depth = replace(depth, normal_axes=normal_axes)
        normals = self.normals
        if normals is not None:
            normals = replace(normals, **changes)
            if normal_axes:
                normals = replace(normals, normal_axes=normal_axes)
        return replace(self, depth=depth, normals=normals)
