"""The ``depth`` output format: ``depth_planar.npy``, the depth each pixel's plane implies.

(H, W) float32 z-depth in the frame's depth units along each pixel's ray
(:meth:`monoplane.datamodel.Reconstruction.planar_depth`); 0 on non-planar pixels. Frames
only (in a multi-view result, each view's folder).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monoplane.contracts.exporter import Exporter
from monoplane.datamodel import Reconstruction
from monoplane.export.shared import SharedWork
from monoplane.hookspecs import hookimpl


def _write(result: Reconstruction, folder: Path, shared: SharedWork) -> None:
    np.save(folder / "depth_planar.npy", result.planar_depth())


EXPORTER = Exporter(
    name="depth",
    files={"frame": ("depth_planar.npy",)},
    write=_write,
    summary="the planes' depth map, depth_planar.npy (float32, depth units, 0 = no plane)",
)


@hookimpl
def monoplane_register_exporters() -> list[Exporter]:
    return [EXPORTER]
