"""Global planes of a multi-view run: the fuser and adjuster calls. What a fused scene yields
per plane is the data model's (:func:`monoplane.datamodel.scene_plane_colors`,
:func:`monoplane.datamodel.global_label_map`) and geometry's
(:func:`monoplane.geometry.mesh.scene_mesh`); they are re-exported here.

Frames: world frame of the SfM model; cameras world-to-camera ``x_cam = R x_world + t``
(OpenCV axes); global planes ``normal . x_world + offset = 0``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from monoplane.contracts import Adjuster, Fuser
from monoplane.datamodel import (  # noqa: F401 - the last two: re-exported
    Reconstruction,
    Scene,
    SfmResult,
    global_label_map,
    scene_plane_colors,
)
from monoplane.deprecation import renamed_names

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


# scene_mesh moved in 0.2.0 (this module was monoplane.multiview.fusion); loaded on first use,
# since it loads OpenCV.
__getattr__ = renamed_names(__name__, {"scene_mesh": "monoplane.geometry.mesh:scene_mesh"})
