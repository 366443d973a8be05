"""The command line only parses, calls the library and prints: checked on its source.

Work a command needs (formatting a library report, reading a file format, deciding from a
stage's answers) belongs in the library, where a Python caller gets it too; these rules catch
it when it creeps back into ``monoplane/cli``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

CLI = Path(__file__).resolve().parents[2] / "monoplane" / "cli"
SOURCES = {p.name: ast.parse(p.read_text()) for p in sorted(CLI.glob("*.py"))}

#: Longest function body allowed: a command's ``run`` parses, calls and prints in this many
#: lines; ``add_parser`` only declares arguments (help texts make it long).
MAX_LINES = 40
MAX_PARSER_LINES = 100


def _functions(tree: ast.AST) -> list[ast.FunctionDef]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)]


def _called(node: ast.AST) -> set[str]:
    """Names of the functions and methods called anywhere below ``node``."""
    names = set()
    for call in (n for n in ast.walk(node) if isinstance(n, ast.Call)):
        func = call.func
        names.add(func.id if isinstance(func, ast.Name) else getattr(func, "attr", ""))
    return names


def test_the_rules_see_every_command() -> None:
    assert {"run.py", "match.py", "multiview.py", "eval.py", "bench.py"} <= set(SOURCES)
    assert sum(len(_functions(t)) for t in SOURCES.values()) > 30


@pytest.mark.parametrize("module", sorted(SOURCES))
def test_functions_are_short(module: str) -> None:
    long = {f.name: f.end_lineno - f.lineno + 1 for f in _functions(SOURCES[module])
            if f.end_lineno - f.lineno + 1 > (MAX_PARSER_LINES if f.name == "add_parser"
                                              else MAX_LINES)}
    assert long == {}


@pytest.mark.parametrize("module", sorted(SOURCES))
def test_loops_only_print_or_add_subcommands(module: str) -> None:
    loops = [n for n in ast.walk(SOURCES[module]) if isinstance(n, (ast.For, ast.While))]
    computing = [n.lineno for n in loops
                 if isinstance(n, ast.While) or not _called(n) & {"print", "add_parser"}]
    assert computing == []


@pytest.mark.parametrize("module", sorted(SOURCES))
def test_no_private_name_of_the_library_is_used(module: str) -> None:
    private = [f"{n.module}.{a.name}" for n in ast.walk(SOURCES[module])
               if isinstance(n, ast.ImportFrom) and (n.module or "").startswith("monoplane")
               for a in n.names if a.name.startswith("_") and not a.name.startswith("__")]
    private += [n.attr for n in ast.walk(SOURCES[module])
                if isinstance(n, ast.Attribute) and n.attr.startswith("_")
                and not n.attr.startswith("__")
                # argparse's own types (_SubParsersAction, _ArgumentGroup) in annotations
                and not (isinstance(n.value, ast.Name) and n.value.id == "argparse")]
    assert private == []


def test_a_computing_loop_or_a_long_function_would_be_caught() -> None:
    tree = ast.parse("def run(args):\n    total = 0\n    for x in args.values:\n"
                     "        total += x * x\n" + "    pass\n" * MAX_LINES)
    (loop,) = [n for n in ast.walk(tree) if isinstance(n, ast.For)]
    assert not _called(loop) & {"print", "add_parser"}
    (func,) = _functions(tree)
    assert func.end_lineno - func.lineno + 1 > MAX_LINES
