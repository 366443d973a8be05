"""``run --cues NAME``: the configured cue provider, not the host, says which of its keys
select a catalogue model, so a third-party provider can take ``--cues`` too."""

import dataclasses

import pytest

from monoplane.cli import main
from monoplane.contracts import CueProvider, param
from monoplane.errors import ConfigError
from monoplane.hookspecs import hookimpl
from monoplane.host import config
from monoplane.host.config import cue_model_overrides
from monoplane.host.registry import get_plugin_manager, get_registry


class _StandIn(CueProvider):
    """A third-party provider whose catalogue models go into a key of its own."""

    name = "stand-in"

    @dataclasses.dataclass
    class Config:
        weights: str = param("", "catalogue name of its weights")

    @classmethod
    def catalogue_config(cls, model: str) -> dict[str, str]:
        return {"weights": model}


class _ThirdParty:
    @hookimpl
    def monoplane_register_cue_providers(self):
        return [_StandIn]


def test_the_onnx_provider_maps_a_catalogue_name_to_its_model_key() -> None:
    reg = get_registry(get_plugin_manager(autoload=False))
    assert cue_model_overrides("depth-anything-v2-small", registry=reg) == {
        "cues": {"model": "depth-anything-v2-small"}}


def test_a_third_party_provider_takes_cues_through_its_own_keys() -> None:
    reg = get_registry(get_plugin_manager(autoload=False, extra_plugins=(_ThirdParty(),)))
    overrides = ["cues.plugin=stand-in"]
    tables = cue_model_overrides("my-net", overrides=overrides, registry=reg)
    assert tables == {"cues": {"weights": "my-net", "plugin": "stand-in"}}
    resolved = config.load(overrides=tables, registry=reg)
    assert resolved.stages["cues"][0] == "stand-in"
    assert resolved.stages["cues"][1].weights == "my-net"


def test_a_provider_without_catalogue_models_refuses_cues(capsys, tmp_path) -> None:
    with pytest.raises(ConfigError, match="cue provider 'given' takes no catalogue model"):
        cue_model_overrides("depth-anything-v2-small", overrides=["cues.plugin=given"],
                            registry=get_registry(get_plugin_manager(autoload=False)))
    assert main(["run", "x.png", "--out", str(tmp_path / "out"), "--cues",
                 "depth-anything-v2-small", "--set", "cues.plugin=given"]) != 0
    assert "takes no catalogue model" in capsys.readouterr().err


def test_the_user_overrides_go_on_top_of_the_catalogue_keys_key_by_key() -> None:
    reg = get_registry(get_plugin_manager(autoload=False))
    tables = cue_model_overrides("depth-anything-v2-small",
                                 overrides=["cues.model=metric3d-v2-small", "labeler.lambda=0.5"],
                                 registry=reg)
    assert tables == {"cues": {"model": "metric3d-v2-small"}, "labeler": {"lambda": 0.5}}
    # As if both came in one --set list: the same resolved config.
    strings = config.load(overrides=['cues.model="depth-anything-v2-small"',
                                     "cues.model=metric3d-v2-small", "labeler.lambda=0.5"],
                          registry=reg)
    assert config.load(overrides=tables, registry=reg).to_dict() == strings.to_dict()


def test_the_given_cue_provider_comes_first_and_may_be_replaced() -> None:
    assert config.given_cues_overrides() == {"cues": {"plugin": config.GIVEN_CUES_PROVIDER}}
    assert config.given_cues_overrides(["cues.plugin=onnx", "cues.model=x"]) == {
        "cues": {"plugin": "onnx", "model": "x"}}
    reg = get_registry(get_plugin_manager(autoload=False))
    resolved = config.load(overrides=config.given_cues_overrides(), registry=reg)
    assert resolved.stages["cues"][0] == config.GIVEN_CUES_PROVIDER
