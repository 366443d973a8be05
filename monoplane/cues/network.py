"""Run an :class:`~monoplane.cues.profiles.OnnxProfile` on frames: the reusable core of the
``onnx`` cue provider, public so that third-party cue plugins can wrap their own profiles.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monoplane.cues.intrinsics import reassume_intrinsics
from monoplane.cues.profiles import OnnxProfile
from monoplane.cues.session import OnnxModel
from monoplane.cues.transforms import (
    decode_normals,
    depth_from_disparity,
    orient_normals,
    relative_depth_from_depth,
)
from monoplane.errors import InvalidInput
from monoplane.geometry.normals import normals_from_depth
from monoplane.types import Frame


class CueNetwork:
    """Depth (and optionally normals) networks of one profile, loaded once.

    Parameters
    ----------
    profile : OnnxProfile
        What the networks expect and return.
    depth_model : str or pathlib.Path or None
        The depth network's ``.onnx`` file. Needed unless every frame already has depth.
    normal_model : str or pathlib.Path or None
        The normals network's ``.onnx`` file; without it normals are estimated from depth.
    threads : int
        onnxruntime CPU threads per network.
    disparity_floor : float
        For inverse-depth networks: smallest usable disparity, as a fraction of the median
        (see :func:`~monoplane.cues.transforms.depth_from_disparity`).
    hfov_deg : float, optional
        Horizontal field of view for frames whose intrinsics were assumed (see
        :mod:`monoplane.cues.intrinsics`); ``None`` uses the profile's estimate, if it has one,
        and otherwise keeps the frame's (60°) guess.
    normals_options : dict, optional
        Keyword arguments for :func:`~monoplane.geometry.normals.normals_from_depth`.
    depth_model_key : str
        The config key that sets ``depth_model``, named in the error when it is missing.

    Notes
    -----
    Models load lazily, on the first frame that needs them, and are reused afterwards.
    """

    def __init__(self, profile: OnnxProfile, depth_model: str | Path | None = None,
                 normal_model: str | Path | None = None, *, threads: int = 2,
                 disparity_floor: float = 0.01, hfov_deg: float | None = None,
                 normals_options: dict | None = None,
                 depth_model_key: str = "cues.depth_model") -> None:
        if normal_model and profile.normals is None:
            raise InvalidInput(f"profile {profile.name!r} has no normals network; leave "
                               f"normal_model empty to estimate normals from depth")
        self.profile = profile
        self.depth_path = Path(depth_model) if depth_model else None
        self.normal_path = Path(normal_model) if normal_model else None
        self.threads = threads
        self.disparity_floor = disparity_floor
        self.hfov_deg = hfov_deg
        self.depth_model_key = depth_model_key
        self.normals_options = dict(normals_options or {})
        self._depth: OnnxModel | None = None
        self._normals: OnnxModel | None = None

    def _depth_model(self) -> OnnxModel:
        if self._depth is None:
            if self.depth_path is None:
                raise InvalidInput(
                    f"profile {self.profile.name!r} needs a depth model file "
                    f"({self.depth_model_key} = \"path/to/model.onnx\"); see docs/cues.md")
            self._depth = OnnxModel(self.depth_path, self.profile.depth, threads=self.threads,
                                    label=f"{self.profile.name} depth model")
        return self._depth

    def _normal_model(self) -> OnnxModel | None:
        if self._normals is None and self.normal_path is not None:
            assert self.profile.normals is not None
            self._normals = OnnxModel(self.normal_path, self.profile.normals,
                                      threads=self.threads,
                                      label=f"{self.profile.name} normals model")
        return self._normals

    def load(self) -> None:
        """Load every configured model now (fail fast on bad files)."""
        if self.depth_path is not None:
            self._depth_model()
        self._normal_model()

    def predict_depth(self, rgb: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, str, str, str]:
        """Depth of one image.

        Parameters
        ----------
        rgb : numpy.ndarray
            (H, W, 3) uint8.
        K : numpy.ndarray
            (3, 3) intrinsics.

        Returns
        -------
        depth : numpy.ndarray
            (H, W) float32 z-depth, 0 = invalid.
        depth_kind : str
            ``"metric"`` or ``"relative"``.
        depth_units : str
            ``"m"`` or ``"relative"``.
        note : str
            Provenance for ``Frame.notes``.
        """
        model = self._depth_model()
        raw = model.predict(rgb, K)
        kind = model.spec.output
        src = f"{self.profile.name} network {model.path.name}"
        if kind == "metric_depth":
            depth = raw * np.float32(model.spec.depth_scale)
            depth = np.where(np.isfinite(depth) & (depth > 0), depth, 0).astype(np.float32)
            if not np.any(depth > 0):
                raise InvalidInput(f"{model.path}: the metric depth network returned no "
                                   f"positive depth")
            return depth, "metric", "m", f"depth: metric, from {src}"
        if kind == "relative_depth":
            depth = relative_depth_from_depth(raw)
            return depth, "relative", "relative", (
                f"depth: relative (median 1, shift assumed zero), from {src}")
        depth = depth_from_disparity(raw, self.disparity_floor)
        return depth, "relative", "relative", (
            f"depth: relative, 1 / (disparity / median disparity) with shift assumed zero and "
            f"disparities below {self.disparity_floor:g} x median invalid, from {src}")

    def provide(self, frame: Frame) -> Frame:
        """Fill the frame's missing cues: depth from the depth network, normals from the
        normals network or, without one, estimated from depth.

        Cues already on the frame (given by the user) are kept. When the frame's intrinsics
        were assumed and the profile knows its field of view, the guess is replaced.

        Returns
        -------
        Frame
            A new frame with ``depth``, ``normals``, ``depth_kind``, ``depth_units`` and
            ``notes`` set. Normals are zero wherever depth is invalid.
        """
        rgb = frame.rgb
        if rgb is None and frame.depth is None:
            raise InvalidInput(f"{frame.name}: the {self.profile.name} networks need an RGB "
                               f"image (or give a depth map)")
        if self.hfov_deg is not None:
            frame = reassume_intrinsics(frame, self.hfov_deg, "cues.hfov_deg")
        elif self.profile.hfov_deg is not None:
            frame = reassume_intrinsics(frame, self.profile.hfov_deg,
                                        f"profile {self.profile.name}")
        notes = list(frame.notes)
        changes: dict = {}
        depth = frame.depth
        if depth is None:
            depth, kind, units, note = self.predict_depth(rgb, frame.K)  # type: ignore[arg-type]
            changes.update(depth=depth, depth_kind=kind, depth_units=units)
            notes.append(note)
        if frame.normals is None:
            # Depth-only input (range images) has no image for a normals network.
            model = self._normal_model() if rgb is not None else None
            if model is not None:
                normals = decode_normals(model.predict(rgb, frame.K), model.spec, frame.K)
                notes.append(f"normals: from {self.profile.name} network {model.path.name}")
            else:
                normals = normals_from_depth(depth, frame.K, **self.normals_options)
                notes.append("normals: estimated from depth (edge-aware inverse-depth fits)")
            changes["normals"] = np.where((depth > 0)[..., None], normals, 0).astype(np.float32)
        else:
            changes["normals"] = orient_normals(frame.normals, frame.K)
        return frame.with_(notes=notes, **changes)
