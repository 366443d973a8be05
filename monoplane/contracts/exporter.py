"""The exporter contract: what one output format states about itself.

An output format is an :class:`Exporter` that a plugin returns from the
``monoplane_register_exporters`` hook (:mod:`monoplane.hookspecs`). The built-in formats are
the modules of :mod:`monoplane.export` that implement the hook, each registering itself
exactly as a third-party package would; :func:`monoplane.export.save` writes every format that
applies to a result.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from monoplane.datamodel import RESULT_KINDS
from monoplane.errors import PluginError

#: Exporter names: lower-case words joined by ``-`` (they are typed after ``--formats``).
_NAME = re.compile(r"[a-z][a-z0-9]*(-[a-z0-9]+)*")


#: ``write(result, folder, shared)``: write the format's files of ``result`` into the existing
#: ``folder`` (a temporary folder that becomes the output once every format is written);
#: ``shared`` is a :class:`monoplane.export.shared.SharedWork`. (Named, not imported: this
#: contract, which the hook specifications name, stays free of the geometry it hands out.)
WriteFn = Callable[[Any, Path, Any], None]


@dataclass(frozen=True)
class Exporter:
    """One output format.

    Attributes
    ----------
    name : str
        Unique name, lower-case words joined by ``-`` (``monoplane plugins`` lists it; the
        ``formats`` of :func:`monoplane.export.save` select by it).
    files : Mapping[str, tuple of str]
        Per result kind it writes (``"frame"``, ``"cloud"``, ``"multiview"``; see
        :data:`monoplane.datamodel.RESULT_KINDS`), the paths it writes relative to the output
        folder; ``view_*/`` stands for every view folder of a multi-view result. A kind that
        is absent is a result the format does not apply to. ``monoplane batch`` counts a frame
        done when every ``"frame"`` file of the default formats is there.
    write : callable
        ``write(result, folder, shared)`` (:data:`WriteFn`): writes exactly ``files[kind]``.
        The views of a multi-view result get the ``"frame"`` formats in their own folders
        from :func:`~monoplane.export.save`; a ``"multiview"`` writer writes the rest.
    default : bool
        Written unless the caller names the formats it wants.
    summary : str
        One line for ``monoplane plugins``.
    """

    name: str
    files: Mapping[str, tuple[str, ...]]
    write: WriteFn
    default: bool = True
    summary: str = ""

    @property
    def kinds(self) -> tuple[str, ...]:
        """The result kinds it writes, in the order of ``files``."""
        return tuple(self.files)

    def check(self, where: str) -> None:
        """Raise :class:`PluginError` (naming ``where``) if the statement is malformed."""
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name):
            raise PluginError(f"{where}: exporter name {self.name!r} must be lower-case words "
                              "joined by '-'")
        bad = [k for k in self.files if k not in RESULT_KINDS or k == "scene"]
        if not self.files or bad:
            raise PluginError(f"{where}: exporter '{self.name}' must state the files it writes "
                              f"for some of the result kinds frame, cloud, multiview"
                              + (f"; unknown kinds: {', '.join(map(str, bad))}" if bad else ""))
        for kind, names in self.files.items():
            if (isinstance(names, str) or not names
                    or not all(isinstance(n, str) and n and not n.startswith("/")
                               for n in names)):
                raise PluginError(f"{where}: exporter '{self.name}' files for {kind} must be a "
                                  "non-empty tuple of relative paths")
        if not callable(self.write):
            raise PluginError(f"{where}: exporter '{self.name}' has no callable write")
