"""Old import paths of modules that moved in 0.2.0, kept working until 0.3.0.

``import monoplane.ransac`` (or ``from monoplane.fileio import load_frame``) still works: the
finder below hands back the module at its new path, under the old name too, with a
:class:`DeprecationWarning` that names the new path. ``CHANGELOG.md`` lists the moves; the
aliases go in 0.3.0.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from types import ModuleType

#: Old module path -> new module path.
MOVED: dict[str, str] = {
    "monoplane.batch.pool": "monoplane.host.pool",
    "monoplane.batch.views": "monoplane.host.view_pool",
    "monoplane.bench": "monoplane.evaluation.bench",
    "monoplane.bench_data": "monoplane.evaluation.bench_frames",
    "monoplane.cloud_config": "monoplane.host.cloud_config",
    "monoplane.cloud_files": "monoplane.io.clouds",
    "monoplane.config": "monoplane.host.config",
    "monoplane.config_fields": "monoplane.contracts.config_fields",
    "monoplane.densecrf": "monoplane.algorithm.densecrf",
    "monoplane.detect": "monoplane.host.detect",
    "monoplane.fileio": "monoplane.io.frames",
    "monoplane.geometry.planarity": "monoplane.geometry.flatness",
    "monoplane.graphcut": "monoplane.algorithm.graphcut",
    "monoplane.io_checks": "monoplane.io.checks",
    "monoplane.lattice_kernels": "monoplane.algorithm.lattice_kernels",
    "monoplane.mincut": "monoplane.algorithm.mincut",
    "monoplane.multiview.fusion": "monoplane.multiview.global_planes",
    "monoplane.pipeline": "monoplane.host.pipeline",
    "monoplane.planarity": "monoplane.algorithm.planarity",
    "monoplane.plugin_manager": "monoplane.host.registry",
    "monoplane.ransac": "monoplane.algorithm.ransac",
    "monoplane.regions": "monoplane.algorithm.regions",
    "monoplane.stages.base": "monoplane.contracts",
    "monoplane.stages.cues": "monoplane.stages.cue_providers",
}


class _Alias(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds an old module path and loads it as the module at its new path."""

    def __init__(self) -> None:
        self._specs: dict[str, importlib.machinery.ModuleSpec | None] = {}

    def find_spec(self, fullname: str, path: object = None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        if fullname not in MOVED:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        new = MOVED[spec.name]
        # warnings skips importlib's own frames, so level 2 is the importing line
        warnings.warn(f"{spec.name} moved to {new}; the old path goes in 0.3.0",
                      DeprecationWarning, stacklevel=2)
        module = importlib.import_module(new)
        self._specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        """Nothing to run: the module is loaded. Only its own spec goes back, which the import
        system replaced with the alias's (pickling and ``importlib.reload`` read it)."""
        module.__spec__ = self._specs.pop(module.__spec__.name)


def install() -> None:
    """Put the alias finder last on ``sys.meta_path`` (once), after the real path finders."""
    if not any(isinstance(finder, _Alias) for finder in sys.meta_path):
        sys.meta_path.append(_Alias())

