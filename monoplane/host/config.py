"""Pipeline configuration: TOML files, shipped presets, ``--set`` overrides, strict validation.

A config is TOML with one table per stage kind (:data:`~monoplane.contracts.STAGE_KINDS`:
``[cues]``, ``[sampler]``, ...), each holding ``plugin = "name"`` and that plugin's parameters,
plus the host's tables (:data:`HOST_TABLES`: ``[ransac]`` for the sequential driver,
``[cloud]`` for point clouds, ``[planarity]`` for the planarity test after the refiner). A config
may start from a preset with a top-level ``preset = "name"``; without one it starts from the
default preset :data:`DEFAULT_PRESET`. A shipped preset may extend another the same way.
Overrides are ``table.key=value`` strings (values in TOML syntax; bare words are taken as
strings).

Merging rule: an override that changes a table's ``plugin`` replaces that whole table, because
the old plugin's parameters mean nothing to the new one.

Every key is checked against the plugin's ``Config`` dataclass: unknown tables, plugins, keys and
ill-typed values raise :class:`~monoplane.errors.ConfigError` listing the valid choices.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, cast

import tomli_w

from monoplane.contracts import STAGE_KINDS, CueProvider, config_key
from monoplane.contracts.config_fields import build_dataclass
from monoplane.errors import ConfigError
from monoplane.host.registry import Registry, get_registry

DEFAULT_PRESET = "monoplane"
#: The cue provider that serves the depth (and normals) given with each frame, estimating only
#: what is missing and predicting nothing: what a run on recorded or corrupted depth needs.
GIVEN_CUES_PROVIDER = "given"
#: Host tables (not stages) and the import path of their config dataclass.
HOST_TABLES: dict[str, str] = {"ransac": "monoplane.algorithm.ransac:RansacConfig",
                               "cloud": "monoplane.host.cloud_config:CloudConfig",
                               "planarity": "monoplane.algorithm.planarity:PlanarityConfig"}


def list_presets() -> list[str]:
    """Names of the presets shipped in ``monoplane/host/presets``."""
    folder = resources.files(__package__) / "presets"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def _parse_toml(text: str, where: str) -> dict[str, Any]:
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{where}: invalid TOML: {exc}") from None


def read_preset(name: str) -> dict[str, Any]:
    """The tables a shipped preset's own file states, ``preset`` key included (not merged).

    Raises
    ------
    ConfigError
        If no preset has that name (the message lists the valid ones).
    """
    presets = list_presets()
    if name not in presets:
        raise ConfigError(f"unknown preset {name!r}; valid presets: {', '.join(presets)}")
    text = (resources.files(__package__) / "presets" / f"{name}.toml").read_text()
    return _parse_toml(text, f"preset '{name}'")


def load_preset(name: str) -> dict[str, Any]:
    """The raw tables of a shipped preset, merged onto the preset it extends.

    A preset file may start from another with a top-level ``preset = "base"``, as a config
    file can, and then states only what differs from it (merged by :func:`merge`).

    Raises
    ------
    ConfigError
        If no preset has that name, or presets extend each other in a loop.
    """
    chain = [name]
    tables = read_preset(name)
    layers = [tables]
    while "preset" in tables:
        base = tables["preset"]
        if not isinstance(base, str):
            raise ConfigError(f"preset '{chain[-1]}': 'preset' must name a preset, got {base!r}")
        if base in chain:
            loop = " -> ".join([*chain, base])
            raise ConfigError(f"presets extend each other in a loop: {loop}")
        chain.append(base)
        tables = read_preset(base)
        layers.append(tables)
    merged: dict[str, Any] = {}
    for layer in reversed(layers):
        merged = merge(merged, {k: v for k, v in layer.items() if k != "preset"})
    return merged


def load_config_file(path: str | Path) -> dict[str, Any]:
    """Read a TOML config file into raw tables (not yet validated)."""
    p = Path(path)
    if not p.is_file():
        raise ConfigError(f"config file not found: {p}")
    return _parse_toml(p.read_text(), str(p))


def parse_override(expr: str) -> tuple[str, str, Any]:
    """Parse ``table.key=value`` into its parts.

    The value is read as a TOML value (``0.9``, ``true``, ``[1, 2]``, ``"text"``); anything that
    is not valid TOML is taken as a bare string, so ``cues.profile=zerodepth`` works unquoted.
    """
    if "=" not in expr:
        raise ConfigError(f"override {expr!r} must look like table.key=value")
    lhs, rhs = expr.split("=", 1)
    if lhs.count(".") != 1 or not all(lhs.split(".")):
        raise ConfigError(f"override {expr!r}: the key must be table.key, e.g. labeler.lambda")
    table, key = (s.strip() for s in lhs.split("."))
    rhs = rhs.strip()
    try:
        value = tomllib.loads(f"v = {rhs}")["v"]
    except tomllib.TOMLDecodeError:
        value = rhs
    return table, key, value


def merge(base: dict[str, Any], override: dict[str, Any]) -> dict[str, Any]:
    """Merge raw config tables (see the module docstring for the ``plugin`` rule)."""
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in base.items()}
    for table, values in override.items():
        if not isinstance(values, dict):
            out[table] = values
            continue
        current = out.get(table)
        if not isinstance(current, dict) or (
            "plugin" in values and values["plugin"] != current.get("plugin")
        ):
            out[table] = dict(values)
        else:
            current.update(values)
    return out


def overrides_to_tables(overrides: dict[str, Any] | list[str] | None) -> dict[str, Any]:
    """Normalise overrides given as ``["t.k=v", ...]`` or ``{"t.k": v}`` or ``{"t": {k: v}}``."""
    tables: dict[str, dict[str, Any]] = {}
    if not overrides:
        return tables
    items: list[tuple[str, str, Any]]
    if isinstance(overrides, dict):
        items = []
        for key, value in overrides.items():
            if isinstance(value, dict):
                items += [(key, k, v) for k, v in value.items()]
            else:
                table, _, field = key.partition(".")
                if not table or not field or "." in field:
                    raise ConfigError(f"override key {key!r} must be table.key")
                items.append((table, field, value))
    else:
        items = [parse_override(e) for e in overrides]
    for table, key, value in items:
        tables.setdefault(table, {})[key] = value
    return tables


def stacked_overrides(first: dict[str, dict[str, Any]],
                      then: dict[str, Any] | list[str] | None) -> dict[str, dict[str, Any]]:
    """Override tables: ``first``, then ``then`` on top of it key by key, as if both came in
    one ``--set`` list (no :func:`merge` rule applies between them: a ``plugin`` in ``then``
    replaces only that key).

    Parameters
    ----------
    first : dict
        ``{table: {key: value}}`` with parsed values.
    then : dict or list of str, optional
        Overrides in any form :func:`overrides_to_tables` takes (e.g. the user's ``--set``).
    """
    tables = {table: dict(values) for table, values in first.items()}
    for table, values in overrides_to_tables(then).items():
        tables.setdefault(table, {}).update(values)
    return tables


def given_cues_overrides(overrides: dict[str, Any] | list[str] | None = None
                         ) -> dict[str, dict[str, Any]]:
    """``overrides`` on top of the cue provider that serves each frame's given depth
    (:data:`GIVEN_CUES_PROVIDER`), so that ``cues.plugin=...`` among them may replace it."""
    return stacked_overrides({"cues": {"plugin": GIVEN_CUES_PROVIDER}}, overrides)


def cue_model_overrides(model: str, preset: str | None = None,
                        config: str | Path | dict[str, Any] | None = None,
                        overrides: dict[str, Any] | list[str] | None = None,
                        registry: Registry | None = None) -> dict[str, dict[str, Any]]:
    """The overrides of a run whose cue provider uses the catalogue model ``model``
    (``monoplane run --cues NAME``): the keys the configured provider names for it
    (:meth:`~monoplane.contracts.CueProvider.catalogue_config`) in ``[cues]``, then
    ``overrides`` on top.

    Parameters
    ----------
    model : str
        Catalogue name (or, for providers that take one, a profile file).
    preset, config, overrides
        The run's preset, config file and overrides (they pick the provider).
    registry : Registry, optional
        Stage registry; the default plugin manager's when omitted.

    Raises
    ------
    ConfigError
        When the configured provider takes no catalogue model.
    """
    registry = registry or get_registry()
    name = load(preset, config, overrides, registry).stages["cues"][0]
    # The registry admits only CueProvider subclasses under "cues".
    provider = cast(type[CueProvider], registry.get("cues", name).cls)
    keys = provider.catalogue_config(model)
    if keys is None:
        raise ConfigError(f"--cues {model}: cue provider '{name}' takes no catalogue model; "
                          "pick one that does with --set cues.plugin=NAME (see 'monoplane "
                          "plugins')")
    return stacked_overrides({"cues": keys}, overrides)


def _host_config_class(table: str) -> type:
    module, _, attr = HOST_TABLES[table].partition(":")
    return getattr(__import__(module, fromlist=[attr]), attr)


def config_values(obj: Any) -> dict[str, Any]:
    """User-facing ``{key: value}`` of a config dataclass instance (keywords unescaped)."""
    return {config_key(f): getattr(obj, f.name) for f in dataclasses.fields(obj)}


@dataclass
class ResolvedConfig:
    """A validated pipeline configuration.

    Attributes
    ----------
    stages : dict
        ``kind -> (plugin name, Config instance)`` for every stage kind.
    host : dict
        ``table -> config instance`` for host tables (``ransac``).
    preset : str
        The preset it started from.
    """

    stages: dict[str, tuple[str, Any]]
    host: dict[str, Any]
    preset: str

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict with every parameter, defaults included."""
        out: dict[str, Any] = {"preset": self.preset}
        for kind, (name, cfg) in self.stages.items():
            out[kind] = {"plugin": name, **config_values(cfg)}
        for table, cfg in self.host.items():
            out[table] = config_values(cfg)
        return out

    def to_toml(self) -> str:
        """The resolved config as TOML, loadable again with ``--config``."""
        return dumps_toml(self.to_dict())


def resolve(raw: dict[str, Any], registry: Registry | None = None) -> ResolvedConfig:
    """Validate raw tables (already merged) against the registered stages.

    Parameters
    ----------
    raw : dict
        Tables as read from TOML; may hold a top-level ``preset`` key.
    registry : Registry, optional
        Stage registry to validate plugin names against; a fresh default one if omitted.
    """
    registry = registry or get_registry()
    raw = dict(raw)
    preset = raw.pop("preset", DEFAULT_PRESET)
    if not isinstance(preset, str):
        raise ConfigError(f"'preset' must be a string naming a preset, got {preset!r}")
    tables = merge(load_preset(preset), raw)
    tables.pop("preset", None)
    valid_tables = list(STAGE_KINDS) + list(HOST_TABLES)
    for table, values in tables.items():
        if table not in valid_tables:
            raise ConfigError(f"unknown config table {table!r}; valid tables: "
                              f"{', '.join(valid_tables)}")
        if not isinstance(values, dict):
            raise ConfigError(f"{table!r} must be a table, e.g. [{table}]")
    stages: dict[str, tuple[str, Any]] = {}
    for kind in STAGE_KINDS:
        values = dict(tables.get(kind, {}))
        if "plugin" not in values:
            raise ConfigError(f"[{kind}] needs a plugin; valid choices: "
                              f"{', '.join(registry.names(kind))}")
        name = values.pop("plugin")
        if not isinstance(name, str):
            raise ConfigError(f"[{kind}] plugin must be a plugin name; valid choices: "
                              f"{', '.join(registry.names(kind))}; got {name!r}")
        info = registry.get(kind, name)
        stages[kind] = (name, build_dataclass(info.cls.Config, values, f"[{kind}] ({name})"))
    host = {t: build_dataclass(_host_config_class(t), tables.get(t, {}), f"[{t}]")
            for t in HOST_TABLES}
    return ResolvedConfig(stages=stages, host=host, preset=preset)


def load(preset: str | None = None, config: str | Path | dict[str, Any] | None = None,
         overrides: dict[str, Any] | list[str] | None = None,
         registry: Registry | None = None) -> ResolvedConfig:
    """Resolve a config from a preset, a file (or dict) and overrides, in that order.

    A ``preset`` argument wins over a ``preset`` key inside the config file.
    """
    raw: dict[str, Any] = {}
    if config is not None:
        raw = dict(config) if isinstance(config, dict) else load_config_file(config)
    if preset is not None:
        raw["preset"] = preset
    raw = merge(raw, overrides_to_tables(overrides))
    return resolve(raw, registry)


def _without_none(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _without_none(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [_without_none(v) for v in value]
    return value


def dumps_toml(data: dict[str, Any]) -> str:
    """Write config tables as TOML (with ``tomli-w``, so any string or key round-trips).

    ``None`` values are omitted (TOML has no null); they mean "use the default".

    Raises
    ------
    ConfigError
        If a value has no TOML form (a set, an arbitrary object).
    """
    try:
        return tomli_w.dumps(_without_none(data))
    except TypeError as exc:
        raise ConfigError(f"cannot write the config as TOML: {exc}") from None
