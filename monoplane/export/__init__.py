"""Writing results: one :func:`save` for every result, and one module per output format.

``monoplane.export.save(result, folder)`` writes a frame's, a point cloud's or a multi-view
result's folder exactly as the command line does, atomically. The formats are plugins of the
``monoplane_register_exporters`` hook (:mod:`monoplane.hookspecs`); the built-in ones are the
modules :mod:`.labels` (label maps, ``planes.json``, ``scene.json``), :mod:`.ply`, :mod:`.gltf`,
:mod:`.depth`, :mod:`.config_file` and :mod:`.rerun_log` (optional extra ``rerun``), over the
shared writers of :mod:`.files`.

The names below are loaded on first use, so that importing one format's module does not load
the plugin system.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

#: Name -> the module that defines it.
_LAZY = {
    "save": "monoplane.export.saving",
    "get_exporters": "monoplane.export.saving",
    "output_files": "monoplane.export.saving",
    "Exporter": "monoplane.contracts.exporter",
}

__all__ = ["Exporter", "get_exporters", "output_files", "save"]

if TYPE_CHECKING:
    from monoplane.contracts.exporter import Exporter
    from monoplane.export.saving import get_exporters, output_files, save


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'monoplane.export' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
