"""Keypoints and correspondences between images, from any feature stage.

A ``[features]`` stage (:class:`monoplane.contracts.FeatureMatcher`) either describes each
image on its own (SIFT, XFeat: :meth:`~monoplane.contracts.FeatureMatcher.detect` plus a
descriptor matcher) or matches two images at once (a pairwise network such as LoFTR or
LightGlue: :meth:`~monoplane.contracts.FeatureMatcher.match_pair`). :class:`Correspondences`
hides the difference from everything downstream (COLMAP's database, the registrar, fusion):
per view one keypoint list, per pair index matches into those lists, computed on demand and
kept.

Pixel coordinates follow :mod:`monoplane.datamodel`: pixel centres at integers, ``(u, v)`` =
(column, row) at the frame's native resolution.
"""

from monoplane.features.correspondences import Correspondences, Keypoints, PairMatches

__all__ = ["Correspondences", "Keypoints", "PairMatches"]
