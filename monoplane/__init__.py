"""monoplane: planar 3D reconstruction from one or a few images (MonoPlane, IROS 2024)."""

from monoplane.errors import ConfigError, InvalidInput, MonoplaneError, StageError
from monoplane.hookspecs import hookimpl
from monoplane.types import Camera, Frame, Reconstruction, Scene

__version__ = "0.1.0"

__all__ = [
    "Camera", "ConfigError", "Frame", "InvalidInput", "MonoplaneError", "Reconstruction",
    "Scene", "StageError", "hookimpl", "__version__",
]
