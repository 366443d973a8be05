"""monoplane: planar 3D reconstruction from one or a few images (MonoPlane, IROS 2024)."""

__version__ = "0.1.0"  # before the imports: submodules read it lazily

from monoplane.detect import detect_planes  # noqa: E402
from monoplane.errors import ConfigError, InvalidInput, MonoplaneError, StageError  # noqa: E402
from monoplane.hookspecs import hookimpl  # noqa: E402
from monoplane.io import load_frame, save_reconstruction  # noqa: E402
from monoplane.pipeline import Pipeline  # noqa: E402
from monoplane.types import Camera, Frame, Reconstruction, Scene  # noqa: E402

__all__ = [
    "Camera", "ConfigError", "Frame", "InvalidInput", "MonoplaneError", "Pipeline",
    "Reconstruction", "Scene", "StageError", "detect_planes", "hookimpl", "load_frame",
    "save_reconstruction", "__version__",
]
