"""The import layers docs/design.md describes hold: each rule is checked on the source."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "monoplane"


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set[str]:
    """Absolute module names a source file imports (``from monoplane import x`` counts as
    ``monoplane.x``); relative imports are not used in the package."""
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module:
            assert node.level == 0, f"{path}: relative import"
            found.add(node.module)
            if node.module == "monoplane":
                found |= {f"monoplane.{alias.name}" for alias in node.names}
    return found


MODULES = {_module_name(p): _imports(p) for p in sorted(PACKAGE.rglob("*.py"))}


def _ours(names: set[str]) -> set[str]:
    return {n for n in names if n == "monoplane" or n.startswith("monoplane.")}


def _within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def test_the_module_table_is_not_empty() -> None:
    assert "monoplane.datamodel" in MODULES and "monoplane.stages.base" in MODULES


def test_data_model_imports_only_errors_and_jit() -> None:
    assert _ours(MODULES["monoplane.datamodel"]) == {"monoplane.errors", "monoplane.jit"}
    assert _ours(MODULES["monoplane.jit"]) == _ours(MODULES["monoplane.errors"]) == set()


@pytest.mark.parametrize("module", sorted(m for m in MODULES
                                          if _within(m, ("monoplane.geometry",))))
def test_geometry_imports_only_the_data_model_and_kernels(module: str) -> None:
    allowed = ("monoplane.geometry", "monoplane.datamodel", "monoplane.errors", "monoplane.jit")
    assert {n for n in _ours(MODULES[module]) if not _within(n, allowed)} == set()


@pytest.mark.parametrize("module", sorted(m for m in MODULES
                                          if _within(m, ("monoplane.stages",))))
def test_stages_import_no_other_stage_and_no_host_driver(module: str) -> None:
    forbidden = ("monoplane.cli", "monoplane.pipeline", "monoplane.batch", "monoplane.bench",
                 "monoplane.evaluation", "monoplane.report", "monoplane.multiview")
    bad = {n for n in _ours(MODULES[module])
           if _within(n, forbidden)
           or (_within(n, ("monoplane.stages",)) and n not in ("monoplane.stages",
                                                                 "monoplane.stages.base"))}
    assert bad == set()


def test_concrete_stages_are_named_only_in_the_default_plugin_list() -> None:
    from monoplane.plugin_manager import DEFAULT_PLUGINS

    stage_modules = {m for m in MODULES if _within(m, ("monoplane.stages",))
                     and m not in ("monoplane.stages", "monoplane.stages.base")}
    assert stage_modules <= set(DEFAULT_PLUGINS)
    importers = {m: MODULES[m] & stage_modules for m in MODULES
                 if not _within(m, ("monoplane.stages",)) and MODULES[m] & stage_modules}
    assert importers == {}


def test_only_the_cli_imports_the_cli() -> None:
    bad = {m for m, names in MODULES.items()
           if not _within(m, ("monoplane.cli",)) and any(_within(n, ("monoplane.cli",))
                                                         for n in names)}
    assert bad == set()


def test_nothing_imports_a_plugin_package() -> None:
    packages = {p.name for p in (PACKAGE.parent / "plugins").glob("*/src/*")
                if p.is_dir() and "." not in p.name}
    assert "monoplane_cgal_baseline" in packages
    bad = {m: n for m, names in MODULES.items() for n in names if n.split(".")[0] in packages}
    assert bad == {}


def _plugin_package_files(part: str) -> list[Path]:
    return sorted((PACKAGE.parent / "plugins").glob(f"*/{part}/**/*.py"))


@pytest.mark.parametrize("part, allowed", [
    ("src", {"monoplane.plugin"}),
    # A plugin's tests may also use the pytest plugin's helpers and fixtures.
    ("tests", {"monoplane.plugin", "monoplane.testing"}),
])
def test_plugin_packages_import_only_the_public_plugin_api(part: str,
                                                           allowed: set[str]) -> None:
    files = _plugin_package_files(part)
    assert len({f.relative_to(PACKAGE.parent).parts[1] for f in files}) >= 2
    bad = {str(f.relative_to(PACKAGE.parent)): sorted(_ours(_imports(f)) - allowed)
           for f in files if _ours(_imports(f)) - allowed}
    assert bad == {}


def test_the_public_plugin_api_is_imported_by_nothing_inside() -> None:
    assert {m for m, names in MODULES.items() if "monoplane.plugin" in names} == set()


def test_the_public_plugin_api_defines_all_it_lists() -> None:
    import monoplane.plugin

    assert [n for n in monoplane.plugin.__all__ if not hasattr(monoplane.plugin, n)] == []
