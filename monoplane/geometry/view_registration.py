"""Relative pose of two views from their depth, normals and planes, with or without features.

Two views that structure from motion could not connect still carry dense geometry: a depth map
(metric, or known up to a scale), per-pixel normals and a plane segmentation. This module turns
that into pose hypotheses and checks each hypothesis against all of it.

Hypotheses (``s·X_v = R·X_r + t``: a point ``X_r`` of the reference camera, in the reference
depth's units, seen by the other view at ``X_v`` in that view's own depth units; ``s`` is the
other view's depth scale, fixed to the reference's when both depths are metric):

* **3D feature matches**: putative keypoint matches lifted with both depths; a rigid (metric) or
  similarity (relative depth) fit on three matches, RANSAC (:func:`feature_hypotheses`);
* **plane-pair rotations**: two non-parallel planes of one view matched to two planes of the
  other with the same dihedral angle give the rotation without any scale; the dominant
  directions of a room (Manhattan or Atlanta frames) are the common case
  (:func:`rotation_hypotheses`). The translation and scale then come
  - from feature matches, two of which fix them once the rotation is known
    (:func:`translation_from_matches`), or
  - from the plane offsets: planes matched by their rotated normals satisfy
    ``n_v·t + s·d_v = d_r``, linear in ``(t, s)`` (:func:`translation_from_planes`);
* **FPFH + RANSAC** (Open3D's global registration) on metric depth (:func:`fpfh_hypothesis`).

Every hypothesis is verified by dense agreement (:func:`agreement`): each view's points moved
into the other view must land on its depth (relative depth error and normal angle), and points
landing in front of the surface the other view sees are free-space violations. The best one is
refined by ICP (Open3D, point-to-plane on metric depth, point-to-point with scale otherwise) and
kept only if the refinement does not lower its agreement.

The pieces live in :mod:`~monoplane.geometry.view_agreement` (view samples, hypotheses, dense
agreement), :mod:`~monoplane.geometry.pose_hypotheses` (the minimal solvers),
:mod:`~monoplane.geometry.open3d_registration` (FPFH, ICP) and :mod:`~monoplane.geometry.epipolar`
(epipolar checks and refinement); this module gathers their public names, so
``from monoplane.geometry.view_registration import agreement`` keeps working.

Frames: OpenCV camera axes (x right, y down, z forward); pixel centres at integer coordinates.
"""

from monoplane.geometry.epipolar import depth_disagreement, epipolar_support, refine_epipolar
from monoplane.geometry.open3d_registration import fpfh_hypothesis, refine_icp
from monoplane.geometry.pose_hypotheses import (
    feature_hypotheses,
    rotation_deg,
    rotation_hypotheses,
    translation_from_matches,
    translation_from_planes,
)
from monoplane.geometry.view_agreement import (
    Agreement,
    Hypothesis,
    ViewGeometry,
    agreement,
    view_geometry,
)

__all__ = [
    "Agreement", "Hypothesis", "ViewGeometry", "agreement", "depth_disagreement",
    "epipolar_support", "feature_hypotheses", "fpfh_hypothesis", "refine_epipolar",
    "refine_icp", "rotation_deg", "rotation_hypotheses", "translation_from_matches",
    "translation_from_planes", "view_geometry",
]
