"""What ``monoplane match`` writes (:func:`save_sfm`: ``cameras.json`` and ``points.ply``),
atomically.

A multi-view result is written by :func:`monoplane.export.save`, like every result (the
formats' modules in :mod:`monoplane.export` say what each file holds); :func:`save_scene` and
:func:`write_global_labels` are its deprecated former writers, :func:`scene_document`,
:func:`cameras_document` and :func:`write_points_ply` are re-exported from there.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from monoplane.datamodel import SfmResult, global_label_map
from monoplane.export.files import atomic_output_dir, write_points_ply
from monoplane.export.labels import (  # noqa: F401 - scene_document: re-exported
    cameras_document,
    scene_document,
    write_json,
)
from monoplane.export.saving import save

if TYPE_CHECKING:
    from monoplane.multiview.driver import MultiviewResult


def save_sfm(sfm: SfmResult, out_dir: str | Path, overwrite: bool = False) -> Path:
    """Write ``cameras.json`` and ``points.ply`` of an SfM result atomically into ``out_dir``."""
    with atomic_output_dir(out_dir, overwrite) as tmp:
        keep = [v for v, ok in enumerate(sfm.registered) if ok]
        doc = cameras_document([sfm.cameras[v] for v in keep],
                               [sfm.registration[v] for v in keep] if sfm.registration else None,
                               [c.name for c, ok in zip(sfm.cameras, sfm.registered,
                                                        strict=True) if not ok])
        doc["num_points"] = int(len(sfm.points))
        doc["matches"] = [{"images": [sfm.cameras[i].name, sfm.cameras[j].name],
                           "verified_matches": int(len(m))}
                          for (i, j), m in sorted(sfm.matches.items())]
        doc["notes"] = list(sfm.notes)
        write_json(tmp / "cameras.json", doc)
        write_points_ply(tmp / "points.ply", sfm.points, sfm.colors)
    return Path(out_dir)


def write_global_labels(path: Path, labels: np.ndarray, links: dict[int, int]) -> None:
    """Deprecated (the ``labels`` format writes it): ``labels_global.png``, 16-bit PNG, value
    = global plane id + 1, 0 = non-planar."""
    _deprecated("write_global_labels", "monoplane.export.save")
    cv2.imwrite(str(path), global_label_map(labels, links))


def save_scene(result: MultiviewResult, out_dir: str | Path, overwrite: bool = False,
               report: bool = False) -> Path:
    """Deprecated: :func:`monoplane.export.save`, which writes the same folder (pass
    ``also=lambda tmp: write_scene_report(result.scene, tmp)`` for the report)."""
    _deprecated("save_scene", "monoplane.export.save")
    also = None
    if report:
        # the one import that runs up the layers (PENDING in tests/test_layers.py): only the
        # deprecated report=True needs the report, and it goes in 0.3.0
        from monoplane.report import write_scene_report

        def also(tmp: Path) -> None:
            write_scene_report(result.scene, tmp)
    return save(result, out_dir, overwrite, also=also)


def _deprecated(old: str, new: str) -> None:
    warnings.warn(f"monoplane.multiview.{old} is deprecated; use {new} (the old name goes in "
                  "0.3.0)", DeprecationWarning, stacklevel=3)
