"""Evaluation of planar reconstructions: segmentation metrics, plane recall, baselines, runner.

Single-view metrics follow the protocol of PlaneRCNN / PlaneTR / PlaneRecTR used in the
MonoPlane paper (Tab. I and IV); see ``docs/evaluation.md``. The two-view metrics live in
:mod:`monoplane.evaluation.twoview`, imported on demand because it needs the SfM stack.
"""

from monoplane.evaluation.recall import (
    DEPTH_THRESHOLDS,
    PlaneRecall,
    match_planes,
    median_scale,
    plane_recall,
)
from monoplane.evaluation.segmentation import (
    SegmentationScores,
    contingency,
    rand_index,
    segmentation_covering,
    segmentation_scores,
    variation_of_information,
)

__all__ = [
    "DEPTH_THRESHOLDS", "PlaneRecall", "SegmentationScores", "contingency", "match_planes",
    "median_scale", "plane_recall", "rand_index", "segmentation_covering",
    "segmentation_scores", "variation_of_information",
]
