"""Sparse-view planar reconstruction (paper §III-C, and past it): SfM, plane-aware registration,
scale alignment, per-view planes, fusion and joint refinement.

Python API::

    from monoplane.export import save
    from monoplane.host.pipeline import Pipeline
    from monoplane.multiview import reconstruct_multiview
    pipe = Pipeline.from_preset("monoplane")
    result = reconstruct_multiview([frame_a, frame_b], pipe, progress=True)
    save(result, "out/")

Steps (:func:`~monoplane.multiview.driver.reconstruct_multiview`):

1. the configured matcher (``[matcher]``) gives cameras, sparse points and keypoint matches;
2. the cue provider fills each view's depth and normals and the single-view pipeline segments
   each view (in the view pool of :mod:`monoplane.host.view_pool`, while SfM runs when the
   matcher keeps every ``K`` as given: neither depends on the depth's scale);
3. each registered view's depth is scaled onto the SfM points
   (:mod:`~monoplane.multiview.registration`); the registrar (``[registrar]``) places the views
   the matcher left out, from their planes, normals, depth and whatever feature matches exist;
   when every view's depth is metric the world is then expressed in the depth's units;
4. the fuser (``[fuser]``) matches and fuses planes into a :class:`~monoplane.datamodel.Scene`
   and the adjuster (``[adjuster]``) refines it (:mod:`~monoplane.multiview.global_planes`);
5. :func:`monoplane.export.save` writes it (the formats of :mod:`monoplane.export`).

Frames: cameras are world-to-camera ``x_cam = R x_world + t`` with OpenCV axes (x right, y down,
z forward).
"""

from monoplane.datamodel import global_label_map, scene_plane_colors
from monoplane.geometry.mesh import scene_mesh
from monoplane.multiview.driver import MultiviewResult, reconstruct_multiview
from monoplane.multiview.registration import (
    hold_given_intrinsics,
    hold_intrinsics_fixed,
    matcher_keeps_intrinsics,
    origin_sfm,
    rescale_reconstruction,
    scale_sfm,
    structure_from_motion,
    subset_sfm,
)
from monoplane.multiview.summaries import scene_summary, sfm_summary, unregistered_names
from monoplane.multiview.writers import (
    cameras_document,
    save_scene,
    save_sfm,
    scene_document,
    write_points_ply,
)

__all__ = [
    "MultiviewResult", "cameras_document", "global_label_map", "hold_given_intrinsics",
    "hold_intrinsics_fixed", "matcher_keeps_intrinsics", "origin_sfm", "reconstruct_multiview",
    "rescale_reconstruction", "save_scene", "save_sfm", "scale_sfm", "scene_document",
    "scene_mesh", "scene_plane_colors", "scene_summary", "sfm_summary", "structure_from_motion",
    "subset_sfm", "unregistered_names", "write_points_ply",
]
