"""Built-in feature matchers: SIFT (OpenCV, or COLMAP's own inside SfM) and XFeat (ONNX).

Pixel coordinates: ``(u, v)`` with pixel centres at integers, at each frame's native resolution.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from monoplane.contracts import FeatureMatcher, Stage, param
from monoplane.datamodel import Frame
from monoplane.errors import ConfigError, InvalidInput
from monoplane.features import Keypoints, PairMatches
from monoplane.features.matching import mutual_nearest, mutual_ratio
from monoplane.features.xfeat import XFeatNetwork
from monoplane.hookspecs import hookimpl
from monoplane.models import cached_model, get_model, require_model


def _rgb(frame: Frame) -> np.ndarray:
    if frame.rgb is None:
        raise InvalidInput(f"{frame.name}: feature matching needs a colour image")
    return frame.rgb


def _model_file(model: str) -> Path | None:
    """The XFeat file a ``model`` setting names (a path, or a catalogue name), or None when a
    catalogue model is not downloaded yet."""
    path = Path(model).expanduser()
    if path.suffix == ".onnx" or path.exists():
        return path
    get_model(model)  # an unknown name lists the catalogue
    return cached_model(model)


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
        who = f"features stage '{self.name}'"
        index, scores = mutual_ratio(a.described(who), b.described(who), self.config.ratio)
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
            path = _model_file(self.config.model) or require_model(self.config.model)
            self._network = XFeatNetwork(path, threads=self.config.threads)
        return self._network

    def detect(self, frame: Frame) -> Keypoints:
        cfg = self.config
        return self._net().detect(_rgb(frame), cfg.max_keypoints, cfg.threshold)

    def match(self, a: Keypoints, b: Keypoints) -> PairMatches:
        who = f"features stage '{self.name}'"
        index, scores = mutual_nearest(a.described(who), b.described(who),
                                       self.config.min_similarity)
        return PairMatches(index, None, None, scores)


#: SIFT's descriptor length; the first block of ``sift+xfeat``'s descriptors.
_SIFT_DIM = 128


class SiftXFeatFeatures(FeatureMatcher):
    """SIFT's and XFeat's keypoints together, each matched with its own rule.

    SIFT localises its keypoints to a fraction of a pixel but finds few matches across wide
    baselines; XFeat finds many times more, about a pixel and a half off (its keypoints come
    from an 8 x 8-pixel cell head). COLMAP and the registrar get both. A keypoint's
    descriptor is its own, unit-normalised, in its own block of a 192-vector (SIFT's 128
    first, XFeat's 64 last, zeros elsewhere), so descriptors of the two kinds never resemble
    each other (guided matching compares whole vectors).
    """

    name = "sift+xfeat"

    @dataclass
    class Config(XFeatFeatures.Config):
        sift_max_keypoints: int = param(4000, "most SIFT keypoints per image")
        ratio: float = param(0.8, "Lowe's ratio of a SIFT match")
        when_missing: str = param(
            "sift", "when the XFeat model is not downloaded: 'sift' warns once and matches "
                    "with SIFT alone (COLMAP's own, as the 'sift' stage), 'error' stops with "
                    "the fetch command")
        sfm: str = param(
            "sift", "what SfM maps: 'sift' (COLMAP's own SIFT, the most precise where it "
                    "connects the views; XFeat's matches then serve the registrar) or 'both' "
                    "(both keypoint sets written into COLMAP's database)")

        def __post_init__(self) -> None:
            super().__post_init__()
            if self.when_missing not in ("sift", "error"):
                raise ConfigError(f"when_missing must be 'sift' or 'error', got "
                                  f"{self.when_missing!r}")
            if self.sfm not in ("sift", "both"):
                raise ConfigError(f"sfm must be 'sift' or 'both', got {self.sfm!r}")
            SiftFeatures.Config(self.sift_max_keypoints, self.ratio)

    def __init__(self, config: Config | None = None) -> None:
        super().__init__(config)
        cfg = self.config
        self.sift = SiftFeatures(SiftFeatures.Config(cfg.sift_max_keypoints, cfg.ratio))
        self.xfeat: XFeatFeatures | None = XFeatFeatures(XFeatFeatures.Config(
            cfg.model, cfg.max_keypoints, cfg.threshold, cfg.min_similarity, cfg.threads))
        # Said when XFeat's keypoints are first wanted (not by a run that maps COLMAP's SIFT
        # and nothing else, such as 'monoplane match').
        self._missing_note: str | None = None
        if cfg.when_missing == "sift" and _model_file(cfg.model) is None:
            self._missing_note = (
                f"monoplane: warning: the XFeat model '{cfg.model}' is not downloaded; "
                f"matching with SIFT alone (run 'monoplane models fetch {cfg.model}' for "
                "XFeat's matches too)")
            self.xfeat = None
        if self.xfeat is None or cfg.sfm == "sift":
            self.sfm_native = "sift"  # type: ignore[misc]  # COLMAP maps its own SIFT

    def detect(self, frame: Frame) -> Keypoints:
        if self.xfeat is None:
            if self._missing_note is not None:
                print(self._missing_note, file=sys.stderr)
                self._missing_note = None
            return self.sift.detect(frame)
        who = f"features stage '{self.name}'"
        a, b = self.sift.detect(frame), self.xfeat.detect(frame)
        da, db = a.described(who), b.described(who)
        desc = np.zeros((len(a) + len(b), _SIFT_DIM + db.shape[1]), np.float32)
        desc[:len(a), :_SIFT_DIM] = da / np.maximum(np.linalg.norm(da, axis=1, keepdims=True),
                                                    1e-12)
        desc[len(a):, _SIFT_DIM:] = db
        return Keypoints(np.concatenate([a.pixels, b.pixels]), desc,
                         np.concatenate([a.scores, b.scores]))

    def match(self, a: Keypoints, b: Keypoints) -> PairMatches:
        if self.xfeat is None:
            return self.sift.match(a, b)
        who = f"features stage '{self.name}'"
        da, db = a.described(who), b.described(who)
        found, scores = [], []
        for part, rule in ((slice(0, _SIFT_DIM), self.sift), (slice(_SIFT_DIM, None),
                                                                self.xfeat)):
            ia = np.flatnonzero(np.any(da[:, part] != 0, axis=1))
            ib = np.flatnonzero(np.any(db[:, part] != 0, axis=1))
            m = rule.match(Keypoints(a.pixels[ia], da[ia, part], a.scores[ia]),
                           Keypoints(b.pixels[ib], db[ib, part], b.scores[ib]))
            pairs = m.index if m.index is not None else np.zeros((0, 2), np.int64)
            found.append(np.c_[ia[pairs[:, 0]], ib[pairs[:, 1]]])
            scores.append(m.scores)
        return PairMatches(np.concatenate(found).astype(np.int64), None, None,
                           np.concatenate(scores))


@hookimpl
def monoplane_register_feature_matchers() -> list[type[Stage]]:
    """Register the built-in feature matchers."""
    return [SiftFeatures, XFeatFeatures, SiftXFeatFeatures]
