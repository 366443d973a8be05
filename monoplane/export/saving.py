"""``save(result, folder)``: every output format that applies to a result, written atomically.

The formats come from the ``monoplane_register_exporters`` hook: the built-in modules
(:func:`builtin_exporters`: every module of :mod:`monoplane.export` that implements the hook)
and any third-party package of the ``monoplane`` entry-point group, alike. ``monoplane run``,
``cloud`` and ``multiview`` write their folders with :func:`save`, so a Python caller gets
exactly what the command line writes.
"""

from __future__ import annotations

import functools
import importlib
import pkgutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pluggy

from monoplane.contracts.exporter import Exporter
from monoplane.errors import ConfigError, InvalidInput, PluginError
from monoplane.export.files import atomic_output_dir
from monoplane.export.shared import SharedWork
from monoplane.host.registry import Registry, get_plugin_manager
from monoplane.version import __version__


@functools.cache
def builtin_exporters() -> tuple[str, ...]:
    """The built-in output formats: the modules of :mod:`monoplane.export` that implement the
    ``monoplane_register_exporters`` hook, by name.

    Found rather than listed, so that a new format is its module (and its test) alone.
    """
    found = []
    for info in pkgutil.iter_modules([str(Path(__file__).parent)]):
        module = importlib.import_module(f"monoplane.export.{info.name}")
        if hasattr(module, "monoplane_register_exporters"):
            found.append(module.__name__)
    return tuple(found)


@dataclass(frozen=True)
class ExporterInfo:
    """One registered output format and who provides it.

    Attributes
    ----------
    exporter : Exporter
    provider : str
        Distribution (package) that provides it, or the plugin's name when not installed.
    version : str
        Provider version, or ``""`` when unknown.
    """

    exporter: Exporter
    provider: str
    version: str


def _plugin_manager(pm: pluggy.PluginManager | None) -> pluggy.PluginManager:
    """``pm`` (a fresh default one when None) with the built-in exporters registered."""
    pm = pm if pm is not None else get_plugin_manager()
    for name in builtin_exporters():
        if pm.get_plugin(name) is None:
            pm.register(importlib.import_module(name), name=name)
    return pm


def get_exporters(pm: pluggy.PluginManager | None = None) -> list[ExporterInfo]:
    """Every registered output format: the built-ins by module name, then the plugins'.

    Parameters
    ----------
    pm : pluggy.PluginManager, optional
        Plugin manager (default: a fresh one with the built-ins and, unless disabled, the
        entry-point plugins); the built-in exporters are added to it if missing.

    Raises
    ------
    PluginError
        A plugin registered something that is not a well-formed :class:`Exporter`, or two
        plugins registered the same name.
    """
    pm = _plugin_manager(pm)
    dists = {id(plugin): dist for plugin, dist in pm.list_plugin_distinfo()}
    found: dict[str, ExporterInfo] = {}
    for impl in pm.hook.monoplane_register_exporters.get_hookimpls():  # registration order
        where = f"plugin '{impl.plugin_name}'"
        provider, version = Registry._provider(impl.plugin, impl.plugin_name, dists,
                                               set(builtin_exporters()))
        if provider == "monoplane":
            version = __version__
        for exporter in impl.function() or []:
            if not isinstance(exporter, Exporter):
                raise PluginError(f"{where} registered {exporter!r} as an exporter, but it is "
                                  "not a monoplane.plugin.Exporter")
            exporter.check(where)
            known = found.get(exporter.name)
            if known is not None and known.exporter is not exporter:
                raise PluginError(f"exporter '{exporter.name}' is registered twice: by "
                                  f"{known.provider} and by {provider}")
            found[exporter.name] = ExporterInfo(exporter, provider, version)
    return list(found.values())


def select_exporters(kind: str, formats: Sequence[str] | None = None,
                     pm: pluggy.PluginManager | None = None) -> list[Exporter]:
    """The formats to write for a result of ``kind``.

    Parameters
    ----------
    kind : str
        ``"frame"``, ``"cloud"`` or ``"multiview"``.
    formats : sequence of str, optional
        Exporter names; default every format that is on by default and applies to ``kind``.
        For a multi-view result a name may apply to its views only (``"depth"``).
    pm : pluggy.PluginManager, optional
        See :func:`get_exporters`.

    Raises
    ------
    ConfigError
        An unknown name (the message lists the valid ones), or a format that writes neither
        this kind of result nor, for a multi-view result, its views.
    """
    infos = get_exporters(pm)
    writes = {"multiview": ("multiview", "frame")}.get(kind, (kind,))
    if formats is None:
        return [i.exporter for i in infos
                if i.exporter.default and any(k in i.exporter.files for k in writes)]
    by_name = {i.exporter.name: i.exporter for i in infos}
    chosen = []
    for name in formats:
        if name not in by_name:
            raise ConfigError(f"unknown output format {name!r}; valid formats: "
                              f"{', '.join(sorted(by_name))}")
        if not any(k in by_name[name].files for k in writes):
            raise ConfigError(f"output format {name!r} does not write {kind} results (it "
                              f"writes {', '.join(by_name[name].kinds)})")
        chosen.append(by_name[name])
    return chosen


def output_files(kind: str, formats: Sequence[str] | None = None,
                 pm: pluggy.PluginManager | None = None) -> tuple[str, ...]:
    """The paths :func:`save` writes for a result of ``kind`` (relative to its folder).

    ``view_*/`` stands for every view folder of a multi-view result. ``monoplane batch``
    counts a frame done when every ``output_files("frame")`` file is there.
    """
    files: list[str] = []
    for exporter in select_exporters(kind, formats, pm):
        files += exporter.files.get(kind, ())
        if kind == "multiview":
            files += [f"view_*/{name}" for name in exporter.files.get("frame", ())]
    return tuple(files)


def write_outputs(result: Any, folder: Path, exporters: Sequence[Exporter]) -> None:
    """Write ``exporters``' files of ``result`` into the existing ``folder`` (not atomic by
    itself: :func:`save` wraps it).

    A multi-view result's views go to ``folder/view_000``, ... with the formats that apply to
    frames, then the formats that apply to multi-view results write the rest.
    """
    kind = getattr(result, "result_kind", "")
    shared = SharedWork()
    if kind == "multiview":
        for v, rec in enumerate(result.scene.views):
            sub = folder / f"view_{v:03d}"
            sub.mkdir()
            for exporter in exporters:
                if "frame" in exporter.files:
                    exporter.write(rec, sub, shared)
    for exporter in exporters:
        if kind in exporter.files:
            exporter.write(result, folder, shared)


def save(result: Any, folder: str | Path, overwrite: bool = False, *,
         formats: Sequence[str] | None = None, also: Callable[[Path], object] | None = None,
         pm: pluggy.PluginManager | None = None) -> Path:
    """Write a result's outputs atomically into ``folder``: what the command line writes.

    Parameters
    ----------
    result : Reconstruction, CloudResult or MultiviewResult
        What ``Pipeline.run``, ``detect_planes`` or ``reconstruct_multiview`` returned; told
        apart by its ``result_kind``.
    folder : str or Path
        Target folder; must not exist (or be empty) unless ``overwrite``. Missing parents are
        created.
    overwrite : bool
        Replace an existing folder (only once the new one is complete).
    formats : sequence of str, optional
        Exporter names to write (``monoplane plugins`` lists them); default every format that
        is on by default and applies to the result.
    also : callable, optional
        Writes more files into the folder, given its temporary path, before the folder is put
        in place, so that they appear with the outputs or not at all (the commands pass their
        HTML report this way).
    pm : pluggy.PluginManager, optional
        Where the exporters come from (default: the built-ins and the entry-point plugins).

    Returns
    -------
    Path
        The output folder.

    Raises
    ------
    InvalidInput
        ``result`` is not a result monoplane can write, or ``folder`` cannot be an output
        folder (an existing file, a non-empty folder without ``overwrite``).
    ConfigError
        An unknown or inapplicable name in ``formats``.
    """
    kind = getattr(result, "result_kind", "")
    if kind not in ("frame", "cloud", "multiview"):
        raise InvalidInput(f"save: cannot write a {type(result).__name__}; give a "
                           "Reconstruction, CloudResult or MultiviewResult")
    exporters = select_exporters(kind, formats, pm)
    with atomic_output_dir(folder, overwrite) as tmp:
        write_outputs(result, tmp, exporters)
        if also is not None:
            also(tmp)
    return Path(folder)
