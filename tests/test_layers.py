"""The import layers docs/design.md describes hold: each rule is checked on the source."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from monoplane.moved_modules import MOVED

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


#: The package of the built-in stages (empty) and the package of the contracts they implement.
STAGES, CONTRACTS = "monoplane.stages", "monoplane.contracts"

MODULES = {_module_name(p): _imports(p) for p in sorted(PACKAGE.rglob("*.py"))}


def _ours(names: set[str]) -> set[str]:
    return {n for n in names if n == "monoplane" or n.startswith("monoplane.")}


def _within(name: str, prefixes: tuple[str, ...]) -> bool:
    return any(name == p or name.startswith(p + ".") for p in prefixes)


def test_the_module_table_is_not_empty() -> None:
    assert "monoplane.datamodel" in MODULES and "monoplane.contracts" in MODULES


@pytest.mark.parametrize("module", sorted(m for m in MODULES
                                          if _within(m, ("monoplane.datamodel",))))
def test_data_model_imports_only_errors_and_jit(module: str) -> None:
    outside = {n for n in _ours(MODULES[module]) if not _within(n, ("monoplane.datamodel",))}
    assert outside <= {"monoplane.errors", "monoplane.jit"}
    assert _ours(MODULES["monoplane.jit"]) == _ours(MODULES["monoplane.errors"]) == set()


@pytest.mark.parametrize("module", sorted(m for m in MODULES
                                          if _within(m, ("monoplane.geometry",))))
def test_geometry_imports_only_the_data_model_and_kernels(module: str) -> None:
    allowed = ("monoplane.geometry", "monoplane.datamodel", "monoplane.errors", "monoplane.jit",
               "monoplane.palette")
    assert {n for n in _ours(MODULES[module]) if not _within(n, allowed)} == set()


@pytest.mark.parametrize("module", sorted(m for m in MODULES
                                          if _within(m, ("monoplane.stages",))))
def test_stages_import_no_other_stage_and_no_host_driver(module: str) -> None:
    forbidden = ("monoplane.cli", "monoplane.host.pipeline", "monoplane.batch",
                 "monoplane.evaluation", "monoplane.report", "monoplane.multiview")
    bad = {n for n in _ours(MODULES[module])
           if _within(n, forbidden)
           or (_within(n, (STAGES,)) and n != STAGES)}
    assert bad == set()


def test_concrete_stages_are_named_only_in_the_default_plugin_list() -> None:
    from monoplane.host.registry import DEFAULT_PLUGINS

    stage_modules = {m for m in MODULES if _within(m, (STAGES,)) and m != STAGES}
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


def _references(path: Path) -> set[str]:
    """Our modules a file names in any form: imports anywhere in it (at the top, in functions,
    under ``TYPE_CHECKING``) and ``"monoplane.x"`` / ``"monoplane.x:Name"`` strings used to
    load a module by name."""
    strings = {node.value.partition(":")[0] for node in ast.walk(ast.parse(path.read_text()))
               if isinstance(node, ast.Constant) and isinstance(node.value, str)
               and _MODULE_REFERENCE.fullmatch(node.value)}
    return _ours(_imports(path) | strings)


@pytest.mark.parametrize("part, allowed", [
    ("src", {"monoplane.plugin"}),
    # A plugin's tests may also use the pytest plugin's helpers and fixtures.
    ("tests", {"monoplane.plugin", "monoplane.testing"}),
])
def test_plugin_packages_import_only_the_public_plugin_api(part: str,
                                                           allowed: set[str]) -> None:
    files = _plugin_package_files(part)
    assert len({f.relative_to(PACKAGE.parent).parts[1] for f in files}) >= 2
    bad = {str(f.relative_to(PACKAGE.parent)): sorted(_references(f) - allowed)
           for f in files if _references(f) - allowed}
    assert bad == {}


def test_the_plugin_check_sees_every_form(tmp_path: Path) -> None:
    probe = tmp_path / "probe.py"
    probe.write_text('def f():\n    from monoplane.contracts import Stage\n'
                     'X = "monoplane.host.registry:get_registry"\n"""monoplane.errors is a '
                     'docstring"""\n')
    assert _references(probe) == {"monoplane.contracts", "monoplane.host.registry"}


def test_the_public_plugin_api_is_imported_by_nothing_inside() -> None:
    assert {m for m, names in MODULES.items() if "monoplane.plugin" in names} == set()


def test_the_public_plugin_api_defines_all_it_lists() -> None:
    import monoplane.plugin

    assert [n for n in monoplane.plugin.__all__ if not hasattr(monoplane.plugin, n)] == []


# --- import cycles ---------------------------------------------------------------------------

#: A string that names a module for lazy loading: "monoplane.x.y" or "monoplane.x.y:Name".
_MODULE_REFERENCE = re.compile(r"monoplane(\.\w+)+(:\w+)?")

#: Every module of the package by name; ``__main__`` modules are scripts run with ``python -m``,
#: which nothing imports.
_FILES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py")) if p.stem != "__main__"}


def _home(name: str) -> str | None:
    """The module ``name`` stands in: itself, or the module that defines it (``a.b.Name``)."""
    while name and name not in _FILES:
        name = name.rpartition(".")[0]
    return name or None


def _run_as_script(tree: ast.AST) -> set[int]:
    """Nodes of the strings after ``-m`` in a command list: a child process runs that module,
    this one does not import it."""
    return {id(b) for node in ast.walk(tree) if isinstance(node, (ast.List, ast.Tuple))
            for a, b in zip(node.elts, node.elts[1:], strict=False)
            if isinstance(a, ast.Constant) and a.value == "-m"}


def _dependencies(path: Path) -> set[str]:
    """The modules of the package one source file needs, in every form it can name them.

    Imports anywhere (top level, inside functions, under ``if TYPE_CHECKING:``); strings used
    for lazy loading (``"monoplane.x.y"``, ``"monoplane.x:Name"``, and f-strings such as
    ``f"monoplane.cli.{name}"``, which stand for every module below that prefix). ``from P
    import N`` needs ``P.N`` when that is a module (Python imports it) and ``P`` otherwise. The
    import of a parent package that every form implies is not counted, in no form: Python
    puts the package in ``sys.modules`` before its submodule runs, and counting it would make
    every package whose ``__init__`` re-exports a submodule a cycle.
    """
    tree = ast.parse(path.read_text())
    scripts = _run_as_script(tree)
    named: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            named += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            named += [f"{node.module}.{alias.name}" for alias in node.names]
        elif (isinstance(node, ast.Constant) and isinstance(node.value, str)
              and id(node) not in scripts and _MODULE_REFERENCE.fullmatch(node.value)):
            named.append(node.value.partition(":")[0])
        elif (isinstance(node, ast.JoinedStr) and node.values
              and isinstance(node.values[0], ast.Constant)
              and str(node.values[0].value).startswith("monoplane.")):
            named += [m for m in _FILES if m.startswith(str(node.values[0].value))]
    # an old path of a moved module is an alias, not a module this file needs
    homes = {_home(n) for n in named if n.split(".")[0] == "monoplane" and n not in MOVED}
    return {h for h in homes if h is not None} - {_module_name(path)}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = [stack.pop()]
            while component[-1] != v:
                component.append(stack.pop())
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_check_sees_every_import_form() -> None:
    deps = {m: _dependencies(p) for m, p in _FILES.items()}
    assert "monoplane.host.cloud_config" in deps["monoplane.host.config"]            # "module:Name"
    assert "monoplane.stages.samplers" in deps["monoplane.host.registry"]  # "module"
    assert "monoplane.cli.run" in deps["monoplane.cli"]                     # f"prefix.{name}"
    assert "monoplane.host.pipeline" in deps["monoplane"]                        # TYPE_CHECKING
    assert "monoplane.host.pipeline" in deps["monoplane.host.view_pool"]        # inside a function
    assert "monoplane.report.html" in deps["monoplane.report.frame"]        # from P import N
    assert "monoplane.cli" not in deps["monoplane.batch.throughput"]        # python -m
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles() -> None:
    assert _cycles({m: _dependencies(p) for m, p in _FILES.items()}) == []


def test_file_outputs_trigger_no_report() -> None:
    # Reports are the caller's choice (save's `also`), not the writers'.
    writers = [m for m in _FILES if _within(m, ("monoplane.export", "monoplane.io.frames"))]
    assert {(m, d) for m in writers for d in _dependencies(_FILES[m])
            if _within(d, ("monoplane.report",))} == set()


# --- layers ----------------------------------------------------------------------------------

#: The layers, bottom up, and the modules or packages each holds. A module belongs to the
#: layer of the longest entry that names it or a package above it; the package ``monoplane``
#: itself (its ``__init__``: the lazy top-level names) is only that module. A package's
#: ``__init__`` stands as high as the highest of its own submodules it imports (``cues``
#: re-exports the model profiles' file reader), so that importing the package counts as
#: importing what it loads. Every form of import counts, as in the cycle check.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("foundation", ("monoplane.errors", "monoplane.version", "monoplane.jit",
                    "monoplane.palette", "monoplane.deprecation")),
    ("data model", ("monoplane.datamodel",)),
    # the compiled solvers and geometry; io.checks holds the input limits and checks that
    # detect_planes shares with the file readers
    ("kernels", ("monoplane.geometry", "monoplane.algorithm", "monoplane.io.checks")),
    ("cue and feature libraries", ("monoplane.cues", "monoplane.features")),
    # what a stage or an output format states, and the hooks that register them
    ("contracts", (CONTRACTS, "monoplane.hookspecs")),
    # model profiles are read into dataclasses with the contracts' config fields
    ("model catalogue", ("monoplane.cues.profile_files", "monoplane.models")),
    ("algorithm drivers", ("monoplane.algorithm.ransac", "monoplane.algorithm.planarity")),
    ("built-in stages", ("monoplane.stages",)),
    ("host", ("monoplane.host",)),
    # the writers know every result by its vocabulary (result_kind), not its producer
    ("io and export", ("monoplane.io", "monoplane.export")),
    ("multiview", ("monoplane.multiview",)),
    ("applications", ("monoplane.batch", "monoplane.evaluation", "monoplane.report",
                      "monoplane.synth")),
    # what users and plugin authors import: free to name anything below
    ("facades", ("monoplane.cli", "monoplane.plugin", "monoplane.testing", "monoplane.warmup",
                 "monoplane.moved_modules", "monoplane")),
)

#: Imports that still run back up while other work moves the code they need (module ->
#: modules it imports from a higher layer). Empty it as they go: the test fails on a stale
#: entry too.
PENDING: dict[str, set[str]] = {
    # the deprecated save_scene(report=True) of 0.1 writes the report itself (save's `also`
    # makes reports the caller's choice now); it stays working until it goes in 0.3.0
    "monoplane.multiview.writers": {"monoplane.report"},
}

_DEPENDENCIES = {m: _dependencies(p) for m, p in _FILES.items()}


def _base_layer(module: str) -> int:
    best, rank = -1, -1
    for i, (_, entries) in enumerate(LAYERS):
        for entry in entries:
            covers = (module == entry if entry == "monoplane"
                      else _within(module, (entry,)))
            if covers and len(entry) > best:
                best, rank = len(entry), i
    assert rank >= 0, f"{module} is in no layer of LAYERS"
    return rank


def _layer(module: str) -> int:
    rank = _base_layer(module)
    if _FILES[module].name == "__init__.py" and module != "monoplane":
        own = [_layer(d) for d in _DEPENDENCIES[module] if d.startswith(module + ".")]
        rank = max([rank, *own])
    return rank


def _upward(table: dict[str, set[str]] = _DEPENDENCIES) -> dict[str, set[str]]:
    """Module -> the modules of a higher layer it imports, in any form."""
    found: dict[str, set[str]] = {}
    for module, deps in table.items():
        up = {d for d in deps if _layer(d) > _layer(module)
              and not (d.startswith(module + ".") and _FILES[module].name == "__init__.py")}
        if up:
            found[module] = up
    return found


def _listing(table: dict[str, set[str]]) -> str:
    return "\n".join(
        f"  {_FILES[m].relative_to(PACKAGE.parent)} -> {d} "
        f"({LAYERS[_layer(m)][0]} -> {LAYERS[_layer(d)][0]})"
        for m in sorted(table) for d in sorted(table[m]))


def test_every_module_has_a_layer() -> None:
    assert {m: LAYERS[_layer(m)][0] for m in ("monoplane", "monoplane.cues",
                                              "monoplane.cues.network",
                                              "monoplane.algorithm.ransac",
                                              "monoplane.algorithm.graphcut")} == {
        "monoplane": "facades", "monoplane.cues": "model catalogue",
        "monoplane.cues.network": "cue and feature libraries",
        "monoplane.algorithm.ransac": "algorithm drivers",
        "monoplane.algorithm.graphcut": "kernels"}
    for module in _FILES:
        _layer(module)


def test_every_layer_entry_names_a_module_or_package() -> None:
    stale = [e for _, entries in LAYERS for e in entries
             if not any(m == e or m.startswith(e + ".") for m in _FILES)]
    assert stale == [], "LAYERS names modules that no longer exist"


def test_the_layer_check_sees_an_import_back_up() -> None:
    table = {m: set(d) for m, d in _DEPENDENCIES.items()}
    table["monoplane.host.detect"].add("monoplane.report.colors")
    table["monoplane.geometry.cloud"].add("monoplane.contracts")
    up = _upward(table)
    assert "monoplane.report.colors" in up["monoplane.host.detect"]
    assert "monoplane.contracts" in up["monoplane.geometry.cloud"]
    # a package that re-exports a higher submodule stands as high as it
    assert _layer("monoplane.cues") > _layer("monoplane.cues.network")


def test_no_import_runs_back_up() -> None:
    up = _upward()
    new = {m: d - PENDING.get(m, set()) for m, d in up.items()}
    new = {m: d for m, d in new.items() if d}
    stale = {m: d - up.get(m, set()) for m, d in PENDING.items()}
    stale = {m: d for m, d in stale.items() if d}
    assert not new, f"imports that run back up the layers (file -> module):\n{_listing(new)}"
    assert not stale, ("PENDING lists imports that no longer run back up; remove them:\n"
                       + "\n".join(f"  {m} -> {d}" for m in sorted(stale)
                                    for d in sorted(stale[m])))


# --- imports inside functions ----------------------------------------------------------------

#: At most this many imports of our modules happen inside functions. Each one left defers a
#: heavy library (numba, SciPy, OpenCV, Open3D, pycolmap, onnxruntime, Ray, Rerun) or the
#: plugin system, and says so in a comment; an import that only broke a cycle or ran up the
#: layers goes to the top. Lower the cap as they go.
MAX_DEFERRED_IMPORTS = 77

#: Files (or folders) that defer every import of ours, and why (instead of a comment at each).
DEFERS_EVERYTHING = {
    "monoplane/testing.py": "pytest loads this plugin in every session of an environment "
                            "where monoplane is installed",
    "monoplane/cli/": "the parser imports every subcommand module; each loads what it runs "
                      "when it runs (all of them at once cost 0.35 s more per command)",
}


def _defers_everything(file: str) -> bool:
    return any(file == k or (k.endswith("/") and file.startswith(k)) for k in DEFERS_EVERYTHING)


def _deferred_imports() -> list[tuple[str, int, bool]]:
    """(file, line, has a comment on its line or just above its run of imports) of every
    import of our modules inside a function."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        lines = path.read_text().splitlines()
        for fn in ast.walk(ast.parse("\n".join(lines))):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.ImportFrom):
                    names = [node.module or ""]
                elif isinstance(node, ast.Import):
                    names = [alias.name for alias in node.names]
                else:
                    continue
                if not any(n.split(".")[0] == "monoplane" for n in names):
                    continue
                first = node.lineno - 1
                while first > 0 and lines[first - 1].strip().startswith(("from ", "import ")):
                    first -= 1
                said = "#" in lines[node.lineno - 1] or (
                    first > 0 and lines[first - 1].strip().startswith("#"))
                found.append((str(path.relative_to(PACKAGE.parent)), node.lineno, said))
    return found


def test_few_imports_happen_inside_functions() -> None:
    found = _deferred_imports()
    assert len(found) <= MAX_DEFERRED_IMPORTS, (
        f"{len(found)} imports of monoplane modules inside functions, at most "
        f"{MAX_DEFERRED_IMPORTS}: move the new ones to the top")
    files = {f for f, _, _ in found}
    stale = sorted(f for f in DEFERS_EVERYTHING
                   if not any(g == f or (f.endswith("/") and g.startswith(f)) for g in files))
    assert stale == [], "no import inside a function left in these: remove them from the lists"


def test_an_import_inside_a_function_says_what_it_defers() -> None:
    silent = [f"{f}:{line}" for f, line, said in _deferred_imports()
              if not said and not _defers_everything(f)]
    assert silent == [], "say in a comment what each of these defers, or move it to the top"


# --- names ------------------------------------------------------------------------------------

#: Names many modules define on purpose: hook implementations, the CLI's subcommand protocol
#: (``add_parser``, ``run``) and scripts' ``main``.
_PROTOCOL = re.compile(r"monoplane_\w+|add_parser|run|main")


def test_public_names_do_not_collide() -> None:
    """No two modules define a public function or class of the same name (one name, one
    meaning; ``orient_normals`` and ``FrameResult`` each named two different things)."""
    where: dict[str, list[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.parse(path.read_text()).body:
            if (isinstance(node, (ast.FunctionDef, ast.ClassDef))
                    and not node.name.startswith("_") and not _PROTOCOL.fullmatch(node.name)):
                where.setdefault(node.name, []).append(_module_name(path))
    assert {n: m for n, m in where.items() if len(m) > 1} == {}

