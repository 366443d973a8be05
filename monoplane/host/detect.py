"""Planes of a point cloud: :func:`detect_planes` for Open3D clouds and (N, 3) arrays.

The cloud goes through the same stages as an image, without the pixel grid:

1. non-finite points are set aside (label 0) and exact duplicates collapsed, so neither can
   break the search or the normal estimation;
2. the unique points are normalised into the unit sphere (``ransac.epsilon`` keeps its
   meaning) and, for the search, subsampled to ``ransac.max_points``;
3. missing normals are estimated with Open3D (PCA over ``cloud.normals_knn`` neighbours) and
   oriented (``cloud.orient``, see :class:`CloudConfig`);
4. the sequential graph-cut RANSAC (:meth:`monoplane.algorithm.ransac.SequentialRansac.run_cloud`) runs
   on the subsample's kNN graph, then the configured refiner's :meth:`refine_cloud` (which
   must not need pixels; the ``cloud`` preset uses ``graph-crf``);
5. every input point is labelled: a point takes, among the planes of its few nearest sampled
   points, the one it is closest to, if its nearest sample is planar and near enough; planes
   are refit by least squares on all their points, in the cloud's own frame and units.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from monoplane.host.cloud_config import CloudConfig
from monoplane.errors import InvalidInput
from monoplane.geometry.cloud import PROPAGATION_RADIUS_FACTOR, PlaneCloud
from monoplane.geometry.graph import NeighbourGraph
from monoplane.geometry.neighbours import PointIndex
from monoplane.geometry.orientation import orient_normals
from monoplane.geometry.planes import fit_planes_per_label
from monoplane.geometry.polygons import PlaneMesh, points_plane_mesh
from monoplane.io.checks import MAX_MAGNITUDE
from monoplane.palette import NON_PLANAR, plane_palette


@dataclass
class CloudPlaneResult:
    """Planes detected in a point cloud.

    Attributes
    ----------
    points : numpy.ndarray
        (N, 3) float64 input points, input order (non-finite ones included).
    labels : numpy.ndarray
        (N,) int32 plane of each input point, 1..P, 0 = no plane (also for NaN/inf points).
    planes : numpy.ndarray
        (P, 4) float64 ``n · x + d = 0`` with unit ``n``, in the cloud's frame and units;
        ``n`` points to the side the points' normals face.
    rmse : numpy.ndarray
        (P,) RMS point-to-plane distance of each plane's points, input units.
    num_points : numpy.ndarray
        (P,) int64 points per plane.
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
    """

    points: np.ndarray
    labels: np.ndarray
    planes: np.ndarray
    rmse: np.ndarray
    num_points: np.ndarray
    centroids: np.ndarray
    colors: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)
    config: dict[str, Any] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)

    @property
    def num_planes(self) -> int:
        """Number P of planes."""
        return int(self.planes.shape[0])

    def plane_colors(self) -> np.ndarray:
        """(P + 1, 3) float colours in [0, 1]: row 0 (no plane) grey, then one per plane."""
        lut = np.vstack([NON_PLANAR[None], plane_palette(self.num_planes)])
        return lut.astype(np.float64) / 255.0

    def to_open3d(self):  # -> open3d.geometry.PointCloud
        """The finite input points as an Open3D cloud coloured by plane (grey: no plane)."""
        import open3d as o3d

        finite = np.isfinite(self.points).all(axis=1)
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(self.points[finite]))
        pcd.colors = o3d.utility.Vector3dVector(self.plane_colors()[self.labels[finite]])
        return pcd

    def plane_mesh(self, cell: float | None = None) -> PlaneMesh:
        """Every plane's area as triangles on the plane, holes left open, faces tagged by plane.

        Each plane's points are projected onto it, rasterised on a grid of ``cell`` (default:
        twice the median point spacing) and outlined with their holes
        (:func:`monoplane.geometry.polygons.points_plane_mesh`).

        Returns
        -------
        PlaneMesh
            Vertices in the cloud's frame and units; ``plane_ids`` 1..P.
        """
        finite = np.isfinite(self.points).all(axis=1)
        if cell is None:
            pts = self.points[finite & (self.labels > 0)]
            if len(pts) >= 2:
                d, _ = PointIndex(pts).query(pts[:: max(1, len(pts) // 2000)], k=2)
                cell = 2.0 * float(np.median(d[:, 1]))
            cell = cell if cell and cell > 0 else 1.0
        parts = []
        for pid in range(1, self.num_planes + 1):
            verts, tris = points_plane_mesh(self.points[self.labels == pid],
                                            self.planes[pid - 1], cell)
            parts.append((pid, verts, tris))
        return PlaneMesh.concatenate(parts)

    def plane_meshes(self, cell: float | None = None) -> list:
        """One Open3D triangle mesh per plane (see :meth:`plane_mesh`), coloured by plane.

        Returns
        -------
        list of open3d.geometry.TriangleMesh
            Index ``i`` is plane ``i + 1``; an empty mesh when a plane has no outline.
        """
        import open3d as o3d

        mesh = self.plane_mesh(cell)
        colors = self.plane_colors()
        meshes = []
        for pid in range(1, self.num_planes + 1):
            tris = mesh.triangles[mesh.plane_ids == pid]
            used, inverse = np.unique(tris, return_inverse=True)
            part = o3d.geometry.TriangleMesh()
            if len(used):
                part.vertices = o3d.utility.Vector3dVector(mesh.vertices[used])
                part.triangles = o3d.utility.Vector3iVector(
                    inverse.reshape(-1, 3).astype(np.int32))
                part.paint_uniform_color(colors[pid])
                part.compute_vertex_normals()
            meshes.append(part)
        return meshes

    def planes_document(self) -> dict[str, Any]:
        """JSON-ready description: one entry per plane (normal, offset, num_points, rmse)."""
        return {
            "num_points": int(self.points.shape[0]),
            "num_planes": self.num_planes,
            "planes": [
                {"id": i + 1, "normal": self.planes[i, :3].tolist(),
                 "offset": float(self.planes[i, 3]), "num_points": int(self.num_points[i]),
                 "rmse": float(self.rmse[i]), "centroid": self.centroids[i].tolist()}
                for i in range(self.num_planes)
            ],
            "notes": list(self.notes),
            "config": self.config,
        }


def _as_arrays(cloud: Any) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(N, 3) points, optional normals and colours of any supported cloud type."""
    import open3d as o3d

    normals = colors = None
    if isinstance(cloud, o3d.geometry.PointCloud):
        points = np.asarray(cloud.points, dtype=np.float64)
        if cloud.has_normals():
            normals = np.asarray(cloud.normals, dtype=np.float64)
        if cloud.has_colors():
            colors = np.asarray(cloud.colors, dtype=np.float64)
    elif isinstance(cloud, o3d.t.geometry.PointCloud):
        if "positions" not in cloud.point:
            raise InvalidInput("the tensor point cloud has no 'positions' attribute")
        points = cloud.point.positions.numpy().astype(np.float64)
        if "normals" in cloud.point:
            normals = cloud.point.normals.numpy().astype(np.float64)
        if "colors" in cloud.point:
            colors = cloud.point.colors.numpy().astype(np.float64)
            if colors.size and colors.max() > 1.0:  # 8-bit colours
                colors = colors / 255.0
    else:
        try:
            points = np.asarray(cloud, dtype=np.float64)
        except (TypeError, ValueError):
            raise InvalidInput(
                f"cloud must be an open3d PointCloud (legacy or tensor) or an (N, 3) array, "
                f"got {type(cloud).__name__}") from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise InvalidInput(f"points must have shape (N, 3), got {points.shape}")
    return points, normals, colors


def _estimate_normals(points: np.ndarray, cfg: CloudConfig) -> np.ndarray:
    """Unit normals of ``points`` by Open3D PCA, oriented as ``cfg.orient`` says."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    k = min(cfg.normals_knn, len(points))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=k))
    if cfg.orient == "consistent" and len(points) > 3:
        pcd.orient_normals_consistent_tangent_plane(min(15, len(points) - 1))
        return np.asarray(pcd.normals, dtype=np.float64)
    normals = np.asarray(pcd.normals, dtype=np.float64)
    if cfg.orient == "auto":
        return orient_normals(points, normals, np.asarray(cfg.viewpoint, dtype=np.float64))
    towards = np.asarray(cfg.viewpoint, dtype=np.float64) - points
    return np.where(((normals * towards).sum(axis=1) < 0)[:, None], -normals, normals)


def _propagate(cloud: PlaneCloud, points: np.ndarray, sample: np.ndarray, labels: np.ndarray,
               planes: np.ndarray, spacing: float) -> np.ndarray:
    """Labels of all (normalised) ``points`` from the labelled ``sample`` of them that
    ``cloud`` holds (see the module docstring and :meth:`PlaneCloud.label_points`)."""
    if sample.size == points.shape[0]:
        out = np.zeros(points.shape[0], dtype=np.int32)
        out[sample] = labels
        return out
    out = cloud.label_points(points, labels, planes,
                             PROPAGATION_RADIUS_FACTOR * max(spacing, 1e-12))
    out[sample] = labels
    return out


def detect_planes(cloud: Any, preset: str = "cloud",
                  overrides: dict[str, Any] | list[str] | None = None,
                  pm: Any | None = None) -> CloudPlaneResult:
    """Detect planes in a point cloud with MonoPlane's graph-cut RANSAC.

    Parameters
    ----------
    cloud : open3d.geometry.PointCloud, open3d.t.geometry.PointCloud or array_like
        (N, 3) points in any frame and unit; normals and colours (in [0, 1], or 8-bit for
        tensor clouds) are used when present. Without normals they are estimated (see
        :class:`CloudConfig`); without colours the colour term is dropped.
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
    import time

    from monoplane.host import config as config_mod
    from monoplane.host.pipeline import Pipeline

    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    pipe = Pipeline.from_preset(preset, overrides=overrides, pm=pm)
    pipe.cloud_refiner()  # a refiner that needs pixels fails before any work
    cfg: CloudConfig = pipe.config.host["cloud"]
    rcfg = pipe.config.host["ransac"]
    points, normals, colors = _as_arrays(cloud)
    n_in = points.shape[0]
    notes: list[str] = []
    for what, arr in (("normals", normals), ("colors", colors)):
        if arr is not None and arr.shape != points.shape:
            raise InvalidInput(f"{what} must have shape {points.shape}, got {arr.shape}")
    finite = np.isfinite(points).all(axis=1)
    huge = finite & (np.abs(points) > MAX_MAGNITUDE).any(axis=1)
    if huge.any():
        first = int(np.argmax(huge))
        raise InvalidInput(f"{int(huge.sum())} point(s) have coordinates beyond "
                           f"±{MAX_MAGNITUDE:.3g} (the first is point {first})")
    if normals is not None:
        # Judged by the largest component: squaring one near 1e300 would overflow.
        size = np.abs(normals).max(axis=1)
        ok_n = np.isfinite(normals).all(axis=1) & (size > 1e-12) & (size <= MAX_MAGNITUDE)
        if not ok_n[finite].all():
            notes.append("some given normals are zero, non-finite or absurdly long: all "
                         "normals re-estimated")
            normals = None
    if colors is not None and not ((colors[finite] >= 0) & (colors[finite] <= 1)).all():
        notes.append("colours outside [0, 1] or not finite: colour term dropped")
        colors = None
    if not finite.all():
        notes.append(f"{int((~finite).sum())} NaN/inf points left unlabelled")
    finite_idx = np.flatnonzero(finite)
    unique, first, inverse = np.unique(points[finite_idx], axis=0, return_index=True,
                                       return_inverse=True)
    inverse = inverse.ravel()
    if len(unique) < 3:
        raise InvalidInput(f"the cloud has {len(unique)} distinct finite point(s); a plane "
                           "needs at least 3")
    if len(unique) < len(finite_idx):
        notes.append(f"{len(finite_idx) - len(unique)} duplicate points share their twin's label")
    u_normals = normals[finite_idx[first]] if normals is not None else None
    u_colors = colors[finite_idx[first]] if colors is not None else None

    center = unique.mean(axis=0)
    extent = float(np.abs(unique - center).max())
    # Points closer together than float64 resolves at their magnitude, or so close that their
    # squared distances underflow, cannot be put into the unit sphere.
    if not extent > max(1e-150, 1e-12 * float(np.abs(center).max())):
        raise InvalidInput(f"the cloud's {len(unique)} distinct points lie within {extent:.3g} "
                           f"of their centre {center.tolist()}: too close together to fit "
                           "planes to")
    scale = float(np.sqrt(((unique - center) ** 2).sum(axis=1).max()))
    norm_pts = (unique - center) / scale
    rng = np.random.default_rng(rcfg.seed)
    sample = np.arange(len(unique))
    if len(unique) > rcfg.max_points:
        sample = np.sort(rng.choice(len(unique), size=rcfg.max_points, replace=False))
        notes.append(f"search on {rcfg.max_points} of {len(unique)} points; all labelled")
    timings["prepare"] = time.perf_counter() - t0

    t = time.perf_counter()
    if u_normals is None:
        s_normals = _estimate_normals(unique[sample], cfg)
        notes.append(f"normals estimated (PCA, {cfg.normals_knn} neighbours, "
                     f"oriented: {cfg.orient})")
    else:
        s_normals = u_normals[sample] / np.linalg.norm(u_normals[sample], axis=1, keepdims=True)
    timings["normals"] = time.perf_counter() - t

    pc = PlaneCloud.from_points(norm_pts[sample], s_normals,
                                None if u_colors is None else u_colors[sample], center, scale)
    t = time.perf_counter()
    graph = NeighbourGraph.build(pc.points, rcfg.knn, tree=pc.tree)
    timings["graph"] = time.perf_counter() - t
    # The RANSAC stages and the refiner, with the pipeline's hooks and error wrapping; they
    # add their seconds to timings["ransac"] and timings["refiner"].
    labels, planes = pipe.segment_cloud(pc, graph, rng, "cloud", timings,
                                        own_normals=u_normals is not None)

    t = time.perf_counter()
    u_labels = _propagate(pc, norm_pts, sample, np.asarray(labels, dtype=np.int32),
                          np.asarray(planes, dtype=np.float64).reshape(-1, 4), graph.spacing)
    num = int(u_labels.max(initial=0))
    params, rmse, support = fit_planes_per_label(unique, u_labels, num)
    kept = ~np.isnan(rmse)
    renumber = np.zeros(num + 1, dtype=np.int32)
    renumber[1:][kept] = np.arange(1, int(kept.sum()) + 1)
    u_labels = renumber[u_labels]
    params, rmse, support = params[kept], rmse[kept], support[kept]
    p = params.shape[0]
    centroids = np.zeros((p, 3))
    mean_normal = np.zeros((p, 3))
    if p:
        np.add.at(centroids, u_labels[u_labels > 0] - 1, unique[u_labels > 0])
        centroids /= support[:, None]
        all_normals = None
        if u_normals is not None:
            all_normals = u_normals
        elif sample.size == len(unique):
            all_normals = np.empty_like(unique)
            all_normals[sample] = s_normals
        if all_normals is not None:
            np.add.at(mean_normal, u_labels[u_labels > 0] - 1, all_normals[u_labels > 0])
        else:
            lab_s = u_labels[sample]
            np.add.at(mean_normal, lab_s[lab_s > 0] - 1, s_normals[lab_s > 0])
        flip = (mean_normal * params[:, :3]).sum(axis=1) < 0
        params[flip] *= -1
    out = np.zeros(n_in, dtype=np.int32)
    out[finite_idx] = u_labels[inverse]
    timings["finalize"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0
    return CloudPlaneResult(points=points, labels=out, planes=params.reshape(-1, 4),
                            rmse=rmse, num_points=support, centroids=centroids,
                            colors=colors, notes=notes,
                            config=config_mod.ResolvedConfig.to_dict(pipe.config),
                            timings=timings)
