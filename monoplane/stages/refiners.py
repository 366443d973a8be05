"""Built-in refiners: image-level refinement of the multi-plane label map (paper appendix).

* ``none``: returns the RANSAC result as is (the ablation rows without CRF).
* ``dense-crf``: fully connected CRF with smoothness, appearance, depth and normal kernels
  (eq. 13 and the kernels after it), then connected-component splitting, removal of small
  regions and a least-squares refit of every plane on its final pixels.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields

import numpy as np

from monoplane.algorithm.densecrf import REFERENCE_AREA, CrfGrid, CrfParams, crf_grid, dense_crf
from monoplane.algorithm.region_moments import scene_radius
from monoplane.algorithm.regions import (
    MIN_AREA_AT_REFERENCE,
    clean_regions,
    gate_filled_pixels,
    scaled_min_area,
)
from monoplane.contracts import RansacParams, Refiner, Stage, WorkAhead, param
from monoplane.datamodel import Frame, Reconstruction
from monoplane.datamodel.pinhole import pixel_rays
from monoplane.errors import ConfigError, InvalidInput, check_config
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.graph import NeighbourGraph
from monoplane.hookspecs import hookimpl


@dataclass
class _FrameWork:
    """What the dense-crf refiner computes from a frame alone (see :meth:`Refiner.prepare`).

    Attributes
    ----------
    grid : CrfGrid
        The CRF's block grid and lattices (:func:`monoplane.algorithm.densecrf.crf_grid`).
    points : numpy.ndarray
        (H, W, 3) camera-frame points, depth units (``frame.points()``).
    fill_tolerance : float
        Distance in depth units within which a filled pixel keeps its plane:
        ``fill_distance`` times the scene radius of the valid pixels (inf without the gate).
    """

    grid: CrfGrid
    points: np.ndarray
    fill_tolerance: float


class NoRefiner(Refiner):
    """Keep the RANSAC labels and planes unchanged."""

    name = "none"
    needs_pixels = False

    def refine(self, rec: Reconstruction, params: RansacParams) -> Reconstruction:
        """Return ``rec`` itself."""
        return rec

    def refine_cloud(self, cloud: PlaneCloud, graph: NeighbourGraph, labels: np.ndarray,
                     planes: np.ndarray, params: RansacParams) -> tuple[np.ndarray, np.ndarray]:
        """Return the cloud labels and planes unchanged."""
        return labels, planes


class DenseCrfRefiner(WorkAhead, Refiner):
    """Dense CRF over the label map, then connected components, small-region removal, refit.

    The unary term gives each pixel's RANSAC label probability ``confidence`` and spreads the
    rest evenly over the other labels. The pairwise term is a Potts model weighted by four
    Gaussian kernels (weights 1, as in the paper); see
    :class:`monoplane.algorithm.densecrf.CrfParams` for exactly what each θ divides. Kernels
    whose weight is 0, or whose cue is missing (no or grey RGB, no depth, no normals), are
    dropped. Positional θ and the minimum area are given
    at the paper's 256 x 192 and scale with the image.

    Deviations from the paper, each a switch (all on by default; off gives the paper's
    refiner), measured in ``docs/design.md`` ("Refiner: deviations from the paper"):

    * ``uniform_nonplanar``: a pixel the RANSAC left non-planar (label 0) has a uniform unary,
      so the kernels decide its label, instead of voting for "non-planar" like an observed
      plane label. ``fill_distance`` optionally keeps such a pixel's new plane only when its
      point lies within that distance of the plane.
    * ``fit_inliers_only``: planes are refit on the pixels the RANSAC labelled planar, so
      filled pixels (possibly on a non-planar object) do not bend them.
    * ``merge``: regions split from one plane whose refit planes agree (normal within
      ``merge_angle_deg``, cross RMS residuals within ``merge_distance``) are re-joined, so an
      occluder does not cut a floor into several planes.
    * ``absorb``: a region under the minimum area joins an adjacent plane its points fit
      (RMS within ``merge_distance``) and is set non-planar only otherwise.

    Distances are fractions of the scene radius
    (:func:`monoplane.algorithm.region_moments.scene_radius`), like the RANSAC's ε.
    """

    name = "dense-crf"
    #: The CRF's kernels are over pixel positions and image colour: it cannot refine a cloud.
    needs_pixels = True

    @dataclass
    class Config:
        theta_position: float = param(
            10.0, "θ_s: positional deviation in pixels at 256x192 (scaled with image size)")
        theta_color: float = param(10.0, "θ_a: colour deviation in 8-bit RGB levels (0-255)")
        theta_depth: float = param(
            0.01, "depth deviation, depth divided by the frame's largest depth")
        theta_normal: float = param(0.1, "normal deviation, on unit normal vectors (0.1 ~ 5.7°)")
        w_smoothness: float = param(1.0, "weight of the smoothness kernel (0 disables)")
        w_appearance: float = param(1.0, "weight of the appearance kernel (0 disables)")
        w_depth: float = param(1.0, "weight of the depth kernel (0 disables)")
        w_normal: float = param(1.0, "weight of the normal kernel (0 disables)")
        confidence: float = param(
            0.55, "unary: probability of the RANSAC label, rest spread evenly over the others")
        iterations: int = param(2, "mean-field iterations (0 skips the CRF, keeps the clean-up)")
        max_pixels: int = param(
            REFERENCE_AREA // 8,
            "above this many pixels mean field runs on a coarser block grid, edges are decided "
            "at full resolution (0: never)")
        band_margin: float = param(
            2.0,
            "with the coarse grid, exact full-resolution messages only at band pixels whose "
            "upsampled messages leave the two best labels within this many nats (inf: all)")
        min_area: int = param(
            MIN_AREA_AT_REFERENCE,
            "smallest region kept, pixels at 256x192 (scaled with image area); 0 keeps all")
        connectivity: int = param(8, "pixel connectivity of a region: 4 or 8")
        split: bool = param(
            True, "give each connected region its own plane (paper); false only drops small ones")
        merge: bool = param(
            True, "after the split, re-join regions of one plane whose refit planes agree")
        merge_adjacent: bool = param(
            True, "merge also joins touching regions of different planes that agree")
        absorb: bool = param(
            True, "a small region joins an adjacent plane its points fit instead of being dropped")
        merge_angle_deg: float = param(10.0, "normal tolerance of merge, degrees (like ε_n)")
        merge_distance: float = param(
            0.04, "RMS point-to-plane tolerance of merge and absorb, fraction of scene radius")
        uniform_nonplanar: bool = param(
            True, "unary: pixels the RANSAC left non-planar get no preference, the kernels decide")
        fill_distance: float = param(
            0.1, "a pixel the CRF gives a new plane keeps it only within this distance "
            "of it, fraction of scene radius (inf: no test)")
        fill_angle_deg: float = param(
            45.0, "... and only where its normal lies within this angle of the plane's, "
            "degrees (180: no test)")
        fill_patch_px: int = param(
            1, "the normal test rejects only patches at least 2 × this + 1 pixels wide (at "
            "256 px, scaled with the width): the cue blurs normals across a crease")
        fit_inliers_only: bool = param(
            True, "refit planes only on pixels the RANSAC labelled planar (not on filled holes)")

    def __init__(self, config: Config | None = None) -> None:
        super().__init__(config)
        c = self.config
        check_config([
            (c.connectivity in (4, 8), f"connectivity must be 4 or 8, got {c.connectivity}"),
            (0 < c.merge_angle_deg <= 90,
             f"merge_angle_deg must lie in (0, 90], got {c.merge_angle_deg}"),
            (c.merge_distance > 0, f"merge_distance must be positive, got {c.merge_distance}"),
            (c.fill_distance > 0, f"fill_distance must be positive, got {c.fill_distance}"),
            (0 < c.fill_angle_deg <= 180,
             f"fill_angle_deg must lie in (0, 180], got {c.fill_angle_deg}"),
            (c.fill_patch_px >= 0, f"fill_patch_px must be >= 0, got {c.fill_patch_px}"),
            (c.min_area >= 0, f"min_area must be >= 0, got {c.min_area}"),
            # Above 1/2 the RANSAC label stays the most likely one whatever the number of
            # planes.
            (0.5 < c.confidence < 1.0, f"confidence must lie in (0.5, 1), got {c.confidence}"),
        ], prefix="refiner.")
        try:
            # The CRF's parameters are a subset of this config, which alone holds defaults.
            self.crf = CrfParams(**{f.name: getattr(c, f.name) for f in fields(CrfParams)})
        except InvalidInput as exc:
            raise ConfigError(f"refiner: {exc}") from exc

    #: The pixel rays of the last camera seen, keyed by its intrinsics and image size: the
    #: frames of a sequence share them, and building them costs more than the points do.
    _rays: tuple[bytes, tuple[int, int], np.ndarray] | None = None

    def prepare(self, frame: Frame) -> None:
        """Build the CRF's lattices, the 3D points and the fill tolerance of ``frame`` on the
        background thread (they do not depend on the labels); :meth:`refine` picks them up.
        With a budget of one thread (batch workers) :meth:`refine` builds them itself, so
        that the time stays in the refiner's."""
        if frame.depth is not None:
            self._start_ahead(frame, lambda f: self._frame_work(f, False))

    def _frame_work(self, frame: Frame, threaded: bool = True) -> _FrameWork:
        """The label-independent part of :meth:`refine` for ``frame`` (which has depth); with
        ``threaded`` False on this thread alone."""
        assert frame.depth is not None
        c = self.config
        grid = crf_grid(frame.shape, self.crf, rgb=frame.rgb, depth=frame.depth,
                        normals=frame.normals, threaded=threaded)
        points = self._points(frame)
        tolerance = np.inf
        if np.isfinite(c.fill_distance):
            tolerance = c.fill_distance * scene_radius(points, frame.depth > 0)
        return _FrameWork(grid, points, tolerance)

    def _points(self, frame: Frame) -> np.ndarray:
        """``frame.points()`` (H, W, 3) float64, with the pixel rays of the frame's camera
        reused from the previous frame when its intrinsics and size are the same (the same
        values: the rays times the depth as float64)."""
        assert frame.depth is not None
        key = (np.asarray(frame.K, dtype=np.float64).tobytes(), frame.shape)
        cached = self._rays
        if cached is None or cached[:2] != key:
            cached = self._rays = (*key, pixel_rays(frame.K, *frame.shape))
        return cached[2] * frame.depth[..., None].astype(np.float64)

    def refine(self, rec: Reconstruction, params: RansacParams) -> Reconstruction:
        """Refine ``rec``'s labels and refit its planes.

        Parameters
        ----------
        rec : Reconstruction
            RANSAC result; its frame must have a depth map (normals and RGB optional).
        params : RansacParams
            Not used: the CRF's distances (``fill_distance``, ``merge_distance``) are fractions
            of the scene radius of their own, tuned on the image benchmark.

        Returns
        -------
        Reconstruction
            Labels 1..P' (each a connected region of at least the minimum area), parameters,
            RMSE and support refit on each region's valid pixels (camera frame, depth units).
        """
        frame = rec.frame
        if frame.depth is None:
            raise InvalidInput(f"{frame.name}: the dense-crf refiner needs a depth map")
        start = time.perf_counter()
        work = self._take_ahead(frame, self._frame_work)
        labels = dense_crf(rec.labels, rec.num_planes + 1, self.crf, rgb=frame.rgb,
                           depth=frame.depth, normals=frame.normals, grid=work.grid)
        c = self.config
        min_area = scaled_min_area(frame.shape, c.min_area)
        if np.isfinite(work.fill_tolerance) or c.fill_angle_deg < 180:
            labels = gate_filled_pixels(
                work.points, frame.depth > 0, rec.labels, labels, rec.planes,
                work.fill_tolerance, frame.normals, c.fill_angle_deg,
                patch_px=int(round(c.fill_patch_px * frame.width / 256)))
        crf = time.perf_counter() - start
        out = clean_regions(rec, labels, min_area, c.connectivity, split=c.split, merge=c.merge,
                            absorb=c.absorb, max_angle_deg=c.merge_angle_deg,
                            max_distance=c.merge_distance, inliers_only=c.fit_inliers_only,
                            merge_adjacent=c.merge_adjacent, points=work.points)
        # Sub-steps for 'monoplane bench': the CRF (with the fill gate, and the wait for the
        # work prepared in the background, if any), then the regions.
        out.timings["refiner.crf"] = crf
        out.timings["refiner.regions"] = time.perf_counter() - start - crf
        return out


@hookimpl
def monoplane_register_refiners() -> list[type[Stage]]:
    """Register the built-in refiners."""
    return [NoRefiner, DenseCrfRefiner]
