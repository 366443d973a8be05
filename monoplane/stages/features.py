"""Built-in feature matchers: SIFT (OpenCV, or COLMAP's own inside SfM) and XFeat (ONNX).

Pixel coordinates: ``(u, v)`` with pixel centres at integers, at each frame's native resolution.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from monoplane.datamodel import Frame
from monoplane.errors import ConfigError, InvalidInput
from monoplane.features import Keypoints, PairMatches
from monoplane.features.matching import mutual_nearest, mutual_ratio
from monoplane.features.xfeat import XFeatNetwork
from monoplane.hookspecs import hookimpl
from monoplane.models import get_model, require_model
from monoplane.stages.base import FeatureMatcher, Stage, param


def _rgb(frame: Frame) -> np.ndarray:
    if frame.rgb is None:
        raise InvalidInput(f"{frame.name}: feature matching needs a colour image")
    return frame.rgb


class SiftFeatures(FeatureMatcher):
    """SIFT keypoints (OpenCV) matched mutually under Lowe's ratio test.

    The ``colmap`` matcher runs COLMAP's own SIFT extraction, matching and geometric
    verification instead (``sfm_native``); these keypoints serve the registrar and fusion
    wherever SfM gave no matches.
    """

    name = "sift"
    sfm_native = "sift"

    @dataclass
    class Config:
        max_keypoints: int = param(4000, "most SIFT keypoints per image")
        ratio: float = param(0.8, "Lowe's ratio: nearest over second-nearest descriptor "
                                  "distance must be below this")

        def __post_init__(self) -> None:
            if self.max_keypoints < 8:
                raise ConfigError(f"max_keypoints must be >= 8, got {self.max_keypoints}")
            if not 0.0 < self.ratio <= 1.0:
                raise ConfigError(f"ratio must be in (0, 1], got {self.ratio}")

    def detect(self, frame: Frame) -> Keypoints:
        grey = cv2.cvtColor(np.ascontiguousarray(_rgb(frame)), cv2.COLOR_RGB2GRAY)
        kp, des = cv2.SIFT_create(nfeatures=self.config.max_keypoints).detectAndCompute(grey,
                                                                                         None)
        if des is None or not kp:
            return Keypoints.empty(128)
        return Keypoints(np.array([k.pt for k in kp], np.float64), des.astype(np.float32),
                         np.array([k.response for k in kp], np.float32))

    def match(self, a: Keypoints, b: Keypoints) -> PairMatches:
        index, scores = mutual_ratio(a.descriptors, b.descriptors, self.config.ratio)
        return PairMatches(index, None, None, scores)


class XFeatFeatures(FeatureMatcher):
    """XFeat keypoints and descriptors (ONNX backbone, CPU) matched as mutual nearest
    neighbours by cosine similarity, as XFeat's own matcher does."""

    name = "xfeat"

    @dataclass
    class Config:
        model: str = param(
            "xfeat", "the XFeat ONNX backbone: a file path, or a catalogue name "
                     "('monoplane models fetch xfeat' downloads it)")
        max_keypoints: int = param(4096, "most keypoints per image, strongest first")
        threshold: float = param(0.05, "smallest keypoint heatmap value (probability, 0-1)")
        min_similarity: float = param(0.82, "smallest cosine similarity of a match")
        threads: int = param(2, "onnxruntime threads")

        def __post_init__(self) -> None:
            if self.max_keypoints < 8:
                raise ConfigError(f"max_keypoints must be >= 8, got {self.max_keypoints}")
            if not 0.0 <= self.threshold < 1.0:
                raise ConfigError(f"threshold must be in [0, 1), got {self.threshold}")
            if not -1.0 <= self.min_similarity <= 1.0:
                raise ConfigError(f"min_similarity must be in [-1, 1], got "
                                  f"{self.min_similarity}")
            if self.threads < 1:
                raise ConfigError(f"threads must be >= 1, got {self.threads}")

    def __init__(self, config: Config | None = None) -> None:
        super().__init__(config)
        self._network: XFeatNetwork | None = None

    def _net(self) -> XFeatNetwork:
        """The network, loaded on first use (a catalogue name resolves to its cached file)."""
        if self._network is None:
            model = self.config.model
            path = Path(model).expanduser()
            if path.suffix != ".onnx" and not path.exists():
                get_model(model)  # an unknown name lists the catalogue
                path = require_model(model)
            self._network = XFeatNetwork(path, threads=self.config.threads)
        return self._network

    def detect(self, frame: Frame) -> Keypoints:
        cfg = self.config
        return self._net().detect(_rgb(frame), cfg.max_keypoints, cfg.threshold)

    def match(self, a: Keypoints, b: Keypoints) -> PairMatches:
        index, scores = mutual_nearest(a.descriptors, b.descriptors, self.config.min_similarity)
        return PairMatches(index, None, None, scores)


@hookimpl
def monoplane_register_feature_matchers() -> list[type[Stage]]:
    """Register the built-in feature matchers."""
    return [SiftFeatures, XFeatFeatures]
