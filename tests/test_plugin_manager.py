import dataclasses
from pathlib import Path

import pytest

from monoplane.errors import PluginError
from monoplane.hookspecs import hookimpl
from monoplane.plugin_manager import REGISTRATION_HOOKS, get_plugin_manager, get_registry
from monoplane.stages.base import STAGE_KINDS, Sampler, param
from monoplane.testing import check_stage_contract

DOCS = Path(__file__).resolve().parents[1] / "docs" / "plugins.md"


def test_every_kind_has_builtins_from_monoplane():
    reg = get_registry(get_plugin_manager(autoload=False))
    for kind in STAGE_KINDS:
        assert reg.names(kind), f"no built-in {kind}"
    assert all(i.provider == "monoplane" for i in reg.all())


@pytest.mark.parametrize("info", get_registry(get_plugin_manager(autoload=False)).all(),
                         ids=lambda i: f"{i.kind}-{i.name}")
def test_builtin_stages_honour_the_static_contract(info):
    check_stage_contract(info.cls)


class _Every3rd(Sampler):
    name = "every-third"

    @dataclasses.dataclass
    class Config:
        offset: int = param(0, "first index")


class _ThirdParty:
    @hookimpl
    def monoplane_register_samplers(self):
        return [_Every3rd]


def test_third_party_registers_like_builtins():
    reg = get_registry(get_plugin_manager(autoload=False, extra_plugins=(_ThirdParty(),)))
    assert reg.get("sampler", "every-third").cls is _Every3rd


def test_duplicate_or_wrong_kind_is_rejected():
    class Dup(_Every3rd):
        name = "uniform"

    class Bad:
        @hookimpl
        def monoplane_register_scorers(self):
            return [Dup]

    class Clash:
        @hookimpl
        def monoplane_register_samplers(self):
            return [Dup]

    with pytest.raises(PluginError, match="does not subclass"):
        get_registry(get_plugin_manager(autoload=False, extra_plugins=(Bad(),)))
    with pytest.raises(PluginError, match="registered twice"):
        get_registry(get_plugin_manager(autoload=False, extra_plugins=(Clash(),)))


def test_plugin_guide_documents_every_hook():
    text = DOCS.read_text()
    import monoplane.hookspecs as hs

    hooks = [n for n in dir(hs) if n.startswith("monoplane_")]
    assert set(REGISTRATION_HOOKS.values()) <= set(hooks)
    missing = [h for h in hooks if h not in text]
    assert not missing, f"docs/plugins.md does not document: {missing}"
