"""A third-party output format, as a plugin package would ship it: ``planes.csv``, one row per
plane of a frame or a point cloud (id, normal, offset, support).

It imports only the public plugin API. The tests install it through the ``monoplane``
entry-point group (a distribution's metadata on ``sys.path``), as ``pip install`` would.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from monoplane.plugin import Exporter, hookimpl


def write_csv(result: Any, folder: Path, shared: Any) -> None:
    rows = ["id,nx,ny,nz,offset,support"]
    rows += [",".join([str(pid), *(f"{v:.6f}" for v in plane), str(n)])
             for pid, plane, n in zip(result.ids, result.planes, result.support, strict=True)]
    (folder / "planes.csv").write_text("\n".join(rows) + "\n")


CSV = Exporter(name="planes-csv", files={"frame": ("planes.csv",), "cloud": ("planes.csv",)},
               write=write_csv, summary="the planes as CSV rows")


@hookimpl
def monoplane_register_exporters() -> list[Exporter]:
    return [CSV]
