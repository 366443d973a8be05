"""The ``[cloud]`` config table: how a point cloud is prepared for the search
(:func:`monoplane.host.cloud_input.prepare_cloud`).

It lives apart from :mod:`monoplane.host.cloud_input` because :mod:`monoplane.host.config`
loads it to check the table, and the pipeline, which imports :mod:`monoplane.host.config`,
imports :mod:`monoplane.host.cloud_input`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from monoplane.contracts import param
from monoplane.errors import ConfigError


@dataclass
class CloudConfig:
    """How a point cloud is prepared for the search (config table ``[cloud]``).

    Normal orientation matters: the sampler, scorer and labeler compare signed normals.

    * ``auto`` (default): towards ``viewpoint`` where the viewpoint sees a point clearly, and
      along the surface from those points elsewhere
      (:func:`monoplane.geometry.orientation.orient_normals`). The same as ``viewpoint`` on a
      single scan whose sensor sat at ``viewpoint`` (by default the origin of the cloud's
      frame), and still consistent over a face that passes through the viewpoint (a sampled
      mesh with a corner at the origin), at about the cost of ``viewpoint``.
    * ``viewpoint``: every normal is turned towards ``viewpoint``, the rule of a single scan;
      on a face through the viewpoint the signs flip at random and the face breaks apart.
    * ``consistent``: Open3D's ``orient_normals_consistent_tangent_plane`` propagates one
      orientation over a Riemannian graph, ignoring the viewpoint; slow (about 11 s for
      20 000 points).
    """

    normals_knn: int = param(30, "neighbours of the PCA normal estimate (missing normals)")
    orient: Literal["auto", "viewpoint", "consistent"] = param(
        "auto", "orient estimated normals towards `viewpoint` where it sees them clearly and "
        "along the surface elsewhere (auto), towards `viewpoint` only, or consistently over "
        "the surface with Open3D (slow)")
    viewpoint: list[float] = param(
        [0.0, 0.0, 0.0], "sensor position for orient = auto or viewpoint, in the cloud's frame")

    def __post_init__(self) -> None:
        if self.normals_knn < 3:
            raise ConfigError(f"normals_knn must be at least 3, got {self.normals_knn}")
        if len(self.viewpoint) != 3 or not all(math.isfinite(v) for v in self.viewpoint):
            raise ConfigError(f"viewpoint must be 3 finite numbers, got "
                              f"{self.viewpoint}")
