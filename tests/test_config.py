import pytest

from monoplane.errors import ConfigError
from monoplane.host import config


def test_presets_include_the_paper_ablation_rows():
    names = config.list_presets()
    for row in ("seq-ransac", "seq-ransac+crf", "gc-ransac", "gc-ransac+crf",
                "monoplane-nocrf", "monoplane"):
        assert row in names


@pytest.mark.parametrize("name", config.list_presets())
def test_every_preset_resolves_and_round_trips_through_toml(name, tmp_path):
    resolved = config.load(preset=name)
    path = tmp_path / "c.toml"
    path.write_text(resolved.to_toml())
    assert config.load(config=path).to_dict() == resolved.to_dict()


def test_override_value_types():
    assert config.parse_override("labeler.lambda=0.9") == ("labeler", "lambda", 0.9)
    assert config.parse_override("cues.profile=zerodepth") == ("cues", "profile", "zerodepth")
    assert config.parse_override('cues.profile="a b"') == ("cues", "profile", "a b")
    assert config.parse_override("ransac.seed = 3") == ("ransac", "seed", 3)


def test_override_applies_to_keyword_field():
    resolved = config.load(preset="monoplane", overrides=["labeler.lambda=0.5"])
    assert resolved.to_dict()["labeler"]["lambda"] == 0.5


def test_changing_plugin_drops_old_parameters():
    resolved = config.load(preset="monoplane", overrides=["labeler.plugin=threshold"])
    assert resolved.stages["labeler"][0] == "threshold"


@pytest.mark.parametrize("overrides, match", [
    (["labeler.lamda=0.5"], r"unknown key 'lamda'.*valid keys: .*lambda"),
    (["labeler.plugin=magic"], r"unknown labeler plugin 'magic'; valid choices: .*graph-cut"),
    (["sampeler.plugin=uniform"], r"unknown config table 'sampeler'; valid tables: cues"),
    (["labeler.lambda=high"], r"\[labeler\].*lambda must be a number"),
    (["ransac.seed=1.5"], r"seed must be an integer"),
    (["nodot=1"], "table.key"),
])
def test_bad_config_lists_valid_choices(overrides, match):
    with pytest.raises(ConfigError, match=match):
        config.load(preset="monoplane", overrides=overrides)


def test_unknown_preset_lists_presets():
    with pytest.raises(ConfigError,
                       match=r"unknown preset 'monoplain'; valid presets: .*gc-ransac"):
        config.load(preset="monoplain")


def test_config_file_with_preset_and_invalid_toml(tmp_path):
    good = tmp_path / "good.toml"
    good.write_text('preset = "gc-ransac"\n[labeler]\nlambda = 0.8\n')
    resolved = config.load(config=good)
    assert resolved.preset == "gc-ransac"
    assert resolved.to_dict()["labeler"]["lambda"] == 0.8
    bad = tmp_path / "bad.toml"
    bad.write_text("[labeler\n")
    with pytest.raises(ConfigError, match="bad.toml: invalid TOML"):
        config.load(config=bad)
    with pytest.raises(ConfigError, match="config file not found"):
        config.load(config=tmp_path / "missing.toml")


@pytest.mark.parametrize("value", ["[1]", "3", "true", "{a = 1}"])
def test_plugin_must_be_a_name(value):
    with pytest.raises(ConfigError, match=r"\[sampler\] plugin must be a plugin name; valid"):
        config.load(overrides=[f"sampler.plugin={value}"])


@pytest.mark.parametrize("override, table, message", [
    ("ransac.epsilon=-1", "ransac", "epsilon must be positive"),
    ("cloud.normals_knn=1", "cloud", "normals_knn must be at least 3, got 1"),
    ("cues.max_jump=0", "cues", "max_jump must be positive, got 0.0"),
])
def test_a_rejected_value_names_its_table_once(override, table, message):
    with pytest.raises(ConfigError) as caught:
        config.load(preset="monoplane", overrides=[override])
    text = str(caught.value)
    assert text.startswith(f"[{table}]") and text.endswith(message)
    assert text.count(table) == 1 + message.count(table)


def test_the_cli_names_the_table_once(capsys, tmp_path):
    from monoplane.cli import main

    assert main(["run", "no-such.png", "--out", str(tmp_path / "out"),
                 "--set", "ransac.epsilon=-1"]) != 0
    assert capsys.readouterr().err.strip() == "monoplane: error: [ransac]: epsilon must be positive"
