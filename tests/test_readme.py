"""The README's command synopsis, presets table and setup text agree with the code and setup.sh,
so none of them goes stale.

Both checks read content, not layout: the synopsis is every fenced block of the README's
"Command line" section, a command being a line that starts with ``monoplane NAME`` plus its
``\\`` continuation lines, and comments (`` # ...``) ignored; the presets table is the Markdown
table whose first header cell is "preset", read by column name.
"""

import argparse
import re
from pathlib import Path

import pytest

from monoplane.cli import SUBCOMMANDS, build_parser
from monoplane.contracts import STAGE_KINDS
from monoplane.host import config

README = Path(__file__).resolve().parents[1] / "README.md"
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")


def _section(text: str, title: str) -> str:
    """The body of the first heading containing ``title``, up to the next heading of the same
    or a higher level."""
    match = re.search(rf"^(#+) [^\n]*{re.escape(title)}[^\n]*$", text, re.M)
    assert match, f"README has no heading with {title!r}"
    level = len(match.group(1))
    end = re.compile(rf"^#{{1,{level}}} ", re.M).search(text, match.end())
    return text[match.end():end.start() if end else len(text)]


def _synopsis() -> dict[str, set[str]]:
    """Flags per command in the synopsis block(s)."""
    body = _section(README.read_text(), "Command line")
    blocks = re.findall(r"^```[^\n]*\n(.*?)^```", body, re.M | re.S)
    assert blocks, "no code block in the README's Command line section"
    flags: dict[str, set[str]] = {}
    command = None
    continued = False
    for block in blocks:
        for raw in block.splitlines():
            line = re.sub(r"\s#\s.*$", "", raw).rstrip()
            words = line.split()
            if not continued:
                command = words[1] if len(words) > 1 and words[0] == "monoplane" else None
            if command:
                flags.setdefault(command, set()).update(FLAG.findall(line))
            continued = line.endswith("\\")
    return flags


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _parser_flags(parser: argparse.ArgumentParser) -> set[str]:
    """Long options of a (sub)command, its nested actions' included (``models list --json``)."""
    flags = {o for a in parser._actions for o in a.option_strings
             if o.startswith("--") and o != "--help"}
    for nested in _subparsers(parser).values():
        flags |= _parser_flags(nested)
    return flags


def test_synopsis_lists_every_command_and_flag_and_no_other():
    synopsis = _synopsis()
    commands = _subparsers(build_parser())
    assert set(commands) == set(SUBCOMMANDS)
    assert set(synopsis) == set(SUBCOMMANDS), "commands missing from or unknown to the synopsis"
    problems = []
    for name, parser in commands.items():
        real = _parser_flags(parser)
        if real - synopsis[name]:
            problems.append(f"monoplane {name}: not in the README: {sorted(real - synopsis[name])}")
        if synopsis[name] - real:
            problems.append(f"monoplane {name}: in the README, unknown to the command: "
                            f"{sorted(synopsis[name] - real)}")
    assert not problems, "\n".join(problems)


def test_synopsis_names_every_models_action():
    body = _section(README.read_text(), "Command line")
    lines = " ".join(line for line in body.splitlines() if line.startswith("monoplane models"))
    for action in _subparsers(_subparsers(build_parser())["models"]):
        assert re.search(rf"\b{action}\b", lines), f"'monoplane models {action}' not in README"


def _preset_table() -> tuple[list[str], dict[str, list[str]], str]:
    """Header, rows by preset name, and the text of the README's presets section."""
    body = _section(README.read_text(), "Presets")
    lines = [line.strip() for line in body.splitlines() if line.strip().startswith("|")]
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in lines]
    starts = [i for i, row in enumerate(cells) if row[0].lower() == "preset"]
    assert starts, "no table with a 'preset' column in the README's Presets section"
    header = [h.lower() for h in cells[starts[0]]]
    rows: dict[str, list[str]] = {}
    for row in cells[starts[0] + 1:]:
        if set("".join(row)) <= set("-: "):
            continue  # the separator line
        name = re.search(r"`([^`]+)`", row[0])
        assert name, f"preset cell without a `name`: {row[0]!r}"
        rows[name.group(1)] = row
    return header, rows, body


def _plugin(cell: str) -> str:
    """The plugin a cell names: its first word (remarks may follow, e.g. "plane-aware, ...")."""
    match = re.match(r"[`*]*([\w+.-]+)", cell)
    assert match, f"cell names no plugin: {cell!r}"
    return match.group(1)


def test_preset_table_matches_the_shipped_presets():
    header, rows, body = _preset_table()
    presets = config.list_presets()
    assert set(rows) == set(presets), "presets missing from or unknown to the README table"
    columns = [h for h in header[1:]]
    assert set(columns) <= set(STAGE_KINDS), f"columns that are not stage kinds: {columns}"
    resolved = {name: config.load(preset=name) for name in presets}
    problems = []
    for name, row in rows.items():
        assert len(row) == len(header), f"row {name}: {len(row)} cells for {len(header)} columns"
        stages = resolved[name].stages
        for kind, cell in zip(columns, row[1:], strict=True):
            if _plugin(cell) != stages[kind][0]:
                problems.append(f"{name}.{kind}: README says {_plugin(cell)!r}, preset has "
                                f"{stages[kind][0]!r}")
        if ("(default)" in row[0]) != (name == config.DEFAULT_PRESET):
            problems.append(f"{name}: '(default)' marks the default preset, "
                            f"{config.DEFAULT_PRESET!r}, and only it")
    # A stage kind without a column must use one plugin in every preset, named in the text.
    for kind in set(STAGE_KINDS) - set(columns):
        used = {resolved[name].stages[kind][0] for name in presets}
        if len(used) > 1:
            problems.append(f"{kind}: presets differ ({sorted(used)}); add a column")
        elif f"`{used.pop()}` {kind}" not in body:
            problems.append(f"{kind}: the Presets section should name its one plugin as "
                            f"'`PLUGIN` {kind}'")
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("text, plugin", [("plane-aware, feature sources only", "plane-aware"),
                                          ("`dense-crf`", "dense-crf"), ("none", "none")])
def test_plugin_cells_read_their_first_word(text, plugin):
    assert _plugin(text) == plugin


def test_setup_text_matches_setup_sh():
    """The README's Setup section names the extras and system packages setup.sh installs."""
    script = (README.parent / "setup.sh").read_text()
    setup = _section(README.read_text(), "Setup")
    extras = re.search(r'pip install --quiet -e "(\.\[[^\]]*\])"', script)
    assert extras, "setup.sh no longer runs pip install -e \".[...]\""
    assert f'pip install -e "{extras.group(1)}"' in setup, (
        f"the README's Setup section should say setup.sh runs pip install -e \"{extras.group(1)}\"")
    packages = re.search(r'^APT_PACKAGES="([^"]*)"', script, re.M)
    assert packages, "setup.sh no longer lists APT_PACKAGES"
    named = set(re.findall(r"[\w.+-]+", setup))
    missing = [p for p in packages.group(1).split() if p not in named]
    assert not missing, f"system packages setup.sh installs, not named in the README: {missing}"
    assert "monoplane.warmup" in script and "monoplane.warmup" in setup
