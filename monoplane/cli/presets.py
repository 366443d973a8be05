"""``monoplane presets``: list shipped presets or print one fully resolved."""

from __future__ import annotations

import argparse

from monoplane.host import config


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("presets", help="list presets, or show one resolved with all parameters",
                       description="Without NAME, list the shipped presets (the paper's ablation "
                                   "rows). With NAME, print its resolved TOML, a starting point "
                                   "for your own --config file.")
    p.add_argument("name", nargs="?", metavar="NAME", help="preset to print")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.name is None:
        for name in config.list_presets():
            mark = "  (default)" if name == config.DEFAULT_PRESET else ""
            print(f"{name}{mark}")
        return 0
    print(config.load(preset=args.name).to_toml(), end="")
    return 0
