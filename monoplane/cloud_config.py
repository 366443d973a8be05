"""The ``[cloud]`` config table: how :func:`monoplane.detect.detect_planes` prepares a cloud.

It lives apart from :mod:`monoplane.detect` because :mod:`monoplane.config` loads it to check the
table, and :mod:`monoplane.detect` drives the pipeline, which imports :mod:`monoplane.config`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from monoplane.errors import ConfigError
from monoplane.stages.base import param


@dataclass
class CloudConfig:
    """How :func:`detect_planes` prepares a cloud (config table ``[cloud]``).

    Normal orientation matters: the sampler, scorer and labeler compare signed normals.

    * ``viewpoint`` (default): every normal is turned towards ``viewpoint``. Right for a
      single scan (LiDAR, one depth camera, an unprojected range image) whose sensor sat at
      that point, by default the origin of the cloud's frame; also right for a convex object
      or a room seen from a point inside it.
    * ``consistent``: Open3D's ``orient_normals_consistent_tangent_plane`` propagates one
      orientation over a Riemannian graph. Right for fused scans and sampled meshes, which
      have no single viewpoint; it is slower and orients each connected part independently.
    """

    normals_knn: int = param(30, "neighbours of the PCA normal estimate (missing normals)")
    orient: Literal["viewpoint", "consistent"] = param(
        "viewpoint", "orient estimated normals towards `viewpoint` (single scans) or "
        "consistently over the surface (fused scans, meshes)")
    viewpoint: list[float] = param(
        [0.0, 0.0, 0.0], "sensor position for orient = viewpoint, in the cloud's frame")

    def __post_init__(self) -> None:
        if self.normals_knn < 3:
            raise ConfigError(f"normals_knn must be at least 3, got {self.normals_knn}")
        if len(self.viewpoint) != 3 or not all(math.isfinite(v) for v in self.viewpoint):
            raise ConfigError(f"viewpoint must be 3 finite numbers, got "
                              f"{self.viewpoint}")
