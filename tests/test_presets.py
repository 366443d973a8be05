"""Presets state only what differs from the stage defaults, and resolve as they always did."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from monoplane import config
from monoplane.plugin_manager import get_registry

#: The resolved config of every preset, recorded when the presets still restated every default.
RECORDED = json.loads((Path(__file__).parent / "data" / "preset_resolved_configs.json")
                      .read_text())


def test_recording_covers_every_preset() -> None:
    assert sorted(RECORDED) == config.list_presets()


@pytest.mark.parametrize("name", sorted(RECORDED))
def test_resolved_preset_is_unchanged(name: str) -> None:
    resolved = config.load(preset=name).to_dict()
    # Keys added to a stage Config later are not in the recording; every recorded value must
    # still resolve to the same thing.
    for table, values in RECORDED[name].items():
        if isinstance(values, dict):
            got = {k: resolved[table].get(k) for k in values}
            assert got == values, f"[{table}] of preset {name} changed"
        else:
            assert resolved[table] == values


@pytest.mark.parametrize("name", config.list_presets())
def test_preset_states_only_differences_from_defaults(name: str) -> None:
    registry = get_registry()
    for table, values in config.load_preset(name).items():
        if table in config.HOST_TABLES:
            cls = config._host_config_class(table)
        else:
            cls = registry.get(table, values["plugin"]).cls.Config
        defaults = config.config_values(cls())
        restated = [k for k, v in values.items() if k != "plugin" and defaults.get(k) == v]
        assert not restated, f"preset {name} restates defaults of [{table}]: {restated}"
