"""``monoplane models``: list, fetch and locate the catalogue's monocular networks."""

from __future__ import annotations

import argparse
import json

from monoplane.cues.profile_files import (
    BUILTIN_PROFILES,
    get_profile,
    is_profile_file,
    load_profile_file,
    profile_to_toml,
)
from monoplane.errors import InvalidInput
from monoplane.models import (
    CATALOGUE,
    cache_dir,
    cached_model,
    fetch,
    get_model,
    model_path,
    require_model,
)
from monoplane.models.catalogue import ModelRecord

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


def _status(record: ModelRecord) -> str:
    try:
        return "cached" if cached_model(record.name) is not None else "-"
    except InvalidInput:  # a wrong-size copy: say so in the listing, do not fail it
        return "broken"


def _size(record: ModelRecord) -> str:
    return "?" if record.size is None else f"{record.size / 1e6:.0f} MB"


def run_list(args: argparse.Namespace) -> int:
    records = [CATALOGUE[n] for n in sorted(CATALOGUE)]
    if args.json:
        rows = [{**r.to_dict(), "cached": _status(r) == "cached", "path": str(model_path(r))}
                for r in records]
        print(json.dumps(rows, indent=2))
        return 0
    table = [("name", "task", "licence", "size", "profile", "cached", "source")]
    for r in records:
        rev = r.revision[:10] if r.pinned else f"{r.revision} (unpinned)"
        table.append((r.name, r.task, r.licence.split(" ")[0], _size(r), r.profile, _status(r),
                     f"{r.repo}@{rev}:{r.filename}"))
    widths = [max(len(row[i]) for row in table) for i in range(len(table[0]) - 1)]
    for row in table:
        print("  ".join(c.ljust(w) for c, w in zip(row[:-1], widths, strict=False)) + "  "
              + row[-1])
    print(f"\ncache: {cache_dir()}")
    for r in records:
        print(f"  {r.name}: {r.summary}; licence {r.licence}")
    print("\n" + BRING_YOUR_OWN.format(names=", ".join(sorted(BUILTIN_PROFILES))))
    return 0


def run_fetch(args: argparse.Namespace) -> int:
    record = get_model(args.name)
    if not record.pinned:
        print(f"note: {record.name} follows the branch {record.revision!r} (no commit hash "
              f"pinned); the size and hash checks guard against a changed file")
    result = fetch(args.name)
    verb = "downloaded" if result.downloaded else "already cached"
    print(f"{record.name}: {verb}, verified -> {result.path}")
    pinned = "matches the catalogue" if record.sha256 and len(record.sha256) == 64 else (
        "not fully pinned in the catalogue: pin it")
    print(f"sha256 {result.sha256} ({pinned})")
    return 0


def run_path(args: argparse.Namespace) -> int:
    print(require_model(args.name))
    return 0


def run_profile(args: argparse.Namespace) -> int:
    """Print a built-in, catalogue or file profile as profile-file TOML (files are checked)."""
    name = args.name
    if is_profile_file(name):
        profile = load_profile_file(name).profile
    elif name in CATALOGUE:
        record = CATALOGUE[name]
        if record.task == "features":
            raise InvalidInput(f"{name} is a features model (the '{record.profile}' features "
                               "stage runs it); only depth and normals models have a profile")
        profile = get_profile(record.profile)
    else:
        profile = get_profile(name)
    print(profile_to_toml(profile), end="")
    return 0

