"""The baseline registry for ``monoplane eval`` and ``monoplane bench``: every baseline the
plugins register, by name, and running one with its options.

Baselines register through the pluggy hook ``monoplane_register_baselines`` (see
:mod:`monoplane.hookspecs`), like every other extension point: a plugin returns a dict from
method name (what users pass to ``--baseline``) to callable. What a baseline is and the
settings it shares with the pipeline are in :mod:`monoplane.evaluation.baseline_base`; the
built-in ``open3d-ransac`` is the plugin :mod:`monoplane.evaluation.open3d_baseline`, which
this module registers on the plugin manager it reads (:data:`BUILTIN_BASELINES`), so that the
core registry (:mod:`monoplane.host.registry`) loads no evaluation module. Both modules'
public names can be imported from here too. Use :func:`run_baseline` to run one by
name::

    from monoplane.evaluation.baselines import run_baseline
    rec = run_baseline("open3d-ransac", frame, seed=0, options={"epsilon": 0.01})
"""

from __future__ import annotations

import functools
import importlib
import time
from collections.abc import Mapping, Sequence
from typing import Any

import pluggy

from monoplane.datamodel import Frame, Reconstruction
from monoplane.errors import ConfigError, PluginError
from monoplane.evaluation.baseline_base import (
    CALL_TIMING,
    Baseline,
    RansacBaselineSettings,
    baseline_config,
)
from monoplane.evaluation.open3d_baseline import Open3DRansacConfig, open3d_ransac
from monoplane.host.config import parse_override
from monoplane.host.registry import get_plugin_manager

__all__ = [
    "BUILTIN_BASELINES", "CALL_TIMING", "Baseline", "Open3DRansacConfig",
    "RansacBaselineSettings", "baseline_config", "baseline_names", "bind_baseline",
    "get_baseline", "open3d_ransac", "parse_baseline_options", "registered_baselines",
    "run_baseline", "with_builtin_baselines",
]


#: The built-in baseline plugins: evaluation registers them on the plugin manager it reads.
BUILTIN_BASELINES: tuple[str, ...] = ("monoplane.evaluation.open3d_baseline",)


def with_builtin_baselines(pm: pluggy.PluginManager) -> pluggy.PluginManager:
    """``pm`` with the modules of :data:`BUILTIN_BASELINES` registered (once), under their
    module names, as :func:`~monoplane.host.registry.get_plugin_manager` registers the
    built-in stages."""
    for modname in BUILTIN_BASELINES:
        module = importlib.import_module(modname)
        if not pm.is_registered(module):
            pm.register(module, name=modname)
    return pm


def registered_baselines(pm: pluggy.PluginManager | None = None) -> dict[str, Baseline]:
    """Every baseline the plugin manager knows, by name, the built-in ones included.

    Parameters
    ----------
    pm : pluggy.PluginManager, optional
        Defaults to :func:`monoplane.host.registry.get_plugin_manager` (built-ins, plus
        installed plugins unless autoloading is disabled). The built-in baselines are
        registered on it (:func:`with_builtin_baselines`).

    Raises
    ------
    PluginError
        When a plugin returns something else than a name -> callable dict, or two plugins
        register the same name.
    """
    pm = with_builtin_baselines(pm or get_plugin_manager())
    found: dict[str, Baseline] = {}
    for impl in pm.hook.monoplane_register_baselines.get_hookimpls():
        table = impl.function() or {}
        if not isinstance(table, dict):
            raise PluginError(f"plugin '{impl.plugin_name}': monoplane_register_baselines must "
                              f"return a dict of name -> callable, got {type(table).__name__}")
        for name, fn in table.items():
            if not callable(fn):
                raise PluginError(f"plugin '{impl.plugin_name}': baseline '{name}' is not "
                                  "callable")
            if name in found:
                raise PluginError(f"plugin '{impl.plugin_name}' registers baseline '{name}', "
                                  "which another plugin registered already")
            found[name] = fn
    return found


def baseline_names(pm: pluggy.PluginManager | None = None) -> list[str]:
    """Names of every available baseline, sorted."""
    return sorted(registered_baselines(pm))


def get_baseline(name: str, pm: pluggy.PluginManager | None = None) -> Baseline:
    """The baseline registered as ``name``.

    Raises
    ------
    ConfigError
        When no baseline has that name (the message lists the valid ones).
    """
    table = registered_baselines(pm)
    if name not in table:
        raise ConfigError(f"unknown baseline '{name}'; valid choices: "
                          f"{', '.join(sorted(table)) or '(none)'}")
    return table[name]


def parse_baseline_options(exprs: Sequence[str], names: Sequence[str],
                           all_baselines: bool = False) -> dict[str, dict[str, Any]]:
    """Parse ``--baseline-set NAME.FIELD=VALUE`` expressions into options per baseline.

    Parameters
    ----------
    exprs : sequence of str
        Expressions; the value is read as a TOML value (``0.001``, ``true``, ``"text"``).
    names : sequence of str
        The baselines being run: every expression must name one of them.
    all_baselines : bool
        Every registered baseline runs too (``--all``), after ``names``.

    Returns
    -------
    dict
        Baseline name -> {field: value}; later expressions win.

    Raises
    ------
    ConfigError
        On a malformed expression or one naming a baseline that is not being run.
    """
    names = list(dict.fromkeys([*names, *(baseline_names() if all_baselines else [])]))
    out: dict[str, dict[str, Any]] = {}
    for expr in exprs:
        try:
            name, key, value = parse_override(expr)
        except ConfigError:
            raise ConfigError(f"--baseline-set {expr!r} must look like NAME.FIELD=VALUE, e.g. "
                              "cgal.min_support=0.001") from None
        if name not in names:
            raise ConfigError(f"--baseline-set {expr!r}: '{name}' is not a baseline of this "
                              f"run; baselines run: {', '.join(names) or '(none)'}")
        out.setdefault(name, {})[key] = value
    return out


def bind_baseline(name: str, options: Mapping[str, Any] | None = None,
                  pm: pluggy.PluginManager | None = None) -> Baseline:
    """The baseline ``name`` with its keyword ``options`` fixed.

    When the baseline exposes its settings dataclass as ``config_class``, the options are
    checked now (:func:`baseline_config`), not on the first frame.

    Returns
    -------
    callable
        ``fn(frame, *, seed=0) -> Reconstruction``.

    Raises
    ------
    ConfigError
        Unknown baseline name, or (with ``config_class``) an unknown or ill-typed option.
    """
    fn = get_baseline(name, pm)
    if not options:
        return fn
    config_class = getattr(fn, "config_class", None)
    if config_class is not None:
        baseline_config(config_class, options, name)
    return functools.partial(fn, **options)


def run_baseline(name: str, frame: Frame, seed: int = 0,
                 pm: pluggy.PluginManager | None = None,
                 options: Mapping[str, Any] | None = None) -> Reconstruction:
    """Run the baseline ``name`` on a cue-filled frame.

    Parameters
    ----------
    options : mapping, optional
        Keyword options of the baseline (fields of its settings to override).

    Returns
    -------
    Reconstruction
        The baseline's planes; ``timings["total"]`` holds the wall time of the whole call and
        ``timings["baseline.call"]`` (when the baseline reports it) its core call alone.
    """
    fn = bind_baseline(name, options, pm)
    start = time.perf_counter()
    rec = fn(frame, seed=seed)
    rec.timings.setdefault("total", time.perf_counter() - start)
    return rec
