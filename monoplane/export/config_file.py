"""The ``config`` output format: ``config.toml``, the resolved configuration of the run.

A frame's file starts with a comment saying how to rerun with it (``monoplane run ...
--config config.toml``); a point cloud's holds the tables alone.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from monoplane.contracts.exporter import Exporter
from monoplane.export.shared import SharedWork
from monoplane.hookspecs import hookimpl
from monoplane.host.config import dumps_toml

#: First line of a frame's ``config.toml``.
RERUN_COMMENT = "# Resolved monoplane config; rerun with: monoplane run ... --config config.toml\n"


def _write(result: Any, folder: Path, shared: SharedWork) -> None:
    head = RERUN_COMMENT if result.result_kind == "frame" else ""
    (folder / "config.toml").write_text(head + dumps_toml(result.config))


EXPORTER = Exporter(
    name="config",
    files={"frame": ("config.toml",), "cloud": ("config.toml",)},
    write=_write,
    summary="the resolved configuration, config.toml (rerun with --config)",
)


@hookimpl
def monoplane_register_exporters() -> list[Exporter]:
    return [EXPORTER]
