"""Global planes of a multi-view run: the fuser and adjuster calls, and what a fused scene
yields per plane (its colour, each view's global label map; its surface mesh is
:func:`monoplane.geometry.mesh.scene_mesh`).

Frames: world frame of the SfM model; cameras world-to-camera ``x_cam = R x_world + t``
(OpenCV axes); global planes ``normal . x_world + offset = 0``.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING, Any

import numpy as np

from monoplane.datamodel import Reconstruction, Scene, SfmResult
from monoplane.stages.base import Adjuster, Fuser

if TYPE_CHECKING:
    from monoplane.host.pipeline import Pipeline


def fuse_and_adjust(pipe: Pipeline, views: list[Reconstruction], sfm: SfmResult,
                    scales: list[float], timings: dict[str, float]
                    ) -> tuple[Scene, Scene, SfmResult, list[Any], dict[str, Any]]:
    """Run the configured fuser, then the adjuster, on scale-aligned views.

    Parameters
    ----------
    pipe : Pipeline
        Its ``fuser`` and ``adjuster`` stages are used.
    views : list of Reconstruction
        Per registered view, its planes with the depth in scene units.
    sfm : SfmResult
        Cameras and sparse points of those views, in scene units.
    scales : list of float
        Each view's depth scale (recorded on the scene).
    timings : dict
        Receives the seconds of ``fuser`` and ``adjuster``.

    Returns
    -------
    (Scene, Scene, SfmResult, list, dict)
        The refined scene, the scene as fused (before the adjuster), the SfM result with the
        refined cameras, the plane correspondences the fuser kept and the adjuster's report.
    """
    fuser = pipe.stage("fuser", Fuser)
    fused, plane_matches = pipe.call("fuser", fuser.name,
                                     lambda: fuser.fuse_with_matches(views, sfm), "multiview",
                                     timings)
    fused.scales = list(scales)
    adjuster = pipe.stage("adjuster", Adjuster)
    scene, sfm, adjustment = pipe.call("adjuster", adjuster.name,
                                       lambda: adjuster.adjust(fused, sfm), "multiview", timings)
    return scene, fused, sfm, plane_matches, adjustment


def scene_plane_colors(scene: Scene) -> np.ndarray:
    """(G, 3) uint8 area-weighted mean colour of each global plane over its views."""
    g = scene.planes.shape[0]
    sums = np.zeros((g, 3))
    weights = np.zeros(g)
    for v, table in enumerate(scene.links):
        colors, area = scene.views[v].colors, scene.views[v].area_px
        for local, glob in table.items():
            sums[glob] += area[local - 1] * colors[local - 1]
            weights[glob] += area[local - 1]
    out = np.full((g, 3), 128, np.uint8)
    ok = weights > 0
    out[ok] = np.clip(sums[ok] / weights[ok, None], 0, 255).astype(np.uint8)
    return out


def global_label_map(labels: np.ndarray, links: dict[int, int]) -> np.ndarray:
    """(H, W) uint16 map of global plane ids + 1 (0 = non-planar) from a view's local labels."""
    lut = np.zeros(int(labels.max()) + 1, dtype=np.uint16)
    for local, glob in links.items():
        if local < len(lut):
            lut[local] = glob + 1
    return lut[labels]


def __getattr__(name: str) -> Any:
    """``scene_mesh`` moved to :mod:`monoplane.geometry.mesh` in 0.2.0; the old path (this
    module was ``monoplane.multiview.fusion``) works until 0.3.0."""
    if name == "scene_mesh":
        # loads OpenCV, and a top-level import would make the old path skip the warning
        from monoplane.geometry.mesh import scene_mesh

        warnings.warn("monoplane.multiview.fusion.scene_mesh moved to "
                      "monoplane.geometry.mesh.scene_mesh; the old path goes in 0.3.0",
                      DeprecationWarning, stacklevel=2)
        return scene_mesh
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
