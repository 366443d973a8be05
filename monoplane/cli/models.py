"""``monoplane models``: list, fetch and locate the catalogue's monocular networks."""

from __future__ import annotations

import argparse
import json

from monoplane.cues.profile_files import BUILTIN_PROFILES, profile_to_toml
from monoplane.models import fetch, get_model, require_model
from monoplane.models.listing import (
    catalogue_rows,
    catalogue_table,
    fetch_summary,
    profile_named,
    unpinned_note,
)

DESCRIPTION = """Monocular depth/normal networks monoplane can download on request (ONNX exports
published on Hugging Face, pinned to a revision where one is known, checked by size and SHA-256).
Nothing is ever downloaded by 'monoplane run' unless you pass --fetch.

Cache: $MONOPLANE_CACHE, or ~/.cache/monoplane.

Your own ONNX file needs no catalogue entry: describe its input and outputs in a profile file
and run it with --set cues.profile=my_model.toml (docs/cues.md, 'Your own model');
'monoplane models profile NAME' prints a built-in profile in that form, to start from."""

BRING_YOUR_OWN = """your own ONNX depth/normals network: write a profile file (input name, layout, \
size, scaling; output name and kind) and run it with --set cues.profile=my_model.toml; \
'monoplane models profile NAME' prints a built-in profile ({names}) as a starting point \
(docs/cues.md, 'Your own model')"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("models", help="list, download and locate monocular models",
                       description=DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    msub = p.add_subparsers(dest="models_command", metavar="ACTION", required=True)
    ls = msub.add_parser("list", help="the catalogue: task, licence, size, profile, source")
    ls.add_argument("--json", action="store_true", help="machine-readable output")
    ls.set_defaults(func=run_list)
    fe = msub.add_parser("fetch", help="download a model into the cache and verify it")
    fe.add_argument("name", metavar="NAME", help="catalogue name (see 'monoplane models list')")
    fe.set_defaults(func=run_fetch)
    pa = msub.add_parser("path", help="print where a downloaded model is")
    pa.add_argument("name", metavar="NAME", help="catalogue name")
    pa.set_defaults(func=run_path)
    pr = msub.add_parser("profile", help="print a profile as a profile file (TOML), the "
                                         "starting point for your own model's")
    pr.add_argument("name", metavar="NAME",
                    help="built-in profile, catalogue name, or a profile file to check")
    pr.set_defaults(func=run_profile)


def run_list(args: argparse.Namespace) -> int:
    if args.json:
        print(json.dumps(catalogue_rows(), indent=2))
        return 0
    print(catalogue_table())
    print("\n" + BRING_YOUR_OWN.format(names=", ".join(sorted(BUILTIN_PROFILES))))
    return 0


def run_fetch(args: argparse.Namespace) -> int:
    record = get_model(args.name)
    note = unpinned_note(record)
    if note:
        print(f"note: {note}")
    print(fetch_summary(record, fetch(args.name)))
    return 0


def run_path(args: argparse.Namespace) -> int:
    print(require_model(args.name))
    return 0


def run_profile(args: argparse.Namespace) -> int:
    """Print a built-in, catalogue or file profile as profile-file TOML (files are checked)."""
    print(profile_to_toml(profile_named(args.name)), end="")
    return 0
