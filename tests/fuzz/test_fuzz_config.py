"""Config files, ``--set`` overrides and the TOML writer on arbitrary input."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from monoplane.contracts import STAGE_KINDS
from monoplane.errors import ConfigError
from monoplane.host import config
from monoplane.host.registry import get_registry

REGISTRY = get_registry()
TABLES = list(STAGE_KINDS) + list(config.HOST_TABLES) + ["nope"]
KEYS = sorted({p[0] for i in REGISTRY.all() for p in i.cls.parameters()}
              | {"plugin", "epsilon", "lo_iterations", "x"})
PLUGINS = sorted({i.name for i in REGISTRY.all()})

_SCALARS = st.one_of(st.booleans(), st.integers(-(2**63), 2**63 - 1),
                     st.floats(allow_nan=False), st.text(max_size=12),
                     st.sampled_from(PLUGINS))
_VALUES = st.one_of(_SCALARS, st.lists(_SCALARS, max_size=3))


def _one_line(exc: Exception) -> None:
    msg = str(exc)
    assert msg and "\n" not in msg, msg


def _plain(value: object) -> object:
    """NaN compares unequal to itself; map it to a marker so round trips can be compared."""
    if isinstance(value, float) and math.isnan(value):
        return "nan-marker"
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def test_toml_writer_round_trips_any_keys_and_strings(fuzz) -> None:
    keys = st.text(min_size=1, max_size=10)  # any characters, control ones included
    leaf = st.one_of(st.booleans(), st.integers(-(2**63), 2**63 - 1), st.floats(),
                     st.text(max_size=20), st.lists(st.text(max_size=5), max_size=3))
    doc = st.dictionaries(keys, st.one_of(leaf, st.dictionaries(keys, leaf, max_size=4)),
                          max_size=5)

    @fuzz
    @given(doc)
    def check(data: dict) -> None:
        text = config.dumps_toml(data)
        assert _plain(tomllib.loads(text)) == _plain(data)

    check()


def test_toml_writer_drops_none_and_rejects_unwritable_values() -> None:
    assert tomllib.loads(config.dumps_toml({"a": None, "t": {"k": None, "j": 1}})) == {
        "t": {"j": 1}}
    with pytest.raises(ConfigError, match="cannot write the config as TOML"):
        config.dumps_toml({"t": {"k": {1, 2}}})


def test_resolved_configs_round_trip_through_the_writer(fuzz) -> None:
    @fuzz
    @given(st.sampled_from(config.list_presets()),
           st.sampled_from(["monoplane", "a\x01b", 'quote " and \\ backslash', "line\nbreak"]))
    def check(preset: str, profile: str) -> None:
        resolved = config.load(preset=preset)
        doc = resolved.to_dict()
        doc["cues"]["normal_axes"] = profile  # any string survives the trip
        assert _plain(tomllib.loads(config.dumps_toml(doc))) == _plain(doc)

    check()


def test_override_parser(fuzz) -> None:
    @fuzz
    @given(st.one_of(
        st.text(max_size=30),
        st.tuples(st.sampled_from(TABLES), st.sampled_from(KEYS),
                  st.one_of(st.text(max_size=10), _VALUES.map(lambda v: config.dumps_toml(
                      {"v": v}).split("=", 1)[1].strip())))
        .map(lambda t: f"{t[0]}.{t[1]}={t[2]}")))
    def check(expr: str) -> None:
        try:
            resolved = config.load(overrides=[expr])
        except ConfigError as exc:
            _one_line(exc)
            return
        assert set(resolved.stages) == set(STAGE_KINDS)

    check()


def test_config_file(fuzz, tmp_path: Path) -> None:
    tables = st.dictionaries(st.sampled_from(KEYS), _VALUES, max_size=3)
    documents = st.one_of(
        st.text(max_size=60),
        st.dictionaries(st.sampled_from(TABLES + ["preset"]),
                        st.one_of(tables, st.sampled_from(config.list_presets() + ["x"]), _VALUES),
                        max_size=4).map(config.dumps_toml),
    )

    @fuzz
    @given(documents)
    def check(text: str) -> None:
        path = tmp_path / "config.toml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        try:
            resolved = config.load(config=path)
        except ConfigError as exc:
            _one_line(exc)
            return
        again = config.load(config=_write(tmp_path / "again.toml", resolved.to_toml()))
        assert _plain(again.to_dict()) == _plain(resolved.to_dict())

    check()


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path
