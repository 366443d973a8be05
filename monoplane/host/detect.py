"""Planes of a point cloud: :func:`detect_planes` for Open3D clouds and (N, 3) arrays.

The cloud goes through the same pipeline as an image, without the pixel grid
(:meth:`monoplane.host.pipeline.Pipeline.run_cloud`): its distinct finite points are
normalised into the unit sphere and subsampled to ``ransac.max_points``, missing normals are
estimated and oriented (``[cloud]``, :class:`~monoplane.host.cloud_config.CloudConfig`;
:mod:`monoplane.host.cloud_input`), the sequential RANSAC, the refiner's ``refine_cloud``
(which must not need pixels; the ``cloud`` preset uses ``graph-crf``) and the planarity test
run on the subsample's kNN graph, and every input point is labelled: a point takes, among the
planes of its few nearest sampled points, the one it is closest to, if its nearest sample is
planar and near enough. Planes are refit by least squares on all their points, in the cloud's
own frame and units.
"""

from __future__ import annotations

from typing import Any

from monoplane.host.cloud_result import CloudPlaneResult
from monoplane.host.pipeline import Pipeline


def detect_planes(cloud: Any, preset: str = "cloud",
                  overrides: dict[str, Any] | list[str] | None = None,
                  pm: Any | None = None) -> CloudPlaneResult:
    """Detect planes in a point cloud with MonoPlane's graph-cut RANSAC.

    Parameters
    ----------
    cloud : open3d.geometry.PointCloud, open3d.t.geometry.PointCloud or array_like
        (N, 3) points in any frame and unit; normals and colours (in [0, 1], or 8-bit for
        tensor clouds) are used when present. Without normals they are estimated (see
        :class:`~monoplane.host.cloud_config.CloudConfig`); without colours the colour term
        is dropped.
    preset : str
        Config preset (default ``cloud``); its refiner must work without pixels.
    overrides : dict or list of str, optional
        ``table.key`` overrides, e.g. ``{"ransac.epsilon": 0.01, "cloud.orient": "consistent"}``.
    pm : pluggy.PluginManager, optional
        Plugin manager providing the stages.

    Returns
    -------
    CloudPlaneResult
        Labels in the input order, planes in the cloud's frame and units, statistics.

    Raises
    ------
    InvalidInput
        Fewer than 3 distinct finite points, or a malformed cloud.
    ConfigError
        Bad overrides, or a refiner that needs pixels (e.g. ``dense-crf``).
    """
    pipe = Pipeline.from_preset(preset, overrides=overrides, pm=pm)
    # the deprecated subclass keeps the former methods working until 0.3.0
    return CloudPlaneResult(**vars(pipe.run_cloud(cloud)))
