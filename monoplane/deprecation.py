"""Deprecated aliases of public names renamed or moved in 0.2.0, until 0.3.0.

Moved *modules* are aliased by :mod:`monoplane.moved_modules`, which names every module and so
sits apart; this module names none, so any layer may use it.
"""

from __future__ import annotations

import importlib
import warnings
from collections.abc import Callable
from typing import Any


def renamed_names(module: str, renames: dict[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for public names renamed or moved in 0.2.0.

    Parameters
    ----------
    module : str
        The module's own dotted name, for messages.
    renames : dict
        Old name -> new location ``"package.module:name"``, imported on first use (so a
        target that loads OpenCV or Open3D costs nothing until the old name is asked for).

    Returns
    -------
    callable
        ``__getattr__(name)``: the new object, with a ``DeprecationWarning`` at the caller's
        line, or ``AttributeError`` for any other name.
    """

    def __getattr__(name: str) -> Any:
        target = renames.get(name)
        if target is None:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        path, new = target.split(":")
        warnings.warn(f"{module}.{name} is now {path}.{new}; the old name goes in 0.3.0",
                      DeprecationWarning, stacklevel=2)
        return getattr(importlib.import_module(path), new)

    return __getattr__
