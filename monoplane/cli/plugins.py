"""``monoplane plugins``: every registered stage and output format with its provider."""

from __future__ import annotations

import argparse
import json

from monoplane.contracts import STAGE_KINDS
from monoplane.export.saving import get_exporters
from monoplane.host.registry import AUTOLOAD_ENV, autoload_enabled, get_plugin_manager, get_registry

#: The ``--kind`` of output formats (stage kinds are the others).
EXPORTER_KIND = "exporter"


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plugins", help="list stage plugins and output formats: kind, name, provider, version",
        description="List every stage and output format registered through the 'monoplane' "
                    "pluggy hooks: built-ins and third-party packages found via the "
                    f"'monoplane' entry-point group (set {AUTOLOAD_ENV}=1 to disable "
                    "autoloading). Stages show their parameters, output formats the files "
                    "they write per result kind and whether they are written by default.")
    p.add_argument("--kind", choices=(*STAGE_KINDS, EXPORTER_KIND),
                   help="only this stage kind, or 'exporter' for the output formats")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    pm = get_plugin_manager()
    infos = [i for i in get_registry(pm).all() if args.kind in (None, i.kind)]
    exporters = get_exporters(pm) if args.kind in (None, EXPORTER_KIND) else []
    if args.json:
        print(json.dumps([{
            "kind": i.kind, "name": i.name, "provider": i.provider, "version": i.version,
            "parameters": [{"name": n, "type": t, "default": d, "doc": doc}
                           for n, t, d, doc in i.cls.parameters()],
        } for i in infos] + [{
            "kind": EXPORTER_KIND, "name": e.exporter.name, "provider": e.provider,
            "version": e.version, "parameters": [], "default": e.exporter.default,
            "files": {k: list(v) for k, v in e.exporter.files.items()},
            "summary": e.exporter.summary,
        } for e in exporters], indent=2, default=str))
        return 0
    if not autoload_enabled():
        print(f"(third-party autoload disabled by {AUTOLOAD_ENV})")
    for i in infos:
        print(f"{i.kind:8s} {i.name:22s} {i.provider} {i.version}")
        for key, type_name, default, doc in i.cls.parameters():
            print(f"{'':9s}{key} ({type_name}, default {default!r}): {doc}")
    for e in exporters:
        x = e.exporter
        print(f"{EXPORTER_KIND:8s} {x.name:22s} {e.provider} {e.version}"
              f"{'' if x.default else '  (off by default)'}")
        if x.summary:
            print(f"{'':9s}{x.summary}")
        for kind, files in x.files.items():
            print(f"{'':9s}{kind}: {', '.join(files)}")
    return 0
