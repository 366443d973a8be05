"""The pluggy plugin manager and the registry of stages it collects.

Built-in stages register exactly like third-party ones: each module in :data:`DEFAULT_PLUGINS`
implements the registration hooks of :mod:`monoplane.hookspecs`, as pytest's default plugins
do. Third-party packages are found through the ``monoplane`` entry-point group unless the
environment variable :data:`AUTOLOAD_ENV` is set (to any non-empty value), which makes runs and
tests reproducible regardless of what else is installed.

Nothing is loaded at import time; call :func:`get_plugin_manager` or :func:`get_registry`.
"""

from __future__ import annotations

import dataclasses
import importlib
import os
from dataclasses import dataclass
from typing import Any

import pluggy

from monoplane import hookspecs
from monoplane.contracts import KINDS, STAGE_KINDS, Stage
from monoplane.errors import ConfigError, PluginError
from monoplane.version import __version__

#: The built-in stage modules, registered in this order. The one place that names them. The
#: built-in baseline is evaluation's, which registers it when evaluation runs
#: (:data:`monoplane.evaluation.baselines.BUILTIN_BASELINES`): the core loads no evaluation code.
DEFAULT_PLUGINS: tuple[str, ...] = (
    "monoplane.stages.cue_providers",
    "monoplane.stages.samplers",
    "monoplane.stages.scorers",
    "monoplane.stages.labelers",
    "monoplane.stages.refiners",
    "monoplane.stages.graph_refiner",
    "monoplane.stages.features",
    "monoplane.stages.matchers",
    "monoplane.stages.registrars",
    "monoplane.stages.fusers",
    "monoplane.stages.adjusters",
)

#: Set this environment variable to disable entry-point autoloading of third-party plugins.
AUTOLOAD_ENV = "MONOPLANE_DISABLE_PLUGIN_AUTOLOAD"

def autoload_enabled() -> bool:
    """False when :data:`AUTOLOAD_ENV` is set to a non-empty value."""
    return not os.environ.get(AUTOLOAD_ENV)


def get_plugin_manager(autoload: bool | None = None,
                       extra_plugins: tuple[object, ...] = ()) -> pluggy.PluginManager:
    """Build a fresh plugin manager with the built-ins and, optionally, third-party plugins.

    Parameters
    ----------
    autoload : bool, optional
        Load plugins from the ``monoplane`` entry-point group. Defaults to
        :func:`autoload_enabled`.
    extra_plugins : tuple
        Plugin objects or modules to register in addition (handy in tests and notebooks).

    Returns
    -------
    pluggy.PluginManager
    """
    pm = pluggy.PluginManager(hookspecs.PROJECT_NAME)
    pm.add_hookspecs(hookspecs)
    for modname in DEFAULT_PLUGINS:
        pm.register(importlib.import_module(modname), name=modname)
    if autoload if autoload is not None else autoload_enabled():
        try:
            pm.load_setuptools_entrypoints(hookspecs.PROJECT_NAME)
        except Exception as exc:  # an installed plugin that cannot even import
            raise PluginError(f"cannot load a '{hookspecs.PROJECT_NAME}' entry-point plugin: "
                              f"{type(exc).__name__}: {exc}") from exc
    for plugin in extra_plugins:
        pm.register(plugin)
    return pm


@dataclass(frozen=True)
class StageInfo:
    """One registered stage.

    Attributes
    ----------
    kind, name : str
        Stage kind and plugin name.
    cls : type
        The stage class.
    provider : str
        Distribution (package) that provides it, or the plugin's name when not installed.
    version : str
        Provider version, or ``""`` when unknown.
    """

    kind: str
    name: str
    cls: type[Stage]
    provider: str
    version: str


class Registry:
    """All stages known to a plugin manager, by kind and name."""

    def __init__(self, pm: pluggy.PluginManager) -> None:
        self.pm = pm
        dists = {id(plugin): dist for plugin, dist in pm.list_plugin_distinfo()}
        builtin = set(DEFAULT_PLUGINS)
        self._stages: dict[str, dict[str, StageInfo]] = {kind: {} for kind in STAGE_KINDS}
        for kind, spec in KINDS.items():
            for impl in getattr(pm.hook, spec.hook).get_hookimpls():
                provider, version = self._provider(impl.plugin, impl.plugin_name, dists, builtin)
                for cls in impl.function() or []:
                    self._add(StageInfo(kind, getattr(cls, "name", ""), cls, provider, version),
                              impl.plugin_name)

    @staticmethod
    def _provider(plugin: object, plugin_name: str, dists: dict[int, Any],
                  builtin: set[str]) -> tuple[str, str]:
        if plugin_name in builtin:
            return "monoplane", __version__
        dist = dists.get(id(plugin))
        if dist is not None:
            return dist.metadata["name"], dist.version
        return plugin_name, ""

    def _add(self, info: StageInfo, plugin_name: str) -> None:
        cls = info.cls
        where = f"plugin '{plugin_name}'"
        base = KINDS[info.kind].base
        if not isinstance(cls, type) or not issubclass(cls, base) or cls.kind != info.kind:
            raise PluginError(f"{where} registered {cls!r} as a {info.kind}, but it does not "
                              f"subclass monoplane.plugin.{base.__name__}")
        if not info.name:
            raise PluginError(f"{where}: {info.kind} class {cls.__name__} has no name")
        if not dataclasses.is_dataclass(cls.Config):
            raise PluginError(f"{where}: {info.kind} '{info.name}' Config is not a dataclass")
        known = self._stages[info.kind].get(info.name)
        if known is not None and known.cls is not cls:
            raise PluginError(f"{info.kind} '{info.name}' is registered twice: by "
                              f"{known.provider} and by {info.provider}")
        self._stages[info.kind][info.name] = info

    def names(self, kind: str) -> list[str]:
        """Sorted plugin names registered for ``kind``."""
        return sorted(self._stages[kind])

    def get(self, kind: str, name: str) -> StageInfo:
        """Look up a stage, raising :class:`ConfigError` with the valid choices if unknown."""
        if kind not in self._stages:
            raise ConfigError(f"unknown stage kind '{kind}'; valid kinds: "
                              f"{', '.join(STAGE_KINDS)}")
        try:
            return self._stages[kind][name]
        except KeyError:
            choices = ", ".join(self.names(kind)) or "(none registered)"
            raise ConfigError(f"unknown {kind} plugin {name!r}; valid choices: {choices}") from None

    def all(self) -> list[StageInfo]:
        """Every registered stage, in pipeline order of kinds then by name."""
        return [self._stages[k][n] for k in STAGE_KINDS for n in self.names(k)]


def get_registry(pm: pluggy.PluginManager | None = None) -> Registry:
    """Registry of a plugin manager (a fresh default one when ``pm`` is None)."""
    return Registry(pm if pm is not None else get_plugin_manager())
