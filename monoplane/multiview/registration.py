"""Where each view stands: SfM bookkeeping, scale alignment onto the SfM points, and the
registrar call that places the views the matcher left out.

Frames: cameras are world-to-camera ``x_cam = R x_world + t`` with OpenCV axes (x right, y down,
z forward).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from monoplane.contracts import FeatureMatcher, Matcher
from monoplane.datamodel import Camera, Frame, Reconstruction, SfmResult
from monoplane.errors import InvalidInput
from monoplane.features import Correspondences
from monoplane.geometry.alignment import ScaleAlignment, align_scale

if TYPE_CHECKING:
    from monoplane.host.pipeline import Pipeline


def feature_correspondences(pipe: Pipeline, frames: list[Frame]) -> Correspondences:
    """The ``[features]`` stage's keypoints and matches of ``frames``, computed on demand."""
    return Correspondences(pipe.stage("features", FeatureMatcher), frames)


def match_views(pipe: Pipeline, frames: list[Frame], found: Correspondences, label: str,
                timings: dict[str, float]) -> SfmResult:
    """Run the ``[matcher]`` (SfM) on ``frames`` with the features stage's correspondences.

    They go to a matcher that declares ``uses_correspondences`` and, whatever the matcher did
    with them, ride along in the result (``SfmResult.correspondences``) for the registrar.
    When the matcher imports them (a stage without an SfM-native counterpart, e.g. XFeat),
    every pair is matched first, under the ``features`` stage's name, so that a features
    failure (a missing model file) is reported as such and not taken for an SfM failure.

    Parameters
    ----------
    pipe : Pipeline
        Configured pipeline.
    frames : list of Frame
        The views, with ``rgb``.
    found : Correspondences
        From :func:`feature_correspondences` on the same frames.
    label : str
        Name for the stage timings hook (``"multiview"``, ``"match"``).
    timings : dict
        Wall seconds per stage kind, added to.

    Raises
    ------
    monoplane.errors.StageError
        From either stage (``kind`` says which); the multi-view driver treats the matcher's
        as "no model" and places the views with the registrar.
    """
    matcher = pipe.stage("matcher", Matcher)
    if matcher.uses_correspondences and found.sfm_native is None:
        pipe.call("features", found.name, found.all_matches, label, timings)
    if matcher.uses_correspondences:
        sfm = pipe.call("matcher", matcher.name, lambda: matcher.match(frames, found), label,
                        timings)
    else:
        sfm = pipe.call("matcher", matcher.name, lambda: matcher.match(frames), label, timings)
    return replace(sfm, correspondences=found)


def structure_from_motion(pipe: Pipeline, frames: list[Frame], label: str = "match",
                          timings: dict[str, float] | None = None) -> SfmResult:
    """The ``[features]`` stage's correspondences of ``frames`` and the ``[matcher]``'s model
    of them, in one call (:func:`feature_correspondences`, then :func:`match_views`).

    Parameters
    ----------
    pipe : Pipeline
        Configured pipeline (see :func:`hold_intrinsics_fixed` to keep the frames' ``K``).
    frames : list of Frame
        The views, with ``rgb``; two or more.
    label : str
        Name for the stage timings hook.
    timings : dict, optional
        Wall seconds per stage kind (``features`` when matched first, ``matcher``), added to.

    Returns
    -------
    SfmResult
        World-to-camera cameras (OpenCV axes), sparse points, verified matches and the
        correspondences; ``registered`` says which views the matcher placed.

    Raises
    ------
    monoplane.errors.StageError
        From the features stage or the matcher (``kind`` says which).
    """
    timings = {} if timings is None else timings
    return match_views(pipe, frames, feature_correspondences(pipe, frames), label, timings)


def scale_sfm(sfm: SfmResult, factor: float) -> SfmResult:
    """The same SfM model with world coordinates multiplied by ``factor`` (> 0).

    Rotations and intrinsics are unchanged; translations and points scale.
    """
    if not factor > 0:
        raise InvalidInput(f"SfM scale factor must be positive, got {factor}")
    cameras = [replace(c, t=c.t * factor) for c in sfm.cameras]
    return replace(sfm, cameras=cameras, points=sfm.points * factor)


def subset_sfm(sfm: SfmResult, views: list[int]) -> SfmResult:
    """The SfM result restricted to ``views`` (indices, increasing), matches re-keyed."""
    pos = {v: k for k, v in enumerate(views)}
    matches = {(pos[i], pos[j]): m for (i, j), m in sfm.matches.items()
               if i in pos and j in pos}
    registration = [sfm.registration[v] for v in views] if sfm.registration else []
    return replace(sfm, correspondences=None, cameras=[sfm.cameras[v] for v in views],
                   keypoints=[sfm.keypoints[v] for v in views],
                   point_ids=[sfm.point_ids[v] for v in views], matches=matches,
                   registration=registration)


def origin_sfm(frames: list[Frame], reason: str) -> SfmResult:
    """A point-less SfM result whose world frame is view 0's camera; other views unplaced.

    Used when the matcher builds no model at all, so that the registrar can still place the
    views (each frame's ``K`` is taken as is).
    """
    n = len(frames)
    cameras = [Camera(K=f.K, R=np.eye(3), t=np.zeros(3), width=f.width, height=f.height,
                      name=f.name) for f in frames]
    return SfmResult(cameras=cameras, points=np.zeros((0, 3)),
                     keypoints=[np.zeros((0, 2)) for _ in frames],
                     point_ids=[np.zeros(0, np.int64) for _ in frames],
                     registration=[{"method": "origin"}] + [{"method": "none"}] * (n - 1),
                     notes=[f"structure from motion failed: {reason}"])


def hold_intrinsics_fixed(pipe: Pipeline) -> bool:
    """Make the pipeline's matcher keep every frame's ``K`` fixed, if it can.

    Asks the configured matcher class (:meth:`Matcher.fixed_intrinsics_config`); returns False
    when it cannot, in which case the given intrinsics are only its starting guess.
    """
    name, cfg = pipe.config.stages["matcher"]
    fixed = pipe.registry.get("matcher", name).cls.fixed_intrinsics_config(cfg)
    if fixed is None:
        return False
    pipe.config.stages["matcher"] = (name, fixed)
    pipe._stages.pop("matcher", None)  # rebuilt from the new config on next use
    return True


def hold_given_intrinsics(pipe: Pipeline) -> str | None:
    """:func:`hold_intrinsics_fixed` for intrinsics the user gave (``--intrinsics``): None when
    the matcher keeps them, otherwise the note saying they are only its starting guess."""
    if hold_intrinsics_fixed(pipe):
        return None
    return (f"matcher '{pipe.config.stages['matcher'][0]}' cannot hold intrinsics fixed; "
            "--intrinsics is its starting guess")


def matcher_keeps_intrinsics(pipe: Pipeline) -> bool:
    """True when the pipeline's matcher returns every frame's ``K`` unchanged.

    That is when its config already is what :meth:`Matcher.fixed_intrinsics_config` would make
    of it (e.g. after :func:`hold_intrinsics_fixed`).
    """
    name, cfg = pipe.config.stages["matcher"]
    fixed = pipe.registry.get("matcher", name).cls.fixed_intrinsics_config(cfg)
    return fixed is not None and fixed == cfg


def rescale_reconstruction(rec: Reconstruction, frame: Frame, scale: float) -> Reconstruction:
    """A reconstruction of ``rec.frame`` expressed for ``frame``, its depth times ``scale``.

    The single-view stages are free of the depth's scale: the cloud is normalised into the
    unit sphere and every tolerance is a fraction of the scene radius, so segmenting depth
    ``s·D`` gives the labels of ``D`` and planes whose offsets (and RMS errors) are ``s``
    times larger (to float rounding; ``tests/multiview/test_overlap.py`` checks the labels
    are identical). That lets the views be segmented before SfM has fixed their scale.

    Parameters
    ----------
    rec : Reconstruction
        Segmentation of a frame with depth ``D``.
    frame : Frame
        The same frame with depth ``scale·D`` (and the units and notes that go with it).
    scale : float
        Positive depth factor.

    Returns
    -------
    Reconstruction
        Same labels and normals; offsets ``d`` and ``rmse`` multiplied by ``scale``; ``frame``
        as given.
    """
    params = rec.planes.copy()
    params[:, 3] *= scale
    return replace(rec, frame=frame, planes=params, rmse=rec.rmse * scale)


#: The alignment of the view that defines the world frame when SfM built no model.
ORIGIN_ALIGNMENT = ScaleAlignment(scale=1.0, num_points=0, num_inliers=0, residual=float("nan"),
                                  relative_residual=float("nan"))


def align_to_sfm(frames: list[Frame], sfm: SfmResult, registration: list[dict],
                 strict: bool = False) -> list[ScaleAlignment | None]:
    """Scale each registered view's depth onto the SfM points it observes.

    Parameters
    ----------
    frames : list of Frame
        The views with their (unscaled) depth, in SfM order.
    sfm : SfmResult
        The matcher's model.
    registration : list of dict
        Per view, how SfM placed it (``method``). A view that cannot be aligned is changed to
        ``{"method": "none", "reason": ...}`` in place.
    strict : bool
        Raise instead of unregistering a view that cannot be aligned.

    Returns
    -------
    list of ScaleAlignment or None
        Per view; None where the view is not registered. The origin view (SfM built no model)
        keeps its own depth's units (scale 1).
    """
    alignments: list[ScaleAlignment | None] = [None] * len(frames)
    for v, frame in enumerate(frames):
        method = registration[v]["method"]
        if method == "none":
            continue
        if method == "origin":
            alignments[v] = ORIGIN_ALIGNMENT
            continue
        pixels, depth = sfm.sparse_depth(v)
        try:
            alignments[v] = align_scale(frame.depth, pixels, depth)
        except InvalidInput as exc:
            if strict:
                raise InvalidInput(f"{frame.name}: {exc}") from None
            registration[v] = {"method": "none", "reason": str(exc)}
    return alignments
