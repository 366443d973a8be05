"""Run an :class:`~monoplane.cues.profiles.OnnxProfile` on frames: the reusable core of the
``onnx`` cue provider, public so that third-party cue plugins can wrap their own profiles.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from monoplane.cues.intrinsics import (
    ASSUMED_INTRINSICS_NOTE,
    assume_intrinsics,
    intrinsics_assumed,
    reassume_intrinsics,
)
from monoplane.cues.pointmap import depth_from_point_map, focal_from_intrinsics, focal_to_pixels
from monoplane.cues.profiles import OnnxProfile
from monoplane.cues.session import OnnxModel
from monoplane.cues.transforms import (
    decode_normals,
    depth_from_disparity,
    face_camera,
    relative_depth_from_depth,
)
from monoplane.datamodel import Frame
from monoplane.errors import InvalidInput
from monoplane.geometry.normals import cue_normals_from_depth


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
        Keyword arguments for :func:`~monoplane.geometry.normals.normals_from_depth`; its
        ``method`` may be ``"auto"`` (:func:`~monoplane.geometry.normals.fit_method`, per
        frame), which is also what a missing ``method`` means
        (:data:`~monoplane.geometry.normals.DEFAULT_NORMALS_METHOD`).
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

    def _depth_from_raw(self, raw: np.ndarray, model: OnnxModel,
                        K: np.ndarray, shape: tuple[int, int]) -> tuple[np.ndarray, str, str, str]:
        kind = model.spec.output
        src = f"{self.profile.name} network {model.path.name}"
        if kind == "metric_depth":
            depth = raw * np.float32(model.spec.depth_scale)
            extra = ""
            if model.spec.canonical_focal:
                # Depth for a canonical camera: rescale by the focal length the network saw.
                fx_net = float(K[0, 0]) * model.letterbox(*shape).scale[0]
                depth = depth * np.float32(fx_net / model.spec.canonical_focal)
                extra = (f", scaled by fx / {model.spec.canonical_focal:g} px at the network's "
                         f"input resolution (fx there = {fx_net:.1f} px)")
            depth = np.where(np.isfinite(depth) & (depth > 0), depth, 0).astype(np.float32)
            if not np.any(depth > 0):
                raise InvalidInput(f"{model.path}: the metric depth network returned no "
                                   f"positive depth")
            return depth, "metric", "m", f"depth: metric, from {src}{extra}"
        if kind == "relative_depth":
            depth = relative_depth_from_depth(raw)
            return depth, "relative", "relative", (
                f"depth: relative (median 1, shift assumed zero), from {src}")
        depth = depth_from_disparity(raw, self.disparity_floor)
        return depth, "relative", "relative", (
            f"depth: relative, 1 / (disparity / median disparity) with shift assumed zero and "
            f"disparities below {self.disparity_floor:g} x median invalid, from {src}")

    def predict_depth(self, rgb: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, str, str, str]:
        """Depth of one image (depth networks; point-map networks go through :meth:`provide`).

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
        if model.spec.output == "point_map":
            raise InvalidInput(f"profile {self.profile.name!r} predicts a point map; use "
                               f"CueNetwork.provide")
        return self._depth_from_raw(model.predict(rgb, K), model, K, rgb.shape[:2])

    def _point_map_cues(self, frame: Frame, outputs: dict[str, np.ndarray],
                        model: OnnxModel) -> tuple[Frame, np.ndarray, str]:
        """Metric depth (and, for guessed intrinsics, the network's own) from a point map."""
        spec = model.spec
        h, w = frame.height, frame.width
        mask = outputs.get(spec.mask_output) if spec.mask_output else None
        scale = float(outputs[spec.scale_output][0]) if spec.scale_output else 1.0
        if not np.isfinite(scale) or scale <= 0:
            raise InvalidInput(f"{model.path}: the network returned metric scale {scale}")
        src = f"{self.profile.name} network {model.path.name}"
        known = None if intrinsics_assumed(frame) else focal_from_intrinsics(frame.K, h, w)
        depth, focal = depth_from_point_map(outputs[model.output_name], mask, scale, known)
        if known is None:
            fx = focal_to_pixels(focal, h, w)
            hfov = float(np.degrees(2 * np.arctan(0.5 * w / fx)))
            K, _ = assume_intrinsics(w, h, hfov)
            note = (f"{ASSUMED_INTRINSICS_NOTE}: estimated from the {src} point map: a "
                    f"{hfov:.1f}° horizontal field of view, fx = fy = {fx:.1f} px, principal "
                    f"point at the image centre")
            notes = [n for n in frame.notes if not n.startswith(ASSUMED_INTRINSICS_NOTE)]
            frame = frame.with_(K=K, notes=[*notes, note])
        how = "focal length and shift recovered" if known is None else (
            "shift recovered for the given focal length")
        return frame, depth, (f"depth: metric, from the {src} point map ({how}, metric scale "
                              f"{scale:.3g})")

    def provide(self, frame: Frame) -> Frame:
        """Fill the frame's missing cues: depth from the depth network, normals from the
        depth network (joint networks), a normals network or, without either, from depth.

        Cues already on the frame (given by the user) are kept. When the frame's intrinsics
        were assumed, a profile's field of view, or a point-map network's own estimate,
        replaces the guess.

        Returns
        -------
        Frame
            A new frame with ``depth``, ``normals``, ``depth_kind``, ``depth_units`` and
            ``notes`` set (and ``K`` when the network estimated it). Normals are zero wherever
            depth is invalid.
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
        spec = self.profile.depth
        joint = spec.joint_normals and rgb is not None and frame.normals is None
        outputs: dict[str, np.ndarray] = {}
        model = None
        if frame.depth is None or joint:
            model = self._depth_model()
            outputs = model.run(rgb, frame.K)  # type: ignore[arg-type]
        changes: dict = {}
        depth = frame.depth
        notes_before: list[str] = []
        if depth is None:
            assert model is not None
            if spec.output == "point_map":
                frame, depth, note = self._point_map_cues(frame, outputs, model)
                kind, units = "metric", "m"
            else:
                depth, kind, units, note = self._depth_from_raw(
                    outputs[model.output_name], model, frame.K, (frame.height, frame.width))
            changes.update(depth=depth, depth_kind=kind, depth_units=units,
                           depth_predicted=True)
            notes_before.append(note)
        notes = [*frame.notes, *notes_before]
        if frame.normals is None:
            if joint:
                assert model is not None and spec.normals_output is not None
                normals = decode_normals(outputs[spec.normals_output], spec, frame.K)
                notes.append(f"normals: from {self.profile.name} network {model.path.name}")
            else:
                # Depth-only input (range images) has no image for a normals network.
                normal_model = self._normal_model() if rgb is not None else None
                if normal_model is not None:
                    assert rgb is not None
                    normals = decode_normals(normal_model.predict(rgb, frame.K),
                                             normal_model.spec, frame.K)
                    notes.append(f"normals: from {self.profile.name} network "
                                 f"{normal_model.path.name}")
                else:
                    normals, note = cue_normals_from_depth(
                        depth, frame.K, self.normals_options, frame.depth_measured)
                    notes.append(note)
                    changes["normals_from_depth"] = True
            if not changes.get("normals_from_depth"):
                # A float32 copy zeroed in place: half the cost of np.where and a cast (2
                # passes). Normals from depth are float32 and zero there already.
                normals = np.array(normals, dtype=np.float32)
                normals[~(depth > 0)] = 0.0
            changes["normals"] = normals
        else:
            changes["normals"] = face_camera(frame.normals, frame.K)
        return frame.with_(notes=notes, **changes)
