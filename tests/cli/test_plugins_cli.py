"""``monoplane plugins``: what it prints is what configs accept."""

from __future__ import annotations

import json

import pytest
import tomli_w

from monoplane.cli import main
from monoplane.host import config


def _toml_literal(value: object) -> str:
    """``value`` written as a TOML value, the way a user types it after ``--set key=``
    (tables as inline tables)."""
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml_literal(v)}" for k, v in value.items()) + "}"
    return tomli_w.dumps({"v": value}).split("=", 1)[1].strip()


def test_every_listed_key_is_accepted_by_set(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plugins", "--json"]) == 0
    listing = json.loads(capsys.readouterr().out)
    assert {s["kind"] for s in listing} >= {"cues", "sampler", "scorer", "labeler", "refiner",
                                             "matcher", "fuser"}
    checked = 0
    for stage in listing:
        kind, name = stage["kind"], stage["name"]
        for p in stage["parameters"]:
            value = _toml_literal(p["default"])
            overrides = [f"{kind}.plugin={name}", f"{kind}.{p['name']}={value}"]
            resolved = config.load(overrides=overrides).to_dict()
            assert resolved[kind]["plugin"] == name
            assert resolved[kind][p["name"]] == p["default"], (kind, name, p["name"])
            checked += 1
    assert checked > 50  # every built-in stage's parameters, not an empty listing


def test_listing_spells_lambda_as_configs_do(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["plugins", "--kind", "labeler"]) == 0
    out = capsys.readouterr().out
    assert "lambda (float" in out and "lambda_" not in out
