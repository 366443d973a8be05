"""Depth Anything cue provider for monoplane (also a template for third-party cue plugins)."""

from monoplane_depth_anything.stages import PROFILE, DepthAnythingConfig, DepthAnythingCues

__version__ = "0.1.0"

__all__ = ["PROFILE", "DepthAnythingConfig", "DepthAnythingCues", "__version__"]
