"""External plane-detection baselines for ``monoplane eval`` and how they are found.

A *baseline* is a callable ``baseline(frame, *, seed=0) -> Reconstruction``: it receives the
same cue-filled :class:`~monoplane.types.Frame` (depth, normals, intrinsics; OpenCV camera axes)
the pipeline presets get and returns planes in the frame's camera frame and depth units.

Baselines are discovered the way stage plugins are, but through their own entry-point group
:data:`ENTRY_POINT_GROUP` (``monoplane.baselines``), where the entry-point name is the method
name users pass to ``--baseline``::

    [project.entry-points."monoplane.baselines"]
    cgal = "monoplane_cgal_baseline:cgal_efficient_ransac"

Built-in baselines sit in the host-side table :data:`BUILTIN_BASELINES` in the same
``"module:attribute"`` form, so both kinds load through one path. Entry points are not read
when ``MONOPLANE_DISABLE_PLUGIN_AUTOLOAD`` is set.

Built-in baseline
-----------------
``open3d-ransac``: Open3D's ``PointCloud.segment_plane`` applied sequentially. The cloud is the
frame's valid pixels normalised into the unit sphere exactly as the pipeline does it
(:class:`~monoplane.geometry.cloud.PlaneCloud`), so the paper's ε = 0.02 means the same thing
for both. Each round takes the best plane of the remaining points and removes its inliers,
until the best plane has fewer inliers than the pipeline's minimum plane size (0.6 % of the
valid pixels, the paper's 300 px at 256×192) or 20 planes were found (the pipeline's limit).
Each round runs at most 1000 iterations (the pipeline's limit too) with Open3D's own early
termination at its default confidence; every valid pixel is used (no subsampling). Normals
are not used (``segment_plane`` has no normal test) and there is no spatial coherence: that is
what the baseline stands for, plain sequential RANSAC from a widely used library.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import asdict, dataclass
from importlib import metadata

import numpy as np

from monoplane.errors import ConfigError, PluginError
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.planes import fit_plane
from monoplane.plugin_manager import autoload_enabled
from monoplane.types import Frame, Reconstruction

#: Entry-point group third-party baselines register in.
ENTRY_POINT_GROUP = "monoplane.baselines"

#: Baselines shipped with monoplane, as ``"module:attribute"`` references.
BUILTIN_BASELINES: dict[str, str] = {
    "open3d-ransac": "monoplane.evaluation.baselines:open3d_ransac",
}

#: Type of a baseline: a frame with cues in, planes out.
Baseline = Callable[..., Reconstruction]

@dataclass(frozen=True)
class Open3DRansacConfig:
    """Settings of the ``open3d-ransac`` baseline.

    Attributes
    ----------
    epsilon : float
        Inlier distance in unit-sphere units (paper: 0.02).
    num_iterations : int
        Maximum RANSAC iterations per plane.
    probability : float
        Confidence at which Open3D stops early (its default).
    max_planes : int
        Stop after this many planes (as the pipeline's ``ransac.max_planes``).
    min_support : float
        Stop when the best plane has fewer inliers than this fraction of the valid pixels (as
        the pipeline's ``ransac.min_support``: the paper's 300 px at 256×192).
    min_support_points : int
        ... and never accept a plane with fewer inliers than this.
    """

    epsilon: float = 0.02
    num_iterations: int = 1000
    probability: float = 0.99999999
    max_planes: int = 20
    min_support: float = 0.006
    min_support_points: int = 30


def open3d_ransac(frame: Frame, *, seed: int = 0,
                  config: Open3DRansacConfig | None = None) -> Reconstruction:
    """Sequential Open3D ``segment_plane`` on the frame's normalised point cloud.

    Parameters
    ----------
    frame : Frame
        Frame with ``depth`` (normals, when present, only decide which pixels are valid).
    seed : int
        Seed of Open3D's global random generator. Open3D 0.19 runs the RANSAC iterations in
        parallel threads with early termination, so two runs with the same seed can still
        differ slightly on hard frames.
    config : Open3DRansacConfig, optional
        Defaults as documented in the module docstring.

    Returns
    -------
    Reconstruction
        Labels 1..P in detection order; planes in the camera frame (OpenCV axes) and depth
        units; ``rmse`` in depth units; ``support`` = inlier count.
    """
    import open3d as o3d

    cfg = config or Open3DRansacConfig()
    cloud = PlaneCloud.from_frame(frame)
    min_support = max(3, cfg.min_support_points,
                      int(np.ceil(cfg.min_support * cloud.all_points.shape[0])))
    o3d.utility.random.seed(int(seed))
    remaining = np.arange(cloud.all_points.shape[0])
    flat = np.zeros(frame.height * frame.width, dtype=np.int32)
    planes: list[np.ndarray] = []
    rmses: list[float] = []
    supports: list[int] = []
    while len(planes) < cfg.max_planes and remaining.size >= min_support:
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.all_points[remaining]))
        _, inliers = pcd.segment_plane(distance_threshold=cfg.epsilon, ransac_n=3,
                                       num_iterations=cfg.num_iterations,
                                       probability=cfg.probability)
        if len(inliers) < min_support:
            break
        chosen = remaining[np.asarray(inliers, dtype=np.int64)]
        # Report the least-squares plane of the inliers (as every method's planes are), in
        # the camera frame; the labels stay Open3D's.
        plane, rmse = fit_plane(cloud.all_points[chosen])
        planes.append(cloud.plane_to_camera(plane))
        rmses.append(rmse * cloud.scale)
        supports.append(chosen.size)
        flat[cloud.all_pixels[chosen]] = len(planes)
        remaining = np.setdiff1d(remaining, chosen, assume_unique=True)
    return Reconstruction(frame=frame, labels=flat.reshape(frame.shape),
                          params=np.asarray(planes, dtype=np.float64).reshape(-1, 4),
                          rmse=np.asarray(rmses, dtype=np.float64),
                          support=np.asarray(supports, dtype=np.int64),
                          config={"baseline": "open3d-ransac", **asdict(cfg)})


def _load_reference(name: str, ref: str) -> Baseline:
    module, _, attr = ref.partition(":")
    try:
        obj = importlib.import_module(module)
        for part in attr.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise PluginError(f"baseline '{name}' ({ref}) cannot be loaded: {exc}") from exc
    if not callable(obj):
        raise PluginError(f"baseline '{name}' ({ref}) is not callable")
    return obj


def _entry_points() -> dict[str, metadata.EntryPoint]:
    if not autoload_enabled():
        return {}
    return {ep.name: ep for ep in metadata.entry_points(group=ENTRY_POINT_GROUP)}


def baseline_names() -> list[str]:
    """Names of every available baseline: built-ins, then installed plugins, sorted."""
    return sorted(set(BUILTIN_BASELINES) | set(_entry_points()))


def get_baseline(name: str) -> Baseline:
    """Load a baseline by name.

    Raises
    ------
    ConfigError
        When no baseline has that name (the message lists the valid ones).
    PluginError
        When a registered baseline fails to import.
    """
    if name in BUILTIN_BASELINES:
        return _load_reference(name, BUILTIN_BASELINES[name])
    eps = _entry_points()
    if name not in eps:
        raise ConfigError(f"unknown baseline '{name}'; valid choices: "
                          f"{', '.join(baseline_names())}")
    return _load_reference(name, eps[name].value)
