"""monoplane: planar 3D reconstruction from one or a few images (MonoPlane, IROS 2024).

The names below are loaded on first use, so that ``import monoplane.datamodel`` (or any other
small module) does not pull in the pipeline, OpenCV and the plugin system.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from monoplane import moved_modules

moved_modules.install()

#: Module -> the public names it defines.
_MODULES: dict[str, tuple[str, ...]] = {
    "monoplane.host.detect": ("detect_planes",),
    "monoplane.export.rerun_log": ("log_rerun",),
    "monoplane.export.saving": ("save",),
    "monoplane.errors": ("ConfigError", "InvalidInput", "MonoplaneError", "StageError"),
    "monoplane.hookspecs": ("hookimpl",),
    "monoplane.io.frames": ("load_frame", "save_reconstruction"),
    "monoplane.host.pipeline": ("Pipeline",),
    "monoplane.datamodel": ("Camera", "CloudResult", "Frame", "Reconstruction", "Scene"),
    "monoplane.version": ("__version__",),
}
_LAZY = {name: module for module, names in _MODULES.items() for name in names}

__all__ = [
    "Camera", "CloudResult", "ConfigError", "Frame", "InvalidInput", "MonoplaneError",
    "Pipeline", "Reconstruction", "Scene", "StageError", "detect_planes", "hookimpl",
    "load_frame", "log_rerun", "save", "save_reconstruction", "__version__",
]

if TYPE_CHECKING:
    from monoplane.datamodel import Camera, CloudResult, Frame, Reconstruction, Scene
    from monoplane.errors import ConfigError, InvalidInput, MonoplaneError, StageError
    from monoplane.export.rerun_log import log_rerun
    from monoplane.export.saving import save
    from monoplane.hookspecs import hookimpl
    from monoplane.host.detect import detect_planes
    from monoplane.host.pipeline import Pipeline
    from monoplane.io.frames import load_frame, save_reconstruction
    from monoplane.version import __version__


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'monoplane' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
