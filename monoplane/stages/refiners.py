"""Built-in refiners: image-level refinement of the multi-plane label map (paper appendix).

* ``none``: returns the RANSAC result as is (the ablation rows without CRF).
* ``dense-crf``: fully connected CRF with smoothness, appearance, depth and normal kernels
  (eq. 13 and the kernels after it), then connected-component splitting, removal of small
  regions and a least-squares refit of every plane on its final pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

from monoplane.densecrf import CrfParams, dense_crf
from monoplane.errors import ConfigError, InvalidInput
from monoplane.hookspecs import hookimpl
from monoplane.regions import MIN_AREA_AT_REFERENCE, clean_regions, scaled_min_area
from monoplane.stages.base import Refiner, Stage, param
from monoplane.types import Reconstruction


class NoRefiner(Refiner):
    """Keep the RANSAC labels and planes unchanged."""

    name = "none"

    def refine(self, rec: Reconstruction) -> Reconstruction:
        """Return ``rec`` itself."""
        return rec


class DenseCrfRefiner(Refiner):
    """Dense CRF over the label map, then connected components, small-region removal, refit.

    The unary term gives each pixel's RANSAC label (non-planar is label 0) probability
    ``confidence`` and spreads the rest evenly over the other labels. The pairwise term is a
    Potts model weighted by four Gaussian kernels; see :class:`monoplane.densecrf.CrfParams`
    for exactly what each θ divides. Kernels whose weight is 0, or whose cue is missing (no or
    grey RGB, no depth, no normals), are dropped. Positional θ and the minimum area are given
    at the paper's 256 x 192 and scale with the image.
    """

    name = "dense-crf"

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
        iterations: int = param(5, "mean-field iterations (0 skips the CRF, keeps the clean-up)")
        min_area: int = param(
            MIN_AREA_AT_REFERENCE,
            "smallest region kept, pixels at 256x192 (scaled with image area); 0 keeps all")
        connectivity: int = param(8, "pixel connectivity of a region: 4 or 8")
        split: bool = param(
            True, "give each connected region its own plane (paper); false only drops small ones")

    def __init__(self, config: Config | None = None) -> None:
        super().__init__(config)
        c = self.config
        if c.connectivity not in (4, 8):
            raise ConfigError(f"refiner.connectivity must be 4 or 8, got {c.connectivity}")
        if c.min_area < 0:
            raise ConfigError(f"refiner.min_area must be >= 0, got {c.min_area}")
        # Above 1/2 the RANSAC label stays the most likely one whatever the number of planes.
        if not 0.5 < c.confidence < 1.0:
            raise ConfigError(f"refiner.confidence must lie in (0.5, 1), got {c.confidence}")
        try:
            self.crf = CrfParams(
                theta_position=c.theta_position, theta_color=c.theta_color,
                theta_depth=c.theta_depth, theta_normal=c.theta_normal,
                w_smoothness=c.w_smoothness, w_appearance=c.w_appearance,
                w_depth=c.w_depth, w_normal=c.w_normal,
                confidence=c.confidence, iterations=c.iterations,
            )
        except InvalidInput as exc:
            raise ConfigError(f"refiner: {exc}") from exc

    def refine(self, rec: Reconstruction) -> Reconstruction:
        """Refine ``rec``'s labels and refit its planes.

        Parameters
        ----------
        rec : Reconstruction
            RANSAC result; its frame must have a depth map (normals and RGB optional).

        Returns
        -------
        Reconstruction
            Labels 1..P' (each a connected region of at least the minimum area), parameters,
            RMSE and support refit on each region's valid pixels (camera frame, depth units).
        """
        frame = rec.frame
        labels = dense_crf(rec.labels, rec.num_planes + 1, self.crf, rgb=frame.rgb,
                           depth=frame.depth, normals=frame.normals)
        min_area = scaled_min_area(frame.shape, self.config.min_area)
        return clean_regions(rec, labels, min_area, self.config.connectivity,
                             split=self.config.split)


@hookimpl
def monoplane_register_refiners() -> list[type[Stage]]:
    """Register the built-in refiners."""
    return [NoRefiner, DenseCrfRefiner]
