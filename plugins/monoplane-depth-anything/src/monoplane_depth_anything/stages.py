"""The ``depth-anything`` cue provider: relative inverse depth from a Depth Anything ONNX
export, normals estimated from that depth.

Everything model-specific is the :data:`PROFILE` below; loading, letterboxing, onnxruntime
inference, disparity-to-depth conversion and normal estimation are monoplane's public cue
machinery, imported from :mod:`monoplane.plugin` like everything else here. Use it in a
config as::

    [cues]
    plugin = "depth-anything"
    model = "depth_anything_v2_vits.onnx"
"""

from __future__ import annotations

from dataclasses import dataclass

from monoplane.plugin import (
    IMAGENET_MEAN,
    IMAGENET_STD,
    ConfigError,
    CueNetwork,
    ModelSpec,
    NetworkCues,
    OnnxProfile,
    Stage,
    hookimpl,
    param,
)

#: Depth Anything (v1 and v2) predicts affine-invariant inverse depth from ImageNet-normalised
#: RGB; its DINOv2 ViT-14 backbone needs input sides that are multiples of 14 (518 in training).
PROFILE = OnnxProfile(
    name="depth-anything",
    depth=ModelSpec(output="inverse_depth", size=(518, 518), multiple_of=14,
                    mean=IMAGENET_MEAN, std=IMAGENET_STD),
    summary="Depth Anything: relative inverse depth (ViT-14), normals from depth",
)


@dataclass
class DepthAnythingConfig:
    """Parameters of the ``depth-anything`` cue provider."""

    model: str = param("", "path to the Depth Anything .onnx file")
    threads: int = param(2, "onnxruntime CPU threads")
    input_size: int = param(518, "longest input side in pixels (rounded up to a multiple of 14)")
    disparity_floor: float = param(
        0.01, "disparities below this fraction of the median are invalid (sky, far background)")

    def __post_init__(self) -> None:
        if self.threads < 1:
            raise ConfigError(f"threads must be >= 1, got {self.threads}")
        if self.input_size < 14:
            raise ConfigError(f"input_size must be >= 14, got {self.input_size}")
        if not 0 < self.disparity_floor < 1:
            raise ConfigError(f"disparity_floor must be in (0, 1), got {self.disparity_floor}")


class DepthAnythingCues(NetworkCues):
    """Relative depth from Depth Anything; normals estimated from it."""

    name = "depth-anything"
    Config = DepthAnythingConfig

    def build_network(self, config: DepthAnythingConfig) -> CueNetwork:
        """:data:`PROFILE` at the configured input size, on the configured file."""
        profile = PROFILE.with_overrides(size=(config.input_size, config.input_size))
        return CueNetwork(profile, config.model or None, threads=config.threads,
                          disparity_floor=config.disparity_floor, depth_model_key="cues.model")


@hookimpl
def monoplane_register_cue_providers() -> list[type[Stage]]:
    """Register the Depth Anything cue provider with monoplane."""
    return [DepthAnythingCues]
