"""The built-in baseline, a plugin of the ``monoplane_register_baselines`` hook like any other.

``open3d-ransac``: Open3D's ``PointCloud.segment_plane`` applied sequentially. The cloud is the
frame's valid pixels normalised into the unit sphere exactly as the pipeline does it
(:class:`~monoplane.geometry.cloud.PlaneCloud`), so the paper's ε = 0.02 means the same thing
for both. Each round takes the best plane of the remaining points and removes its inliers,
until the best plane has fewer inliers than the pipeline's minimum plane size (0.6 % of the
valid pixels, the paper's 300 px at 256×192) or 20 planes were found (the pipeline's limit).
Each round runs at most 1000 iterations (the pipeline's limit too) with Open3D's own early
termination at its default confidence; every valid pixel is used (no subsampling). These
shared values are read from :class:`~monoplane.algorithm.ransac.RansacConfig`'s defaults. Normals are not
used (``segment_plane`` has no normal test) and there is no spatial coherence: that is what the
baseline stands for, plain sequential RANSAC from a widely used library.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from monoplane.datamodel import Frame, Reconstruction
from monoplane.evaluation.baseline_base import (
    CALL_TIMING,
    Baseline,
    RansacBaselineSettings,
    baseline_config,
)
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.planes import fit_plane
from monoplane.hookspecs import hookimpl
from monoplane.algorithm.ransac import RansacConfig

_RANSAC = RansacConfig()


@dataclass(frozen=True)
class Open3DRansacConfig(RansacBaselineSettings):
    """Settings of the ``open3d-ransac`` baseline (plus :class:`RansacBaselineSettings`).

    Attributes
    ----------
    num_iterations : int
        Maximum RANSAC iterations per plane (the pipeline's ``ransac.max_iterations``).
    probability : float
        Confidence at which Open3D stops early (its default).
    max_planes : int
        Stop after this many planes (as the pipeline's ``ransac.max_planes``).
    """

    num_iterations: int = _RANSAC.max_iterations
    probability: float = 0.99999999
    max_planes: int = _RANSAC.max_planes

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.num_iterations < 1 or self.max_planes < 1:
            raise ValueError("num_iterations and max_planes must be at least 1")
        if not 0 < self.probability <= 1:
            raise ValueError(f"probability must lie in (0, 1], got {self.probability}")


def open3d_ransac(frame: Frame, *, seed: int = 0, **options: Any) -> Reconstruction:
    """Sequential Open3D ``segment_plane`` on the frame's normalised point cloud.

    Parameters
    ----------
    frame : Frame
        Frame with ``depth`` (normals, when present, only decide which pixels are valid).
    seed : int
        Seed of Open3D's global random generator. Open3D 0.19 runs the RANSAC iterations in
        parallel threads with early termination, so two runs with the same seed can still
        differ slightly on hard frames.
    **options
        Fields of :class:`Open3DRansacConfig` to override (defaults as documented in the
        module docstring), e.g. ``min_support=0.001``.

    Returns
    -------
    Reconstruction
        Labels 1..P in detection order; planes in the camera frame (OpenCV axes) and depth
        units; ``rmse`` in depth units; ``support`` = inlier count.

    Raises
    ------
    ConfigError
        On an unknown option or an ill-typed value (the message lists the valid options).
    """
    import open3d as o3d

    cfg = baseline_config(Open3DRansacConfig, options, "open3d-ransac")
    cloud = PlaneCloud.from_frame(frame)
    min_support = max(3, cfg.min_support_points,
                      int(np.ceil(cfg.min_support * cloud.all_points.shape[0])))
    o3d.utility.random.seed(int(seed))
    remaining = np.arange(cloud.all_points.shape[0])
    flat = np.zeros(frame.height * frame.width, dtype=np.int32)
    planes: list[np.ndarray] = []
    rmses: list[float] = []
    supports: list[int] = []
    call = 0.0
    while len(planes) < cfg.max_planes and remaining.size >= min_support:
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.all_points[remaining]))
        start = time.perf_counter()
        _, inliers = pcd.segment_plane(distance_threshold=cfg.epsilon, ransac_n=3,
                                       num_iterations=cfg.num_iterations,
                                       probability=cfg.probability)
        call += time.perf_counter() - start
        if len(inliers) < min_support:
            break
        chosen = remaining[np.asarray(inliers, dtype=np.int64)]
        # Report the least-squares plane of the inliers (as every method's planes are), in
        # the camera frame; the labels stay Open3D's.
        plane, rmse = fit_plane(cloud.all_points[chosen])
        planes.append(cloud.plane_to_camera(plane))
        rmses.append(rmse * cloud.scale)
        supports.append(chosen.size)
        flat[cloud.pixel_grid()[2][chosen]] = len(planes)
        remaining = np.setdiff1d(remaining, chosen, assume_unique=True)
    return Reconstruction(frame=frame, labels=flat.reshape(frame.shape),
                          planes=np.asarray(planes, dtype=np.float64).reshape(-1, 4),
                          rmse=np.asarray(rmses, dtype=np.float64),
                          support=np.asarray(supports, dtype=np.int64),
                          config={"baseline": "open3d-ransac", **asdict(cfg)},
                          timings={CALL_TIMING: call})


# Lets the host check --baseline-set options before the first frame.
open3d_ransac.config_class = Open3DRansacConfig  # type: ignore[attr-defined]


@hookimpl
def monoplane_register_baselines() -> dict[str, Baseline]:
    """Register the built-in baseline."""
    return {"open3d-ransac": open3d_ransac}
