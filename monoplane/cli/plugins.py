"""``monoplane plugins``: every registered stage with its provider and parameters."""

from __future__ import annotations

import argparse
import json

from monoplane.host.registry import AUTOLOAD_ENV, autoload_enabled, get_registry
from monoplane.stages.base import STAGE_KINDS


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plugins", help="list stage plugins: kind, name, provider, version, parameters",
        description="List every stage registered through the 'monoplane' pluggy hooks: built-ins "
                    "and third-party packages found via the 'monoplane' entry-point group "
                    f"(set {AUTOLOAD_ENV}=1 to disable autoloading).")
    p.add_argument("--kind", choices=STAGE_KINDS, help="only this stage kind")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    infos = [i for i in get_registry().all() if args.kind in (None, i.kind)]
    if args.json:
        print(json.dumps([{
            "kind": i.kind, "name": i.name, "provider": i.provider, "version": i.version,
            "parameters": [{"name": n, "type": t, "default": d, "doc": doc}
                           for n, t, d, doc in i.cls.parameters()],
        } for i in infos], indent=2, default=str))
        return 0
    if not autoload_enabled():
        print(f"(third-party autoload disabled by {AUTOLOAD_ENV})")
    for i in infos:
        print(f"{i.kind:8s} {i.name:22s} {i.provider} {i.version}")
        for key, type_name, default, doc in i.cls.parameters():
            print(f"{'':9s}{key} ({type_name}, default {default!r}): {doc}")
    return 0
