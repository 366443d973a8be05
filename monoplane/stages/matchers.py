"""Built-in matchers: structure from motion over a few frames.

``colmap`` runs pycolmap on the CPU (no colmap binary): SIFT extraction, exhaustive matching
with geometric verification, then incremental mapping. It returns an
:class:`~monoplane.types.SfmResult` in the frames' native pixel coordinates (pixel centres at
integers, OpenCV camera axes), whatever resolution SIFT ran at internally.
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from monoplane.errors import InvalidInput, MonoplaneError
from monoplane.hookspecs import hookimpl
from monoplane.stages.base import Matcher, Stage, param
from monoplane.types import Camera, Frame, SfmResult, intrinsics_matrix

#: COLMAP puts pixel centres at +0.5; monoplane puts them at integers.
_COLMAP_PIXEL_OFFSET = 0.5


class SfmError(MonoplaneError):
    """Structure from motion failed on the given images; the message says why."""


@dataclass
class ColmapConfig:
    """Parameters of the ``colmap`` matcher."""

    fixed_intrinsics: bool = param(
        False, "use each frame's K as fixed PINHOLE intrinsics (set when calibration is known)")
    shared_intrinsics: bool = param(
        True, "when estimating intrinsics, one camera for all images (same device and zoom)")
    max_image_size: int = param(
        1024, "longest image side SIFT runs at (px); keypoints are mapped back to native size")
    max_num_features: int = param(4096, "maximum SIFT features per image")
    min_num_matches: int = param(15, "fewest verified matches for an image pair to be used")
    min_num_features: int = param(50, "fewest SIFT features an image must yield")
    num_threads: int = param(-1, "CPU threads for pycolmap (-1 = all cores)")
    seed: int = param(0, "random seed of the mapper's RANSAC")


@contextlib.contextmanager
def _quiet_colmap() -> Iterator[None]:
    """Silence glog's INFO chatter from pycolmap while keeping errors."""
    import pycolmap

    previous = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 2
    try:
        yield
    finally:
        pycolmap.logging.minloglevel = previous


class ColmapMatcher(Matcher):
    """SIFT + exhaustive matching + incremental mapping with pycolmap, on the CPU.

    Camera intrinsics are fixed to each frame's ``K`` when ``fixed_intrinsics`` is set (paper
    appendix: "camera intrinsics are fixed and input to the SfM if available"); otherwise the
    frames' ``K`` is only the initial guess and the focal length is refined by bundle
    adjustment (principal point kept at the guess, no distortion, so the result stays a
    pinhole ``K``).
    """

    name = "colmap"
    Config = ColmapConfig

    def match(self, frames: list[Frame]) -> SfmResult:
        """Reconstruct cameras and sparse points of ``frames``.

        Parameters
        ----------
        frames : list of Frame
            Two or more frames with ``rgb`` set; ``K`` is the fixed or initial intrinsics.

        Returns
        -------
        SfmResult
            Cameras in input order, world-to-camera (OpenCV axes), arbitrary SfM scale.

        Raises
        ------
        SfmError
            When too few features or matches are found, no initial pair can be registered, or
            some images cannot be registered.
        """
        if len(frames) < 2:
            raise InvalidInput(f"structure from motion needs at least 2 images, got {len(frames)}")
        for f in frames:
            if f.rgb is None:
                raise InvalidInput(f"{f.name}: structure from motion needs a colour image")
        work = Path(tempfile.mkdtemp(prefix="monoplane-sfm-"))
        try:
            with _quiet_colmap():
                return self._run(frames, work)
        finally:
            shutil.rmtree(work, ignore_errors=True)

    def _run(self, frames: list[Frame], work: Path) -> SfmResult:
        import pycolmap

        cfg = self.config
        images = work / "images"
        images.mkdir()
        names = [f"{i:04d}.png" for i in range(len(frames))]
        for name, f in zip(names, frames, strict=True):
            cv2.imwrite(str(images / name), f.rgb[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 1])
        database = work / "database.db"

        extraction = pycolmap.FeatureExtractionOptions()
        extraction.use_gpu = False
        extraction.max_image_size = int(cfg.max_image_size)
        extraction.num_threads = int(cfg.num_threads)
        extraction.sift.max_num_features = int(cfg.max_num_features)
        for group, model, params in self._camera_groups(frames):
            reader = pycolmap.ImageReaderOptions()
            reader.camera_model = model
            reader.camera_params = params
            mode = pycolmap.CameraMode.SINGLE if len(group) > 1 else pycolmap.CameraMode.PER_IMAGE
            pycolmap.extract_features(
                database, images, image_names=[names[i] for i in group], camera_mode=mode,
                reader_options=reader, extraction_options=extraction,
                device=pycolmap.Device.cpu,
            )

        db = pycolmap.Database.open(database)
        try:
            ids = {img.name: img.image_id for img in db.read_all_images()}
            for name, f in zip(names, frames, strict=True):
                k = db.num_keypoints_for_image(ids[name])
                if k < cfg.min_num_features:
                    raise SfmError(
                        f"{f.name}: only {k} SIFT features found (need {cfg.min_num_features}); "
                        "the image is too small, blurred or textureless"
                    )
        finally:
            db.close()

        matching = pycolmap.FeatureMatchingOptions()
        matching.use_gpu = False
        matching.num_threads = int(cfg.num_threads)
        pycolmap.match_exhaustive(database, matching_options=matching, device=pycolmap.Device.cpu)
        matches = self._read_matches(database, names, ids)
        self._check_connectivity(frames, matches)

        options = pycolmap.IncrementalPipelineOptions()
        options.min_model_size = 2
        options.min_num_matches = int(cfg.min_num_matches)
        options.num_threads = int(cfg.num_threads)
        options.random_seed = int(cfg.seed)
        options.multiple_models = False
        # With only two views every track has length 2; keep them or nothing is triangulated.
        options.triangulation.ignore_two_view_tracks = False
        options.ba_refine_principal_point = False
        options.ba_refine_extra_params = False
        options.ba_refine_focal_length = not cfg.fixed_intrinsics
        options.mapper.abs_pose_refine_focal_length = not cfg.fixed_intrinsics
        output = work / "sparse"
        output.mkdir()
        models = pycolmap.incremental_mapping(database, images, output, options=options)
        if not models:
            best = max((len(m) for m in matches.values()), default=0)
            raise SfmError(
                "incremental mapping found no initial image pair: the best pair has "
                f"{best} verified matches but too little parallax (the camera moved too "
                "little for the scene depth) or too few inliers; use overlapping views taken "
                "further apart"
            )
        model = max(models.values(), key=lambda m: m.num_reg_images())
        result = self._to_result(model, frames, names, matches)
        result.notes.append(
            "intrinsics fixed to the given K" if cfg.fixed_intrinsics
            else "focal length estimated by bundle adjustment"
        )
        return result

    def _camera_groups(self, frames: list[Frame]) -> list[tuple[list[int], str, str]]:
        """Frames that share one COLMAP camera, with its model and parameter string."""
        cfg = self.config
        groups: dict[tuple, list[int]] = {}
        for i, f in enumerate(frames):
            if cfg.fixed_intrinsics:
                key: tuple = (f.width, f.height, *np.round(f.K[[0, 1, 0, 1], [0, 1, 2, 2]], 6))
            elif cfg.shared_intrinsics:
                key = (f.width, f.height)
            else:
                key = (i,)
            groups.setdefault(key, []).append(i)
        out = []
        for group in groups.values():
            K = frames[group[0]].K
            cx, cy = K[0, 2] + _COLMAP_PIXEL_OFFSET, K[1, 2] + _COLMAP_PIXEL_OFFSET
            if cfg.fixed_intrinsics:
                values = (K[0, 0], K[1, 1], cx, cy)
                out.append((group, "PINHOLE", ",".join(repr(float(v)) for v in values)))
            else:
                f0 = 0.5 * (K[0, 0] + K[1, 1])
                values = (f0, cx, cy)
                out.append((group, "SIMPLE_PINHOLE", ",".join(repr(float(v)) for v in values)))
        return out

    @staticmethod
    def _read_matches(database: Path, names: list[str],
                      ids: dict[str, int]) -> dict[tuple[int, int], np.ndarray]:
        """Geometrically verified keypoint matches of every image pair, keyed by frame index."""
        import pycolmap

        db = pycolmap.Database.open(database)
        try:
            out = {}
            for i in range(len(names)):
                for j in range(i + 1, len(names)):
                    a, b = ids[names[i]], ids[names[j]]
                    if not db.exists_two_view_geometry(a, b):
                        out[(i, j)] = np.zeros((0, 2), np.int64)
                        continue
                    pairs = np.asarray(db.read_two_view_geometry(a, b).inlier_matches,
                                       dtype=np.int64).reshape(-1, 2)
                    out[(i, j)] = pairs
        finally:
            db.close()
        return out

    def _check_connectivity(self, frames: list[Frame],
                            matches: dict[tuple[int, int], np.ndarray]) -> None:
        """Fail early, naming the images, when the match graph cannot link every view."""
        need = self.config.min_num_matches
        parent = list(range(len(frames)))

        def root(i: int) -> int:
            while parent[i] != i:
                i = parent[i]
            return i

        for (i, j), pairs in matches.items():
            if len(pairs) >= need:
                parent[root(i)] = root(j)
        groups: dict[int, list[str]] = {}
        for i, f in enumerate(frames):
            groups.setdefault(root(i), []).append(f.name)
        if len(groups) > 1:
            counts = ", ".join(
                f"{frames[i].name}-{frames[j].name}: {len(p)}" for (i, j), p in matches.items()
            )
            parts = " | ".join(", ".join(g) for g in groups.values())
            raise SfmError(
                f"too few verified matches to connect all images (need {need} per pair; "
                f"{counts}); disconnected groups: {parts}"
            )

    @staticmethod
    def _to_result(model: object, frames: list[Frame], names: list[str],
                   matches: dict[tuple[int, int], np.ndarray]) -> SfmResult:
        """Convert a pycolmap reconstruction to an :class:`SfmResult` in input order."""
        by_name = {img.name: img for img in model.images.values()}
        missing = [f.name for name, f in zip(names, frames, strict=True) if name not in by_name
                   or not by_name[name].has_pose]
        if missing:
            raise SfmError(
                f"could not register {len(missing)} of {len(frames)} images: "
                f"{', '.join(missing)}; they overlap too little with the others"
            )
        point_rows: dict[int, int] = {}
        xyz, rgb = [], []
        for pid, point in model.points3D.items():
            point_rows[pid] = len(xyz)
            xyz.append(point.xyz)
            rgb.append(point.color)
        cameras, keypoints, point_ids = [], [], []
        for name, f in zip(names, frames, strict=True):
            img = by_name[name]
            cam = model.cameras[img.camera_id]
            K = cam.calibration_matrix()
            K = intrinsics_matrix(K[0, 0], K[1, 1], K[0, 2] - _COLMAP_PIXEL_OFFSET,
                                  K[1, 2] - _COLMAP_PIXEL_OFFSET)
            pose = img.cam_from_world()
            cameras.append(Camera(K=K, R=pose.rotation.matrix(), t=pose.translation,
                                  width=f.width, height=f.height, name=f.name))
            pts2d = img.points2D
            kp = np.array([p.xy for p in pts2d], dtype=np.float64).reshape(-1, 2)
            keypoints.append(kp - _COLMAP_PIXEL_OFFSET)
            point_ids.append(np.array(
                [point_rows.get(p.point3D_id, -1) if p.has_point3D() else -1 for p in pts2d],
                dtype=np.int64))
        return SfmResult(
            cameras=cameras,
            points=np.array(xyz, dtype=np.float64).reshape(-1, 3),
            keypoints=keypoints,
            point_ids=point_ids,
            matches=matches,
            colors=np.array(rgb, dtype=np.uint8).reshape(-1, 3),
        )


@hookimpl
def monoplane_register_matchers() -> list[type[Stage]]:
    """Register the built-in matchers."""
    return [ColmapMatcher]
