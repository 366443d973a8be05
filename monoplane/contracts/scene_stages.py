"""Contracts of the stages that work on several views: features, the SfM matcher, the
registrar, the fuser and the adjuster."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

from monoplane.contracts.stage import Stage

if TYPE_CHECKING:
    from monoplane.datamodel import Frame, Reconstruction, Scene, SfmResult
    from monoplane.features import Correspondences, Keypoints, PairMatches
    from monoplane.geometry.alignment import ScaleAlignment


class FeatureMatcher(Stage):
    """Keypoints and correspondences between images, for SfM, the registrar and fusion.

    Two shapes plug in here. A **local feature** (SIFT, XFeat, ALIKED, ...) describes each image
    on its own: implement :meth:`detect` and :meth:`match`. A **pairwise network** (LoFTR,
    LightGlue run on two images, ...) sees both images at once: set ``pairwise = True`` and
    implement :meth:`match_pair`; the host gathers its matched pixels into one keypoint list
    per view (:class:`monoplane.features.Correspondences`), so either shape feeds COLMAP's
    database, the registrar and plane matching alike.
    """

    kind = "features"
    #: True for networks that match two images at once (:meth:`match_pair`).
    pairwise: ClassVar[bool] = False
    #: Names an SfM matcher's own implementation of the same features (``"sift"``: COLMAP's
    #: SIFT extraction, matching and verification), which such a matcher runs instead of
    #: importing these correspondences; None when there is none.
    sfm_native: ClassVar[str | None] = None

    def detect(self, frame: Frame) -> Keypoints | None:
        """Keypoints and descriptors of one frame (None for a pairwise network).

        Parameters
        ----------
        frame : Frame
            A frame with ``rgb`` (H, W, 3) uint8.

        Returns
        -------
        Keypoints or None
            Pixels ``(u, v)`` at the frame's native resolution, pixel centres at integers.
        """
        return None

    def match(self, a: Keypoints, b: Keypoints) -> PairMatches:
        """Matches of two images' keypoints (``index`` set), for stages that :meth:`detect`."""
        raise NotImplementedError(f"features stage '{self.name}' does not match descriptors")

    def match_pair(self, frame_i: Frame, frame_j: Frame) -> PairMatches:
        """Matched pixels of two frames (``pixels_i``, ``pixels_j`` set): pairwise networks."""
        raise NotImplementedError(f"features stage '{self.name}' does not match image pairs")


class Matcher(Stage):
    """Structure from motion over several frames."""

    kind = "matcher"
    #: True when :meth:`match` takes the ``[features]`` stage's correspondences.
    uses_correspondences: ClassVar[bool] = False

    def match(self, frames: list[Frame], correspondences: Correspondences | None = None
              ) -> SfmResult:
        """Cameras, sparse points and pairwise keypoint matches for ``frames``.

        A matcher that cannot register every frame may mark those frames ``{"method": "none"}``
        in the result's ``registration`` (their cameras are then placeholders); the registrar
        stage then tries to place them. A matcher that declares ``uses_correspondences`` is
        handed the ``[features]`` stage's keypoints and matches (computed on demand) and builds
        its model on them; the host passes nothing to the others.
        """
        raise NotImplementedError

    @classmethod
    def fixed_intrinsics_config(cls, config: Any) -> Any | None:
        """This matcher's config changed to hold every frame's ``K`` fixed, or None.

        The host calls it when the user gives calibrated intrinsics. The default says the
        matcher cannot hold intrinsics fixed (None); a matcher that can returns a copy of
        ``config`` with that option set, leaving ``config`` itself unchanged.
        """
        return None


class Registrar(Stage):
    """Places the views the matcher left unregistered, from what every view already has.

    The host calls it on every multi-view run, also when the matcher placed every view, so a
    registrar may check (and replace) weakly supported placements too."""

    kind = "registrar"

    def register(self, views: list[Reconstruction], sfm: SfmResult,
                 alignments: list[ScaleAlignment | None]
                 ) -> tuple[SfmResult, list[ScaleAlignment | None]]:
        """Give a pose and a depth scale to every view it can place.

        Parameters
        ----------
        views : list of Reconstruction
            Every input view, segmented: ``rec.frame`` holds its image, its depth in its own
            (unaligned) units, its normals and ``K``; labels and planes are in that frame.
        sfm : SfmResult
            The matcher's model. ``sfm.registration[v]["method"]`` is ``"none"`` for a view
            to place; the others' cameras are world-to-camera poses in the model's frame.
            ``sfm.matches`` may hold keypoint matches between any two views, placed or not
            (a learned matcher puts its correspondences there).
        alignments : list of ScaleAlignment or None
            Per view, the factor bringing its depth into the model's units; None for the
            views to place.

        Returns
        -------
        (SfmResult, list of ScaleAlignment or None)
            The model with the placed views' cameras and their ``registration`` entries
            (``method`` naming how, plus its evidence), and their alignments. A view that
            cannot be placed keeps ``{"method": "none", "reason": ...}``. A view whose SfM
            pose it replaced says so (``"replaced": "sfm"``) and observes no model point.
        """
        raise NotImplementedError


class Fuser(Stage):
    """Matches per-view planes and fuses them into global planes."""

    kind = "fuser"

    def fuse(self, views: list[Reconstruction], sfm: SfmResult) -> Scene:
        """Fuse scale-aligned per-view reconstructions into a
        :class:`~monoplane.datamodel.Scene`."""
        raise NotImplementedError

    def fuse_with_matches(self, views: list[Reconstruction],
                          sfm: SfmResult) -> tuple[Scene, list[Any]]:
        """:meth:`fuse`, also returning the plane correspondences it accepted.

        The host calls this one. Each correspondence has attributes ``view_i``, ``plane_i``,
        ``view_j``, ``plane_j`` (1-based local ids) and ``criterion`` (a short string); they are
        written to ``scene.json``. The default returns no correspondences.
        """
        return self.fuse(views, sfm), []


class Adjuster(Stage):
    """Jointly refines the cameras, per-view depth scales and global planes of a fused scene."""

    kind = "adjuster"

    def adjust(self, scene: Scene, sfm: SfmResult) -> tuple[Scene, SfmResult, dict[str, Any]]:
        """Refine a fused scene.

        Parameters
        ----------
        scene : Scene
            Fused scene: cameras (world-to-camera), per-view reconstructions whose ``frame``
            holds the scale-aligned depth, global planes and the view-to-global links.
        sfm : SfmResult
            The sparse model the scene was built on (same cameras, world frame and units).

        Returns
        -------
        (Scene, SfmResult, dict)
            The refined scene (cameras, view depths and plane parameters rescaled by the
            refined per-view scales, global planes), the SfM result with the refined cameras
            and points, and a JSON-serialisable report (at least ``"before"`` and ``"after"``
            residual summaries; empty when nothing was done).
        """
        raise NotImplementedError
