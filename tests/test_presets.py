"""Presets state only what differs from the stage defaults, and resolve as they always did."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import pytest

from monoplane.host import config
from monoplane.host.registry import get_registry

#: The resolved config of every preset, recorded when the presets still restated every default.
RECORDED = json.loads((Path(__file__).parent / "data" / "preset_resolved_configs.json")
                      .read_text())


def test_recording_covers_every_preset() -> None:
    assert sorted(RECORDED) == config.list_presets()


#: Keys a stage table once restated and now reads from the shared ``[ransac]`` table.
SHARED = {"epsilon", "epsilon_n_deg"}


@pytest.mark.parametrize("name", sorted(RECORDED))
def test_resolved_preset_is_unchanged(name: str) -> None:
    resolved = config.load(preset=name).to_dict()
    # Keys added to a stage Config later are not in the recording; every recorded value must
    # still resolve to the same thing, a shared threshold in [ransac].
    for table, values in RECORDED[name].items():
        if isinstance(values, dict):
            got = {k: resolved["ransac" if k in SHARED and k not in resolved[table] else table]
                   .get(k) for k in values}
            assert got == values, f"[{table}] of preset {name} changed"
        else:
            assert resolved[table] == values


@pytest.mark.parametrize("name", config.list_presets())
def test_preset_states_only_differences(name: str) -> None:
    """A preset's file states only what differs from the preset it extends, or, for a table
    whose plugin it changes (or a preset that extends none), from the plugin's defaults."""
    registry = get_registry()
    own = config.read_preset(name)
    base = config.load(preset=own.pop("preset")).to_dict() if "preset" in own else {}
    for table, values in own.items():
        inherited = base.get(table, {})
        plugin = values.get("plugin", inherited.get("plugin"))
        if table in config.HOST_TABLES:
            defaults = config.config_values(config._host_config_class(table)())
        else:
            defaults = config.config_values(registry.get(table, plugin).cls.Config())
        extends = table in base and plugin == inherited.get("plugin")
        reference = {**defaults, **inherited} if extends else defaults
        restated = [k for k, v in values.items() if k in reference and reference[k] == v]
        assert not restated, f"preset {name} restates [{table}]: {restated}"


def test_only_the_base_preset_states_every_table() -> None:
    """Every preset but the default extends another; the chain ends at the default."""
    for name in config.list_presets():
        chain = [name]
        while "preset" in (raw := config.read_preset(chain[-1])):
            chain.append(raw["preset"])
        assert chain[-1] == config.DEFAULT_PRESET, chain


def test_presets_extending_in_a_loop_are_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    loop = {"a": {"preset": "b"}, "b": {"preset": "a"}}
    monkeypatch.setattr(config, "read_preset", lambda name: dict(loop[name]))
    with pytest.raises(config.ConfigError, match="loop: a -> b -> a"):
        config.load_preset("a")


@pytest.mark.parametrize("name", config.list_presets())
def test_shared_thresholds_are_printed_once(name: str) -> None:
    """`monoplane presets NAME` states ε and ε_n in [ransac] only."""
    from monoplane.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["presets", name]) == 0
    keys = [line.split("=")[0].strip() for line in out.getvalue().splitlines()]
    assert keys.count("epsilon") == 1 and keys.count("epsilon_n_deg") == 1
