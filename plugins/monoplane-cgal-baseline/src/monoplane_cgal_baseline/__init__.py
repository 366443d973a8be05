"""CGAL Efficient RANSAC (Schnabel et al. 2007) as a ``monoplane eval`` baseline.

Registered under the name ``cgal`` through monoplane's ``monoplane_register_baselines`` hook
(this module is a plugin in the ``monoplane`` entry-point group). The callable follows
monoplane's baseline contract: ``baseline(frame, *, seed=0, **options) -> Reconstruction``,
planes in the frame's camera frame (OpenCV axes) and depth units, and
``timings["baseline.call"]`` the seconds of the ``efficient_RANSAC`` call alone (building
CGAL's point set excluded). The keyword options are fields of :class:`CgalRansacConfig`
(``monoplane eval --baseline cgal --baseline-set cgal.min_support=0.001``).

License: GPL-3.0-or-later (CGAL's Shape_detection package is GPL).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from monoplane.plugin import (
    Frame,
    PlaneCloud,
    RansacBaselineSettings,
    RansacParams,
    Reconstruction,
    baseline_config,
    fit_plane,
    hookimpl,
)

__version__ = "0.1.0"

#: The pipeline's shared thresholds; their defaults are read, not copied.
_RANSAC = RansacParams()


@dataclass(frozen=True)
class CgalRansacConfig(RansacBaselineSettings):
    """Settings of CGAL's ``efficient_RANSAC`` (plane shapes only), in unit-sphere units, plus
    the ε and minimum plane size every RANSAC baseline shares with the pipeline.

    Attributes
    ----------
    normal_deg : float
        Largest angle between a point's normal and the plane normal (paper's ε_n), degrees.
    cluster_epsilon : float
        Largest gap between neighbouring points of one shape (CGAL keeps the largest connected
        component of a candidate).
    probability : float
        CGAL's probability of missing the largest candidate shape (its default).
    """

    normal_deg: float = _RANSAC.epsilon_n_deg
    cluster_epsilon: float = 0.03
    probability: float = 0.01

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.cluster_epsilon > 0:
            raise ValueError("cluster_epsilon must be positive")
        if not 0 < self.normal_deg < 90:
            raise ValueError(f"normal_deg must lie in (0, 90), got {self.normal_deg}")
        if not 0 < self.probability < 1:
            raise ValueError(f"probability must lie in (0, 1), got {self.probability}")


def _point_set(points: np.ndarray, normals: np.ndarray) -> object:
    from CGAL import CGAL_Point_set_3
    from CGAL.CGAL_Kernel import Vector_3

    ps = CGAL_Point_set_3.Point_set_3()
    ps.insert_range(np.ascontiguousarray(points, dtype=np.float64).ravel().tolist())
    ps.add_normal_map()
    normal_map = ps.normal_map()
    for i, (x, y, z) in enumerate(normals.tolist()):
        normal_map.set(i, Vector_3(x, y, z))
    return ps


def cgal_efficient_ransac(frame: Frame, *, seed: int = 0, **options: Any) -> Reconstruction:
    """Detect planes with CGAL's Efficient RANSAC on the frame's normalised oriented cloud.

    Parameters
    ----------
    frame : Frame
        Frame with ``depth`` and ``normals`` (camera frame, facing the camera).
    seed : int
        Accepted for the baseline contract; CGAL's bindings expose no seed.
    **options
        Fields of :class:`CgalRansacConfig` to override (defaults as in the package README),
        e.g. ``min_support=0.001``.

    Returns
    -------
    Reconstruction
        Labels 1..P in CGAL's detection order (0 = unassigned); planes are least-squares fits
        of each shape's points in the camera frame and depth units.

    Raises
    ------
    monoplane.plugin.ConfigError
        On an unknown option or an ill-typed value (the message lists the valid options).
    """
    from CGAL import CGAL_Shape_detection

    del seed  # CGAL uses its own default random generator
    cfg = baseline_config(CgalRansacConfig, options, "cgal")
    cloud = PlaneCloud.from_frame(frame)
    normals = frame.normals.reshape(-1, 3)[cloud.all_pixels].astype(np.float64)
    ps = _point_set(cloud.all_points, normals)
    shape_map = ps.add_int_map("shape", -1)
    n_points = cloud.all_points.shape[0]
    min_points = max(3, cfg.min_support_points, int(math.ceil(cfg.min_support * n_points)))
    start = time.perf_counter()
    CGAL_Shape_detection.efficient_RANSAC(
        ps, shape_map, min_points=min_points, epsilon=cfg.epsilon,
        cluster_epsilon=cfg.cluster_epsilon,
        normal_threshold=math.cos(math.radians(cfg.normal_deg)),
        probability=cfg.probability, planes=True)
    call = time.perf_counter() - start
    shape = np.fromiter((shape_map.get(i) for i in range(n_points)), dtype=np.int64,
                        count=n_points)
    flat = np.zeros(frame.height * frame.width, dtype=np.int32)
    planes: list[np.ndarray] = []
    rmses: list[float] = []
    supports: list[int] = []
    for sid in np.unique(shape[shape >= 0]):
        members = np.flatnonzero(shape == sid)
        if members.size < 3:
            continue
        plane, rmse = fit_plane(cloud.all_points[members])
        planes.append(cloud.plane_to_camera(plane))
        rmses.append(rmse * cloud.scale)
        supports.append(members.size)
        flat[cloud.all_pixels[members]] = len(planes)
    return Reconstruction(frame=frame, labels=flat.reshape(frame.shape),
                          planes=np.asarray(planes, dtype=np.float64).reshape(-1, 4),
                          rmse=np.asarray(rmses, dtype=np.float64),
                          support=np.asarray(supports, dtype=np.int64),
                          config={"baseline": "cgal", **asdict(cfg)},
                          timings={"baseline.call": call})


# Lets monoplane check --baseline-set options before the first frame.
cgal_efficient_ransac.config_class = CgalRansacConfig  # type: ignore[attr-defined]


@hookimpl
def monoplane_register_baselines() -> dict:
    """Register ``cgal`` with monoplane's evaluation and benchmark."""
    return {"cgal": cgal_efficient_ransac}
