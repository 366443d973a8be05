"""Planes detected in a point cloud: :class:`CloudResult` (what ``detect_planes`` returns).

Conventions: see :mod:`monoplane.datamodel`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from monoplane.datamodel.planeset import PlaneSet, as_planes, deprecated_name
from monoplane.errors import InvalidInput


@dataclass(init=False)
class CloudResult(PlaneSet):
    """Planes detected in a point cloud.

    Attributes
    ----------
    points : numpy.ndarray
        (N, 3) float64 input points, input order (non-finite ones included).
    labels : numpy.ndarray
        (N,) int32 plane of each input point, 1..P, 0 = no plane (also for NaN/inf points).
    planes : numpy.ndarray
        (P, 4) float64 ``n · x + d = 0`` with unit ``n``, in the cloud's frame and units;
        ``n`` points to the side the points' normals face. ``ids`` are the label values 1..P.
    rmse : numpy.ndarray
        (P,) RMS point-to-plane distance of each plane's points, input units.
    support : numpy.ndarray
        (P,) int64 points per plane. Formerly ``num_points`` (still accepted, with a
        DeprecationWarning, until 0.3.0).
    centroids : numpy.ndarray
        (P, 3) mean of each plane's points.
    colors : numpy.ndarray or None
        (N, 3) input colours in [0, 1], if any.
    notes : list of str
        What was done to the input (dropped points, estimated normals...).
    config : dict
        The resolved configuration.
    timings : dict
        Seconds per step.
    source : str
        Where the points came from (a file name), when known; ``planes.json`` records it.
    """

    result_kind: ClassVar[str] = "cloud"

    points: np.ndarray
    labels: np.ndarray
    planes: np.ndarray
    rmse: np.ndarray
    support: np.ndarray
    centroids: np.ndarray
    colors: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    config: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    source: str = ""

    def __init__(self, points: np.ndarray, labels: np.ndarray, planes: np.ndarray,
                 rmse: np.ndarray, support: np.ndarray | None = None,
                 centroids: np.ndarray | None = None, colors: np.ndarray | None = None,
                 notes: list[str] | None = None, config: dict[str, Any] | None = None,
                 timings: dict[str, float] | None = None, source: str = "", *,
                 num_points: np.ndarray | None = None) -> None:
        if num_points is not None:  # the old name wins: dataclasses.replace passes both
            deprecated_name("CloudResult", "num_points", "support")
            support = num_points
        self.points = np.asarray(points, dtype=np.float64)
        self.labels = np.asarray(labels, dtype=np.int32)
        self.planes = as_planes(planes)
        p = self.planes.shape[0]
        self.rmse = np.asarray(rmse, dtype=np.float64).reshape(-1)
        self.support = (np.bincount(self.labels[self.labels > 0], minlength=p + 1)[1:]
                        if support is None else np.asarray(support)).astype(np.int64)
        self.centroids = (np.zeros((p, 3)) if centroids is None
                          else np.asarray(centroids, dtype=np.float64).reshape(-1, 3))
        if self.labels.shape != self.points.shape[:1]:
            raise InvalidInput(f"labels must have shape ({len(self.points)},), "
                               f"got {self.labels.shape}")
        if self.rmse.shape != (p,) or self.support.shape != (p,) or len(self.centroids) != p:
            raise InvalidInput(f"rmse, support and centroids must have {p} rows")
        self.colors = colors
        self.notes = [] if notes is None else notes
        self.config = {} if config is None else config
        self.timings = {} if timings is None else timings
        self.source = source

    @property
    def num_points(self) -> np.ndarray:
        """Deprecated name of :attr:`support`."""
        deprecated_name("CloudResult", "num_points", "support")
        return self.support
