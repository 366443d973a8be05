"""Per-view keypoints and per-pair matches of a feature stage, computed on demand and kept.

Frames: pixel centres at integer coordinates, ``(u, v)`` = (column, row), native resolution.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Protocol

import numpy as np

from monoplane.errors import InvalidInput

if TYPE_CHECKING:
    from monoplane.datamodel import Frame


@dataclass(frozen=True)
class Keypoints:
    """The keypoints of one image.

    Attributes
    ----------
    pixels : numpy.ndarray
        (k, 2) float64 ``(u, v)`` pixel coordinates.
    descriptors : numpy.ndarray or None
        (k, D) float32 descriptors (unit length for learned features), or None for keypoints
        a pairwise network produced (they have no descriptor of their own).
    scores : numpy.ndarray
        (k,) float32 detection scores, higher is stronger.
    """

    pixels: np.ndarray
    descriptors: np.ndarray | None
    scores: np.ndarray

    @classmethod
    def empty(cls, dim: int | None = None) -> Keypoints:
        """No keypoints (with ``dim``-dimensional descriptors, or none)."""
        return cls(np.zeros((0, 2)), None if dim is None else np.zeros((0, dim), np.float32),
                   np.zeros(0, np.float32))

    def __len__(self) -> int:
        return len(self.pixels)

    def described(self, who: str) -> np.ndarray:
        """The (k, D) descriptors; a one-line error naming ``who`` when there are none
        (keypoints a pairwise network produced cannot be matched by descriptor)."""
        if self.descriptors is None:
            raise InvalidInput(f"{who}: these keypoints have no descriptors to match")
        return self.descriptors


@dataclass(frozen=True)
class PairMatches:
    """Correspondences between two images, as a feature stage returns them.

    Attributes
    ----------
    index : numpy.ndarray or None
        (m, 2) int64 ``(keypoint in i, keypoint in j)`` for stages that detect per image;
        None for pairwise networks, which give pixels instead.
    pixels_i, pixels_j : numpy.ndarray or None
        (m, 2) float64 matched pixels in each image (pairwise networks); None otherwise.
    scores : numpy.ndarray
        (m,) float32 match confidence (cosine similarity, or the network's score).
    """

    index: np.ndarray | None
    pixels_i: np.ndarray | None
    pixels_j: np.ndarray | None
    scores: np.ndarray


class FeatureSource(Protocol):
    """What :class:`Correspondences` needs of a ``[features]`` stage
    (:class:`monoplane.contracts.FeatureMatcher` is the contract that provides it)."""

    name: ClassVar[str]
    pairwise: ClassVar[bool]
    sfm_native: ClassVar[str | None]

    def detect(self, frame: Frame) -> Keypoints | None: ...

    def match(self, a: Keypoints, b: Keypoints) -> PairMatches: ...

    def match_pair(self, frame_i: Frame, frame_j: Frame) -> PairMatches: ...


def _no_matches() -> np.ndarray:
    return np.zeros((0, 2), np.int64)


class Correspondences:
    """Keypoints and matches of a set of frames from one ``[features]`` stage.

    Keypoints of a stage that detects per image are computed once per view. A pairwise
    network's matched pixels are gathered into one keypoint list per view: a pixel within half
    a pixel of one already listed (from another pair) reuses it, so a point matched in several
    pairs forms one track, as COLMAP needs.

    Parameters
    ----------
    stage : FeatureSource
        The configured features stage.
    frames : list of Frame
        The views, each with ``rgb``.
    """

    def __init__(self, stage: FeatureSource, frames: list[Frame]) -> None:
        self.stage = stage
        self.frames = frames
        self.name = stage.name
        #: The SfM implementation that may replace these features (``"sift"``: COLMAP's own).
        self.sfm_native = stage.sfm_native
        self._keypoints: dict[int, Keypoints] = {}
        self._matches: dict[tuple[int, int], np.ndarray] = {}
        self._scores: dict[tuple[int, int], np.ndarray] = {}
        # Pairwise networks: per view, the listed pixels and a rounded-pixel index of them.
        self._pixels: dict[int, list[np.ndarray]] = {}
        self._where: dict[int, dict[tuple[int, int], int]] = {}

    def __len__(self) -> int:
        return len(self.frames)

    def _check(self, v: int) -> None:
        if not 0 <= v < len(self.frames):
            raise InvalidInput(f"view {v} out of range for {len(self.frames)} views")

    def keypoints(self, v: int) -> Keypoints:
        """The keypoints of view ``v`` (for a pairwise network: of every pair with ``v``)."""
        self._check(v)
        if v not in self._keypoints:
            found = self.stage.detect(self.frames[v])
            if found is None:
                for u in range(len(self.frames)):
                    if u != v:
                        self.matches(min(u, v), max(u, v))
                pixels = (np.concatenate(self._pixels[v]) if self._pixels.get(v)
                          else np.zeros((0, 2)))
                found = Keypoints(pixels, None, np.ones(len(pixels), np.float32))
            self._keypoints[v] = found
        return self._keypoints[v]

    def matches(self, i: int, j: int) -> np.ndarray:
        """(m, 2) int64 ``(keypoint of i, keypoint of j)`` matches of views ``i`` and ``j``."""
        self._check(i)
        self._check(j)
        if i == j:
            raise InvalidInput(f"a view cannot be matched with itself (view {i})")
        if i > j:
            return self.matches(j, i)[:, ::-1]
        key = (i, j)
        if key not in self._matches:
            if self.stage.pairwise:
                found = self.stage.match_pair(self.frames[i], self.frames[j])
                if found.pixels_i is None or found.pixels_j is None:
                    raise InvalidInput(f"features stage '{self.name}': match_pair returned no "
                                       "pixels")
                index = np.c_[self._gather(i, found.pixels_i), self._gather(j, found.pixels_j)]
                # Two pixels merged into one keypoint may leave a keypoint matched twice.
                _, first = np.unique(index[:, 0], return_index=True)
                keep = np.sort(first)
                index, scores = index[keep], found.scores[keep]
            else:
                found = self.stage.match(self.keypoints(i), self.keypoints(j))
                index = found.index if found.index is not None else _no_matches()
                scores = found.scores
            self._matches[key] = np.asarray(index, np.int64).reshape(-1, 2)
            self._scores[key] = np.asarray(scores, np.float32).reshape(-1)
        return self._matches[key]

    def scores(self, i: int, j: int) -> np.ndarray:
        """(m,) float32 confidence of each match of :meth:`matches` ``(i, j)``."""
        self.matches(i, j)
        return self._scores[(min(i, j), max(i, j))]

    def pixels(self, i: int, j: int) -> tuple[np.ndarray, np.ndarray]:
        """The matched pixels, (m, 2) float64 in view ``i`` and (m, 2) in view ``j``."""
        m = self.matches(i, j)
        return self.keypoints(i).pixels[m[:, 0]], self.keypoints(j).pixels[m[:, 1]]

    def all_matches(self) -> dict[tuple[int, int], np.ndarray]:
        """Matches of every pair ``(i, j)``, ``i < j`` (keys as in ``SfmResult.matches``)."""
        n = len(self.frames)
        return {(i, j): self.matches(i, j) for i in range(n) for j in range(i + 1, n)}

    def _gather(self, v: int, pixels: np.ndarray) -> np.ndarray:
        """Index of each pixel in view ``v``'s keypoint list, appending the new ones."""
        if v in self._keypoints:
            raise InvalidInput(f"features stage '{self.name}': view {v}'s keypoints were read "
                               "before all its pairs were matched")
        pixels = np.asarray(pixels, np.float64).reshape(-1, 2)
        where = self._where.setdefault(v, {})
        listed = self._pixels.setdefault(v, [])
        count = sum(len(p) for p in listed)
        out = np.empty(len(pixels), np.int64)
        fresh: list[np.ndarray] = []
        for k, (u, w) in enumerate(np.rint(pixels).astype(np.int64)):
            cell = (int(u), int(w))
            if cell not in where:
                where[cell] = count + len(fresh)
                fresh.append(pixels[k])
            out[k] = where[cell]
        if fresh:
            listed.append(np.array(fresh, np.float64).reshape(-1, 2))
        return out
