import dataclasses
import subprocess
import sys
from pathlib import Path

import pytest

from monoplane.contracts import KINDS, STAGE_KINDS, Sampler, param
from monoplane.errors import PluginError
from monoplane.host.registry import get_plugin_manager, get_registry
from monoplane.testing import check_stage_contract, stage_plugin

DOCS = Path(__file__).resolve().parents[1] / "docs" / "plugins.md"


def test_every_kind_has_builtins_from_monoplane():
    reg = get_registry(get_plugin_manager(autoload=False))
    for kind in STAGE_KINDS:
        assert reg.names(kind), f"no built-in {kind}"
    assert all(i.provider == "monoplane" for i in reg.all())


def test_the_core_registry_loads_no_evaluation_module():
    """Baselines are evaluation's: the core plugin manager registers stages only, and the
    evaluation code adds its built-in baseline when it looks baselines up."""
    code = ("import sys; from monoplane.host.registry import get_plugin_manager, get_registry; "
            "get_registry(get_plugin_manager(autoload=False)); "
            "print(sorted(m for m in sys.modules if m.startswith('monoplane.evaluation')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "[]"
    from monoplane.evaluation.baselines import BUILTIN_BASELINES, baseline_names

    pm = get_plugin_manager(autoload=False)
    assert "open3d-ransac" in baseline_names(pm)
    assert [pm.get_plugin(name) is not None for name in BUILTIN_BASELINES] == [True]
    assert "open3d-ransac" in baseline_names(pm)  # registering twice is harmless


@pytest.mark.parametrize("info", get_registry(get_plugin_manager(autoload=False)).all(),
                         ids=lambda i: f"{i.kind}-{i.name}")
def test_builtin_stages_honour_the_static_contract(info):
    check_stage_contract(info.cls)


class _Every3rd(Sampler):
    name = "every-third"

    @dataclasses.dataclass
    class Config:
        offset: int = param(0, "first index")


def _registry_with(**hooks: list[type]):
    """The registry of the built-ins and one plugin registering ``hooks``' classes."""
    return get_registry(get_plugin_manager(autoload=False, extra_plugins=(stage_plugin(**hooks),)))


def test_third_party_registers_like_builtins():
    reg = _registry_with(monoplane_register_samplers=[_Every3rd])
    assert reg.get("sampler", "every-third").cls is _Every3rd


def test_duplicate_or_wrong_kind_is_rejected():
    class Dup(_Every3rd):
        name = "uniform"

    with pytest.raises(PluginError, match="does not subclass"):
        _registry_with(monoplane_register_scorers=[Dup])
    with pytest.raises(PluginError, match="registered twice"):
        _registry_with(monoplane_register_samplers=[Dup])


def test_plugin_guide_documents_every_hook():
    text = DOCS.read_text()
    import monoplane.hookspecs as hs

    hooks = [n for n in dir(hs) if n.startswith("monoplane_")]
    assert {k.hook for k in KINDS.values()} <= set(hooks)
    missing = [h for h in hooks if h not in text]
    assert not missing, f"docs/plugins.md does not document: {missing}"


@pytest.mark.parametrize("kind", KINDS.values(), ids=lambda k: k.name)
def test_each_kind_has_its_written_out_hookspec(kind):
    """Each registration hook is a function of its own in hookspecs.py (greppable, documented
    as pytest's are), named as the kind says, stating its summary, table and contract."""
    import inspect

    import monoplane.hookspecs as hs

    spec = getattr(hs, kind.hook)
    assert getattr(spec, "monoplane_spec", None) is not None, f"{kind.hook} is no hookspec"
    assert spec.__name__ == kind.hook and spec.__module__ == hs.__name__
    assert f"def {kind.hook}()" in inspect.getsource(hs)  # written out, not generated
    doc = " ".join(inspect.getdoc(spec).split())
    assert doc.startswith(kind.summary)
    assert f"Config table ``[{kind.name}]``" in doc
    assert f":class:`monoplane.contracts.{kind.base.__name__}`" in doc
    assert inspect.signature(spec).return_annotation == f"list[type[{kind.base.__name__}]]"


def test_the_kinds_list_is_the_one_source():
    """Hookspecs, registry, config tables and the plugin guide's two tables all follow
    ``KINDS``: one registration hook per kind, one row per kind in each table, in order."""
    import monoplane.hookspecs as hs

    specs = {n for n in dir(hs) if n.startswith("monoplane_register_")}
    assert specs == {k.hook for k in KINDS.values()} | {"monoplane_register_baselines",
                                                         "monoplane_register_exporters"}
    assert STAGE_KINDS == tuple(k.base.kind for k in KINDS.values())
    lines = DOCS.read_text().splitlines()
    contract_rows = [ln for ln in lines if ln.startswith("| `") and "` | `" in ln
                     and ln.split("|")[1].strip().strip("`") in KINDS]
    assert [r.split("|")[1].strip().strip("`") for r in contract_rows] == list(KINDS)
    for row, kind in zip(contract_rows, KINDS.values(), strict=True):
        assert row.split("|")[2].strip() == f"`{kind.base.__name__}`", row
    hook_rows = [ln for ln in lines if ln.startswith("| `monoplane_register_")
                 and "baselines" not in ln and "exporters" not in ln]
    assert [r.split("`")[1].removesuffix("()") for r in hook_rows] == \
        [k.hook for k in KINDS.values()]
    for row, kind in zip(hook_rows, KINDS.values(), strict=True):
        assert f"`list[type[{kind.base.__name__}]]`" in row, row


def test_wrong_base_names_the_base_class():
    class NotAScorer(_Every3rd):
        name = "not-a-scorer"

    with pytest.raises(PluginError, match="subclass monoplane.plugin.CueProvider"):
        _registry_with(monoplane_register_cue_providers=[NotAScorer])
