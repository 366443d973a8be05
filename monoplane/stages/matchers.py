"""Built-in matchers: structure from motion over a few frames.

``colmap`` runs pycolmap on the CPU (no colmap binary): SIFT extraction, exhaustive matching
with geometric verification, then incremental mapping. With another ``[features]`` stage (XFeat,
a pairwise network) it writes that stage's keypoints and matches into COLMAP's database
instead, and COLMAP verifies and maps them. It returns an
:class:`~monoplane.datamodel.SfmResult` in the frames' native pixel coordinates (pixel centres at
integers, OpenCV camera axes), whatever resolution SIFT ran at internally.
"""

from __future__ import annotations

import contextlib
import shutil
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from monoplane.contracts import Matcher, Stage, param
from monoplane.datamodel import Camera, Frame, SfmResult, intrinsics_matrix
from monoplane.errors import InvalidInput, MonoplaneError
from monoplane.features import Correspondences
from monoplane.hookspecs import hookimpl

#: COLMAP puts pixel centres at +0.5; monoplane puts them at integers.
_COLMAP_PIXEL_OFFSET = 0.5


def image_name(index: int) -> str:
    """File name of the ``index``-th frame in COLMAP's image folder and database."""
    return f"{index:04d}.bmp"


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
    upsample_below: int = param(
        640, "images whose longest side (px) is below this get SIFT on a 2x upsampled copy "
        "(COLMAP's first octave -1: more features on small images); larger ones start at "
        "their own size, about 3x faster")
    min_num_matches: int = param(15, "fewest verified matches for an image pair to be used")
    min_num_features: int = param(50, "fewest SIFT features an image must yield")
    num_threads: int = param(-1, "CPU threads for pycolmap (-1 = all cores)")
    seed: int = param(0, "random seed of the mapper's RANSAC")


@contextlib.contextmanager
def _quiet_colmap() -> Iterator[None]:
    """Silence glog's output from pycolmap below FATAL while SfM runs.

    Its ERROR lines ("Failed to create any sparse model") describe outcomes this matcher
    reports itself, in one line naming the views (and which the registrar then handles); printed
    raw they reach the user's terminal as a third-party message with a glog prefix.
    """
    import pycolmap

    previous = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 3
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
    uses_correspondences = True

    @classmethod
    def fixed_intrinsics_config(cls, config: ColmapConfig) -> ColmapConfig:
        """``config`` with ``fixed_intrinsics`` set: COLMAP holds PINHOLE cameras fixed."""
        return replace(config, fixed_intrinsics=True)

    def match(self, frames: list[Frame], correspondences: Correspondences | None = None
              ) -> SfmResult:
        """Reconstruct cameras and sparse points of ``frames``.

        Parameters
        ----------
        frames : list of Frame
            Two or more frames with ``rgb`` set; ``K`` is the fixed or initial intrinsics.
        correspondences : Correspondences, optional
            The ``[features]`` stage's keypoints and matches. They are written into COLMAP's
            database and verified there, unless the stage is SIFT (``sfm_native == "sift"``)
            or none is given: then COLMAP extracts and matches its own SIFT.

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
            imported = (correspondences if correspondences is not None
                        and correspondences.sfm_native != "sift" else None)
            with _quiet_colmap():
                return self._run(frames, work, imported)
        finally:
            shutil.rmtree(work, ignore_errors=True)

    def _run(self, frames: list[Frame], work: Path,
             imported: Correspondences | None) -> SfmResult:
        import pycolmap

        cfg = self.config
        images = work / "images"
        images.mkdir()
        names = [image_name(i) for i in range(len(frames))]
        for name, f in zip(names, frames, strict=True):
            # Uncompressed BMP: COLMAP only reads the pixels back, and PNG's deflate cost
            # about 20 ms per 640x480 image on the critical path of a multi-view run.
            cv2.imwrite(str(images / name), f.rgb[..., ::-1])
        database = work / "database.db"
        if imported is None:
            self._extract_and_match(frames, names, images, database)
            what = "SIFT features"
        else:
            self._import(frames, names, images, database, imported)
            what = f"{imported.name} keypoints"

        db = pycolmap.Database.open(database)
        try:
            ids = {img.name: img.image_id for img in db.read_all_images()}
            # A textureless image cannot join the model, but need not stop the others: it is
            # left unregistered (the registrar may still place it from its depth and planes).
            poor = [(f.name, db.num_keypoints_for_image(ids[name]))
                    for name, f in zip(names, frames, strict=True)
                    if db.num_keypoints_for_image(ids[name]) < cfg.min_num_features]
            if len(frames) - len(poor) < 2:
                name, k = poor[0]
                raise SfmError(
                    f"{name}: only {k} {what} found (need {cfg.min_num_features}); "
                    "the image is too small, blurred or textureless"
                )
        finally:
            db.close()

        matches = self._read_matches(database, names, ids)
        if not any(len(m) >= cfg.min_num_matches for m in matches.values()):
            counts = ", ".join(f"{frames[i].name}-{frames[j].name}: {len(p)}"
                               for (i, j), p in matches.items())
            raise SfmError(f"too few verified matches to connect any two images (need "
                           f"{cfg.min_num_matches} per pair; {counts}); the images overlap too "
                           "little or are too textureless")
        model, attempts = self._map_with_retries(database, images, work, matches, len(frames))
        if model is None:
            best = max((len(m) for m in matches.values()), default=0)
            raise SfmError(
                "incremental mapping found no initial image pair: the best pair has "
                f"{best} verified matches but too little parallax (the camera moved too "
                "little for the scene depth) or too few inliers; use overlapping views taken "
                "further apart"
            )
        result = self._to_result(model, frames, names, matches, imported)
        for name, k in poor:
            result.notes.append(f"{name}: only {k} {what} (need {cfg.min_num_features}); "
                                "left out of the model")
        if imported is not None:
            result.notes.append(f"keypoints and matches from the '{imported.name}' features "
                                "stage, verified by COLMAP")
        result.notes.append(
            "intrinsics fixed to the given K" if cfg.fixed_intrinsics
            else "focal length estimated by bundle adjustment"
        )
        if attempts > 1:
            result.notes.append(f"registration needed {attempts} mapping attempts")
        missing = [f.name for f, ok in zip(frames, result.registered, strict=True) if not ok]
        if missing:
            groups = self._components(len(frames), matches)
            apart = [frames[i].name for i in range(len(frames))
                     if not result.registered[i] and groups[i] != groups[
                         int(np.flatnonzero(result.registered)[0])]]
            why = f" ({', '.join(apart)} share too few matches with the rest)" if apart else ""
            result.notes.append(f"COLMAP could not register {', '.join(missing)}{why}")
        return result

    def _readers(self, frames: list[Frame]) -> Iterator[tuple[list[int], object, object]]:
        """Per camera group: its frames, the image reader options and the camera mode."""
        import pycolmap

        for group, model, params in self._camera_groups(frames):
            reader = pycolmap.ImageReaderOptions()
            reader.camera_model = model
            reader.camera_params = params
            mode = pycolmap.CameraMode.SINGLE if len(group) > 1 else pycolmap.CameraMode.PER_IMAGE
            yield group, reader, mode

    def _extract_and_match(self, frames: list[Frame], names: list[str], images: Path,
                           database: Path) -> None:
        """COLMAP's own SIFT: extraction, exhaustive matching and geometric verification."""
        import pycolmap

        cfg = self.config
        extraction = pycolmap.FeatureExtractionOptions()
        extraction.use_gpu = False
        extraction.max_image_size = int(cfg.max_image_size)
        extraction.num_threads = int(cfg.num_threads)
        extraction.sift.max_num_features = int(cfg.max_num_features)
        for group, reader, mode in self._readers(frames):
            side = min(max(frames[group[0]].shape), int(cfg.max_image_size))
            extraction.sift.first_octave = -1 if side < cfg.upsample_below else 0
            pycolmap.extract_features(
                database, images, image_names=[names[i] for i in group], camera_mode=mode,
                reader_options=reader, extraction_options=extraction,
                device=pycolmap.Device.cpu,
            )
        matching = pycolmap.FeatureMatchingOptions()
        matching.use_gpu = False
        matching.num_threads = int(cfg.num_threads)
        pycolmap.match_exhaustive(database, matching_options=matching, device=pycolmap.Device.cpu)

    def _import(self, frames: list[Frame], names: list[str], images: Path, database: Path,
                found: Correspondences) -> None:
        """Write a features stage's keypoints and matches into COLMAP's database and let COLMAP
        verify every pair geometrically (the same verification its own matches get)."""
        import pycolmap

        pycolmap.Database.open(database).close()  # import_images needs the file to exist
        for group, reader, mode in self._readers(frames):
            pycolmap.import_images(database, images, camera_mode=mode,
                                   image_names=[names[i] for i in group], options=reader)
        matches = found.all_matches()
        db = pycolmap.Database.open(database)
        try:
            ids = {img.name: img.image_id for img in db.read_all_images()}
            for v, name in enumerate(names):
                pixels = found.keypoints(v).pixels + _COLMAP_PIXEL_OFFSET
                db.write_keypoints(ids[name], np.ascontiguousarray(pixels, np.float32))
            for (i, j), m in matches.items():
                db.write_matches(ids[names[i]], ids[names[j]],
                                 np.ascontiguousarray(m, np.uint32).reshape(-1, 2))
        finally:
            db.close()
        verification = pycolmap.TwoViewGeometryOptions()
        verification.compute_relative_pose = True
        pycolmap.geometric_verification(database, two_view_geometry_options=verification)

    def _options(self, relaxed: bool) -> object:
        """Incremental-mapping options; ``relaxed`` lowers the image-registration thresholds."""
        import pycolmap

        cfg = self.config
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
        if relaxed:
            # Small or low-texture views see few of the model's points: accept a pose from
            # fewer 2D-3D inliers, and let the mapper try each view more often.
            options.mapper.abs_pose_min_num_inliers = 12
            options.mapper.abs_pose_min_inlier_ratio = 0.1
            options.mapper.max_reg_trials = 6
            options.mapper.init_min_num_inliers = 50
            options.structure_less_registration_fallback = True
        return options

    def _map_with_retries(self, database: Path, images: Path, work: Path,
                          matches: dict[tuple[int, int], np.ndarray],
                          n: int) -> tuple[object | None, int]:
        """Incremental mapping that tries harder when views are left out.

        1. COLMAP's defaults. 2. If views are missing, continue from that model with relaxed
        registration thresholds, so left-over views are re-attempted against the grown
        model. 3. If views are still missing (or there was no model), map afresh from a
        second initial pair: the best-matched pair that involves a missing view. The model
        with the most registered views wins.

        Returns
        -------
        (pycolmap.Reconstruction or None, int)
            The best model and the number of mapping runs.
        """
        import pycolmap

        def run(tag: str, options: object, input_path: Path | None = None) -> object | None:
            out = work / f"sparse_{tag}"
            out.mkdir()
            kwargs = {"input_path": input_path} if input_path is not None else {}
            models = pycolmap.incremental_mapping(database, images, out, options=options,
                                                  **kwargs)
            if not models:
                return None
            best = max(models.values(), key=lambda m: m.num_reg_images())
            best_dir = out / "best"
            best_dir.mkdir()
            best.write(best_dir)
            return best, best_dir

        def count(entry: object | None) -> int:
            return entry[0].num_reg_images() if entry is not None else 0

        attempts = 1
        best = run("a", self._options(relaxed=False))
        if count(best) < n and best is not None:
            attempts += 1
            grown = run("b", self._options(relaxed=True), best[1])
            if count(grown) > count(best):
                best = grown
        if count(best) < n:
            db = pycolmap.Database.open(database)
            try:
                ids = {img.name: img.image_id for img in db.read_all_images()}
            finally:
                db.close()
            names_by_id = {i: name for name, i in ids.items()}
            registered = set()
            if best is not None:
                registered = {names_by_id[i] for i in best[0].reg_image_ids()}
            order = sorted(matches.items(), key=lambda kv: -len(kv[1]))
            for (i, j), pairs in order:
                if len(pairs) < self.config.min_num_matches:
                    break
                name_i, name_j = image_name(i), image_name(j)
                if name_i in registered and name_j in registered:
                    continue
                attempts += 1
                options = self._options(relaxed=True)
                options.init_image_id1 = int(ids[name_i])
                options.init_image_id2 = int(ids[name_j])
                second = run(f"c{attempts}", options)
                if count(second) > count(best):
                    best = second
                break
        return (best[0] if best is not None else None), attempts

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

    def _components(self, n: int, matches: dict[tuple[int, int], np.ndarray]) -> np.ndarray:
        """(n,) component label of each view in the graph of pairs with enough matches."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import connected_components

        need = self.config.min_num_matches
        pairs = np.array([key for key, m in matches.items() if len(m) >= need],
                         dtype=np.int64).reshape(-1, 2)
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
        return connected_components(graph, directed=False)[1]

    @staticmethod
    def _to_result(model: object, frames: list[Frame], names: list[str],
                   matches: dict[tuple[int, int], np.ndarray],
                   imported: Correspondences | None) -> SfmResult:
        """Convert a pycolmap reconstruction to an :class:`SfmResult` in input order.

        With imported correspondences every view keeps its keypoints and verified matches,
        registered or not (they are the features stage's own); with COLMAP's SIFT an
        unregistered view's keypoints are not in the model and its matches are dropped.
        """
        by_name = {img.name: img for img in model.images.values() if img.has_pose}
        point_rows: dict[int, int] = {}
        xyz, rgb = [], []
        for pid, point in model.points3D.items():
            point_rows[pid] = len(xyz)
            xyz.append(point.xyz)
            rgb.append(point.color)
        cameras, keypoints, point_ids = [], [], []
        registration = []
        for name, f in zip(names, frames, strict=True):
            img = by_name.get(name)
            if img is None:
                # Placeholder camera (identity pose, the frame's K), marked unregistered.
                cameras.append(Camera(K=f.K, R=np.eye(3), t=np.zeros(3), width=f.width,
                                      height=f.height, name=f.name))
                own = (imported.keypoints(len(keypoints)).pixels if imported is not None
                       else np.zeros((0, 2)))
                keypoints.append(own)
                point_ids.append(np.full(len(own), -1, np.int64))
                registration.append({"method": "none"})
                continue
            registration.append({"method": "sfm"})
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
        # COLMAP's SIFT keypoints of unregistered views are not in the model: drop their matches.
        usable = [imported is not None or r["method"] != "none" for r in registration]
        matches = {(i, j): (m if usable[i] and usable[j] else np.zeros((0, 2), np.int64))
                   for (i, j), m in matches.items()}
        return SfmResult(
            cameras=cameras,
            points=np.array(xyz, dtype=np.float64).reshape(-1, 3),
            keypoints=keypoints,
            point_ids=point_ids,
            matches=matches,
            colors=np.array(rgb, dtype=np.uint8).reshape(-1, 3),
            registration=registration,
        )


@hookimpl
def monoplane_register_matchers() -> list[type[Stage]]:
    """Register the built-in matchers."""
    return [ColmapMatcher]
