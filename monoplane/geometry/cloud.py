"""The oriented, coloured point cloud that plane RANSAC works on (paper §III-A).

A :class:`PlaneCloud` is a frame's valid pixels unprojected into the camera frame (OpenCV axes:
x right, y down, z forward) and then normalised "roughly into a unit sphere" so that the RANSAC
thresholds (ε = 0.02, α_p² = 0.005, ...) mean the same thing whatever the depth's scale or unit:

    X_norm = (X_cam - center) / scale

``center`` is the centroid of the valid points and ``scale`` the largest distance of a valid
point from it, so every point lies in the closed unit ball.

Subsampling
-----------
At high resolution RANSAC runs on a random subset of at most ``max_points`` valid pixels (drawn
from the caller's generator, so it is deterministic for a seed), or on the valid pixels of a
regular lattice (``grid``; :func:`lattice_stride`, or :func:`lattice_step` for a step that
need not be whole), whose neighbours the lattice itself gives
(:meth:`NeighbourGraph.from_lattice`). :meth:`PlaneCloud.propagate`
then carries the labels of the subset to every valid pixel. A pixel first takes the label of
its nearest sampled pixel in the image (a distance transform). Where that is doubtful (the
pixel is not close to the sample's plane) it is decided in 3D instead: non-planar if its
nearest 3D sample is non-planar, else the closest plane among its few nearest samples'
planes. The 3D candidates are the sample and its neighbours in the graph (the pixel is
next to the sample, so its nearest samples are the sample's); only pixels farther in 3D from
their image-nearest sample than a radius tied to the sampling density (across a depth jump)
query the point index, and are non-planar when no sample lies within the radius.
Neighbour transfer keeps region extents where the graph cut put them (a plain per-plane
distance test would re-open holes that the proximity terms had closed), choosing by plane
distance keeps creases sharp, and the 3D radius stops labels leaking across depth jumps.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, partial

import numpy as np

from monoplane.datamodel import Frame
from monoplane.errors import InvalidInput
from monoplane.geometry.distance_transform import nearest_true_pixel
from monoplane.geometry.graph import NeighbourGraph
from monoplane.geometry.lattice import lattice_lines, lattice_step, lattice_stride
from monoplane.geometry.neighbours import PointIndex
from monoplane.geometry.propagation import (
    TILE,
    SampleImage,
    closest_plane,
    mixed_samples,
    propagate_pixels,
    sample_tiles,
)
from monoplane.geometry.unprojection import (
    drawn_rows,
    gather_samples,
    lattice_rows,
    valid_points,
)
from monoplane.jit import chunks, run_threaded

#: A non-sampled pixel inherits its nearest sample's label only within this many times the
#: median sample-to-nearest-sample spacing.
PROPAGATION_RADIUS_FACTOR = 4.0
#: Nearest samples whose planes compete for a non-sampled pixel (see :meth:`propagate`).
PROPAGATION_NEIGHBOURS = 4
#: Neighbours per sample of the graph :meth:`PlaneCloud.propagate` builds when given none.
PROPAGATION_GRAPH_K = 8
#: Query points labelled at a time by :meth:`PlaneCloud.label_points`.
_LABEL_CHUNK = 200_000
#: Pixels per thread below which propagation runs on one thread.
THREADED_PIXELS = 16_384


@dataclass
class PlaneCloud:
    """Oriented point cloud of one frame, or of a point cloud, normalised into the unit sphere.

    A frame's cloud (:meth:`from_frame`) knows the pixel of each point; a point cloud's
    (:meth:`from_points`) has no image, and its pixel attributes are ``None``: the RANSAC's
    :meth:`~monoplane.algorithm.ransac.SequentialRansac.run_cloud`, a refiner's ``refine_cloud`` and
    :meth:`label_points` need none, the methods on the pixel grid (:meth:`propagate`,
    :meth:`image_nearest_sample`, :meth:`pixel_grid`) refuse such a cloud.

    Attributes
    ----------
    points : numpy.ndarray
        (N, 3) float64 normalised points ``(X_cam - center) / scale`` (camera axes, unitless).
    normals : numpy.ndarray
        (N, 3) float64 unit normals in the camera frame (normalisation does not rotate them),
        facing the camera.
    colors : numpy.ndarray or None
        (N, 3) float64 RGB in [0, 1]; ``None`` when the frame has no colour (depth-only or grey
        input), in which case colour terms are dropped.
    pixels : numpy.ndarray or None
        (N,) int64 flat pixel index ``v * W + u`` of each point; None without an image.
    center : numpy.ndarray
        (3,) float64 camera-frame centre subtracted before scaling, in depth units.
    scale : float
        Depth units per normalised unit.
    shape : tuple of int or None
        ``(H, W)`` of the frame; None without an image.
    all_points : numpy.ndarray
        (V, 3) float64 normalised points of *every* valid pixel (equal to ``points`` when no
        subsampling happened; ``points`` without an image).
    all_pixels : numpy.ndarray or None
        (V,) int64 flat pixel index of every valid pixel, ascending; None without an image.
    sampled : numpy.ndarray or None
        (N,) int64 row of ``all_points`` of each point of a subsampled cloud without an image
        (a frame's cloud says it with ``pixels``); None otherwise.
    stride : int or None
        Whole step in pixels of the regular lattice a frame's points were sampled on
        (:meth:`from_frame` with ``grid``; 1: every valid pixel); None for a fractional step,
        a random sample or a cloud without an image.
    lattice : numpy.ndarray or None
        (R, C) int64 point of each node of the regular lattice a frame's points were sampled
        on (:meth:`from_frame` with ``grid``), -1 where the lattice pixel is not valid; None
        for a random sample or a cloud without an image.
    intrinsics : numpy.ndarray or None
        (3, 3) float64 intrinsics the frame's points were unprojected with
        (:meth:`from_frame`); the kNN graph (:meth:`neighbour_graph`) and :meth:`propagate`
        then find the samples near a point in 3D through the image. None otherwise (a point
        index serves instead).
    normals_from_sensor_depth : bool
        :attr:`monoplane.datamodel.Frame.normals_from_sensor_depth` of the frame: its normals
        were estimated from its own metric depth, not predicted by a network. False for
        normals given with the input, a network's normals, normals from a network's or a
        relative depth, and a cloud without a frame. The proximity labeler's normal gate
        reads it.
    """

    points: np.ndarray
    normals: np.ndarray
    colors: np.ndarray | None
    pixels: np.ndarray | None
    center: np.ndarray
    scale: float
    shape: tuple[int, int] | None
    all_points: np.ndarray
    all_pixels: np.ndarray | None
    sampled: np.ndarray | None = None
    stride: int | None = None
    lattice: np.ndarray | None = None
    intrinsics: np.ndarray | None = None
    normals_from_sensor_depth: bool = False

    def __post_init__(self) -> None:
        n = self.points.shape[0]
        if self.points.shape != (n, 3) or self.normals.shape != (n, 3):
            raise InvalidInput("points and normals must both have shape (N, 3)")
        if self.colors is not None and self.colors.shape != (n, 3):
            raise InvalidInput("colors must have shape (N, 3)")
        grid = (self.pixels, self.shape, self.all_pixels)
        if any(g is None for g in grid) and any(g is not None for g in grid):
            raise InvalidInput("pixels, shape and all_pixels must be all given or all None")
        if self.pixels is not None and self.pixels.shape != (n,):
            raise InvalidInput("pixels must have shape (N,)")
        if self.sampled is not None and self.sampled.shape != (n,):
            raise InvalidInput("sampled must have shape (N,)")
        if not self.scale > 0:
            raise InvalidInput(f"scale must be positive, got {self.scale}")

    @property
    def size(self) -> int:
        """Number N of points RANSAC works on."""
        return int(self.points.shape[0])

    @cached_property
    def tree(self) -> PointIndex:
        """Nearest-neighbour index over ``points`` (built on first use)."""
        return PointIndex(self.points)

    @property
    def sample_image(self) -> SampleImage | None:
        """Where the points lie in the frame's image, for searches in 3D through the image
        (the kNN graph, :meth:`propagate`); None for a cloud without an image or with
        intrinsics other than a pinhole camera's."""
        if (self.pixels is None or self.shape is None or self.intrinsics is None
                or not np.array_equal(self.intrinsics[2], [0.0, 0.0, 1.0])):
            return None
        return SampleImage(self.pixels, self.shape, self.intrinsics, self.center, self.scale)

    def neighbour_graph(self, k: int) -> NeighbourGraph:
        """The kNN graph over ``points`` (:meth:`NeighbourGraph.build`), found through the
        image when the cloud has one (:attr:`sample_image`), else with :attr:`tree`. The few
        samples the image search leaves go to :attr:`tree` too, built then and kept for its
        later users (the pixels :meth:`label_points` misses, NAPSAC sampling)."""
        image = self.sample_image
        return NeighbourGraph.build(self.points, k, tree=(lambda: self.tree) if image
                                    else self.tree, image=image)

    @cached_property
    def image_nearest_sample(self) -> np.ndarray:
        """(M,) int64 index into ``points`` of the sample nearest in the image to each of the
        ``all_pixels`` (exact Euclidean distance in pixels).

        It depends on the sampling only, not on labels, so RANSAC computes it while the
        neighbour graph is being built; :meth:`propagate` starts from it.
        """
        pixels, (h, w), all_pixels = self.pixel_grid()
        sampled = np.zeros((h, w), dtype=bool)
        sampled.ravel()[pixels] = True
        sample_of = np.full(h * w, -1, dtype=np.int64)
        sample_of[pixels] = np.arange(self.size)
        return sample_of[nearest_true_pixel(sampled)[all_pixels]]

    def pixel_grid(self) -> tuple[np.ndarray, tuple[int, int], np.ndarray]:
        """``(pixels, shape, all_pixels)`` of a frame's cloud (see the attributes).

        Raises
        ------
        InvalidInput
            For a cloud without an image (:meth:`from_points`).
        """
        if self.pixels is None or self.shape is None or self.all_pixels is None:
            raise InvalidInput("this point cloud has no image: no pixel grid to work on")
        return self.pixels, self.shape, self.all_pixels

    @property
    def subsampled(self) -> bool:
        """True when RANSAC works on a subset of the valid pixels."""
        return self.points.shape[0] != self.all_points.shape[0]

    @classmethod
    def from_frame(cls, frame: Frame, max_points: int | None = None,
                   rng: np.random.Generator | None = None, grid: bool = False,
                   fractional: bool = False) -> PlaneCloud:
        """Unproject a frame's valid pixels into a normalised oriented cloud.

        Parameters
        ----------
        frame : Frame
            Needs ``depth`` and ``normals`` (camera frame, facing the camera); ``rgb`` is
            optional and ignored when grey.
        max_points : int, optional
            Keep at most this many points, drawn uniformly without replacement; ``None`` or
            a value >= the number of valid pixels keeps all of them.
        rng : numpy.random.Generator, optional
            Source of the subsampling; required when random subsampling happens.
        grid : bool
            Subsample on a regular lattice instead: the valid pixels of the rows and columns
            ``⌊(i + ½) s⌋`` (:func:`lattice_lines`; for a whole ``s``, ``v, u ≡ s // 2
            (mod s)``) for the smallest whole step ``s`` that keeps at most ``max_points`` of
            them (:func:`lattice_stride`); ``stride`` records ``s`` and ``lattice`` which
            point each lattice node holds. Draws nothing from ``rng``.
        fractional : bool
            With ``grid``: the smallest step that need not be whole (:func:`lattice_step`),
            so that the lattice holds about ``max_points`` points at any resolution;
            ``stride`` is then None.

        Returns
        -------
        PlaneCloud
            Points ordered by ascending pixel index.

        Raises
        ------
        InvalidInput
            When the frame lacks depth or normals or has fewer than 3 valid pixels.
        """
        if frame.depth is None or frame.normals is None:
            raise InvalidInput(
                f"{frame.name}: plane fitting needs depth and normals; run a cue provider first"
            )
        valid_image, all_pixels, all_points, center, scale = valid_points(
            np.ascontiguousarray(frame.depth, dtype=np.float32),
            np.ascontiguousarray(frame.normals, dtype=np.float32),
            np.linalg.inv(np.asarray(frame.K, dtype=np.float64)))
        if all_pixels.size < 3:
            raise InvalidInput(f"{frame.name}: fewer than 3 valid pixels")
        if scale <= 0:
            raise InvalidInput(f"{frame.name}: all valid pixels unproject to the same point")

        chosen = None  # rows of the valid pixels kept (None: all)
        stride = lattice = None
        if grid:
            step, stride = 1.0, 1
            if max_points is not None and all_pixels.size > max_points:
                if fractional:
                    step, stride = lattice_step(valid_image, max_points), None
                else:
                    stride = lattice_stride(valid_image, max_points)
                    step = float(stride)
            chosen, lattice = lattice_rows(valid_image, lattice_lines(frame.shape[0], step),
                                           lattice_lines(frame.shape[1], step))
        elif max_points is not None and all_pixels.size > max_points:
            if max_points < 3:
                raise InvalidInput(f"max_points must be at least 3, got {max_points}")
            if rng is None:
                raise InvalidInput("subsampling a cloud needs a random generator")
            chosen = drawn_rows(all_pixels.size,
                                rng.choice(all_pixels.size, size=max_points, replace=False))
        keep, points, normals = gather_samples(
            np.arange(all_pixels.size) if chosen is None else chosen, all_pixels, all_points,
            np.ascontiguousarray(frame.normals, dtype=np.float32).reshape(-1, 3))
        if chosen is None:  # every valid pixel: the points are the same array
            keep, points = all_pixels, all_points
        colors = None
        if frame.has_color and frame.rgb is not None:
            colors = frame.rgb.reshape(-1, 3)[keep].astype(np.float64) / 255.0
        return cls(points=points, normals=normals, colors=colors,
                   pixels=keep, center=center, scale=scale, shape=frame.shape,
                   all_points=all_points, all_pixels=all_pixels, stride=stride,
                   lattice=lattice, intrinsics=np.asarray(frame.K, dtype=np.float64),
                   normals_from_sensor_depth=frame.normals_from_sensor_depth)

    @classmethod
    def from_points(cls, points: np.ndarray, normals: np.ndarray, colors: np.ndarray | None,
                    center: np.ndarray, scale: float, all_points: np.ndarray | None = None,
                    sampled: np.ndarray | None = None) -> PlaneCloud:
        """A cloud without an image, from points already normalised into the unit sphere
        (:func:`normalised_cloud`).

        Parameters
        ----------
        points : numpy.ndarray
            (N, 3) normalised points ``(X - center) / scale``.
        normals : numpy.ndarray
            (N, 3) unit normals, oriented.
        colors : numpy.ndarray or None
            (N, 3) RGB in [0, 1], or None.
        center : numpy.ndarray
            (3,) centre subtracted before scaling, in the input's frame and units.
        scale : float
            Input units per normalised unit.
        all_points, sampled : numpy.ndarray, optional
            When ``points`` are a subsample: the (V, 3) normalised points they were drawn
            from and the (N,) int64 row of each point among them; :meth:`propagate` labels
            them all.
        """
        points = np.ascontiguousarray(points, dtype=np.float64)
        if (all_points is None) != (sampled is None):
            raise InvalidInput("all_points and sampled must be given together")
        return cls(points=points, normals=normals, colors=colors, pixels=None, center=center,
                   scale=scale, shape=None,
                   all_points=points if all_points is None else all_points, all_pixels=None,
                   sampled=sampled)

    def plane_to_camera(self, planes: np.ndarray) -> np.ndarray:
        """Express normalised-frame planes in the camera frame and depth units.

        ``n · X_norm + d = 0`` with ``X_norm = (X_cam - c) / s`` gives
        ``n · X_cam + (s d - n · c) = 0``.

        Parameters
        ----------
        planes : numpy.ndarray
            (P, 4) or (4,) unit-normal planes in the normalised frame.

        Returns
        -------
        numpy.ndarray
            Same shape, unit normals, camera frame, not re-oriented.
        """
        p = np.array(planes, dtype=np.float64)
        out = p.copy()
        out[..., 3] = self.scale * p[..., 3] - p[..., :3] @ self.center
        return out

    def plane_to_normalised(self, planes: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`plane_to_camera`: ``d_norm = (d + n · c) / s``.

        Parameters
        ----------
        planes : numpy.ndarray
            (P, 4) or (4,) unit-normal camera-frame planes in depth units.

        Returns
        -------
        numpy.ndarray
            Same shape, planes in the normalised frame.
        """
        p = np.array(planes, dtype=np.float64)
        out = p.copy()
        out[..., 3] = (p[..., 3] + p[..., :3] @ self.center) / self.scale
        return out

    def propagate(self, labels: np.ndarray, planes: np.ndarray | None = None,
                  spacing: float | None = None, tolerance: float = 0.0,
                  graph: NeighbourGraph | None = None) -> np.ndarray:
        """Carry per-point labels of the (possibly subsampled) cloud to the full image, or to
        all the points of a cloud without an image.

        Parameters
        ----------
        labels : numpy.ndarray
            (N,) integer labels of ``points`` (0 = non-planar, ``i`` = ``planes[i - 1]``).
        planes : numpy.ndarray, optional
            (P, 4) planes of the labels in the normalised frame. When given, a pixel whose
            nearest sample is planar but which lies farther than ``tolerance`` from that
            sample's plane takes, among the planar labels of its
            :data:`PROPAGATION_NEIGHBOURS` nearest samples, the plane it is closest to; this
            keeps creases between planes sharp instead of following the sampling pattern.
        spacing : float, optional
            Median distance from a point to its nearest other point, if known already
            (default: ``graph.spacing``).
        tolerance : float
            Distance to its nearest sample's plane (normalised units) below which a pixel
            keeps that label without comparing planes.
        graph : NeighbourGraph, optional
            The kNN graph over ``points`` (built here with :data:`PROPAGATION_GRAPH_K`
            neighbours when omitted and needed).

        Returns
        -------
        numpy.ndarray
            (H, W) int32 label image; invalid pixels are 0. See the module docstring for the
            nearest-sample rule used on pixels that were not sampled. For a cloud without an
            image, (V,) int32 labels of ``all_points`` (:meth:`label_points` for those left
            out of the sample, within the radius; ``tolerance`` does not apply).
        """
        labels = np.ascontiguousarray(labels, dtype=np.int32)
        if self.pixels is None:
            return self._propagate_points(labels, planes, spacing, graph)
        return self.propagate_pixels(labels, planes, spacing, tolerance, graph)[0]

    def propagate_pixels(self, labels: np.ndarray, planes: np.ndarray | None = None,
                         spacing: float | None = None, tolerance: float = 0.0,
                         graph: NeighbourGraph | None = None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`propagate` on a frame's cloud, with the labels of every valid pixel too.

        Parameters
        ----------
        labels, planes, spacing, tolerance, graph
            As for :meth:`propagate`.

        Returns
        -------
        image : numpy.ndarray
            (H, W) int32 label image, as :meth:`propagate` returns it.
        valid : numpy.ndarray
            (V,) int32 label of each of ``all_pixels`` (``image.ravel()[all_pixels]``).
        """
        labels = np.ascontiguousarray(labels, dtype=np.int32)
        pixels, (h, w), all_pixels = self.pixel_grid()
        out = np.zeros(h * w, dtype=np.int32)
        if not self.subsampled:
            out[pixels] = labels
            return out.reshape(h, w), labels.copy()
        if graph is None:
            graph = self.neighbour_graph(PROPAGATION_GRAPH_K)
        radius = PROPAGATION_RADIUS_FACTOR * (graph.spacing if spacing is None else spacing)
        # Nearest sample in the image first (a distance transform, far cheaper than a 3D query
        # for every pixel); pixels where that choice is doubtful are resolved in 3D.
        near = self.image_nearest_sample
        p = np.zeros((0, 4)) if planes is None else np.asarray(planes, dtype=np.float64)
        k = min(PROPAGATION_NEIGHBOURS, self.size) if len(p) else 1
        indptr, indices = graph.indptr, graph.indices
        mixed = mixed_samples(labels, indptr, indices)
        valid = np.empty(all_pixels.shape[0], dtype=np.int32)
        # Pixels farther than the radius from their image-nearest sample lie across a depth
        # jump from it: their nearest samples in 3D are looked up in the image around them
        # when the intrinsics say where a point projects, else in the point index.
        image = self.sample_image
        cam = np.zeros((0, 3)) if image is None else image.intrinsics
        tiles = sample_tiles(pixels, self.points, w, h, TILE)

        def label_chunk(a: int, b: int) -> None:
            gap = propagate_pixels(out, valid, all_pixels, self.all_points, near, self.points,
                                   pixels, labels, p, indptr, indices, mixed, radius**2,
                                   float(tolerance), k, tiles, (h, w), cam,
                                   float(self.scale), self.center, a, b)
            if gap.size:
                valid[gap] = self.label_points(self.all_points[gap], labels, p, radius)
                out[all_pixels[gap]] = valid[gap]

        # Pixels are labelled independently: contiguous chunks run on parallel threads, each
        # writing its own pixels.
        run_threaded([partial(label_chunk, a, b)
                      for a, b in chunks(near.shape[0], THREADED_PIXELS)])
        return out.reshape(h, w), valid

    def _propagate_points(self, labels: np.ndarray, planes: np.ndarray | None,
                          spacing: float | None, graph: NeighbourGraph | None) -> np.ndarray:
        """:meth:`propagate` for a cloud without an image: (V,) int32 labels of all points."""
        if self.sampled is None:
            return labels.copy()
        if spacing is None:
            if graph is None:
                graph = self.neighbour_graph(PROPAGATION_GRAPH_K)
            spacing = graph.spacing
        p = np.zeros((0, 4)) if planes is None else np.asarray(planes, dtype=np.float64)
        out = self.label_points(self.all_points, labels, p.reshape(-1, 4),
                                PROPAGATION_RADIUS_FACTOR * max(spacing, 1e-12))
        out[self.sampled] = labels  # sampled points keep their own label
        return out

    def label_points(self, queries: np.ndarray, labels: np.ndarray, planes: np.ndarray,
                     radius: float) -> np.ndarray:
        """Labels of any points from the labels of this cloud's points (grid kNN index).

        A query point is non-planar when its nearest cloud point within ``radius`` is
        non-planar or there is none; otherwise it takes, among the planar labels of its
        :data:`PROPAGATION_NEIGHBOURS` nearest cloud points within ``radius``, the plane it is
        closest to. :meth:`propagate` uses it for the pixels across a depth jump from their
        image-nearest sample and for the points of a cloud without an image left out of the
        search.

        Parameters
        ----------
        queries : numpy.ndarray
            (Q, 3) points in the normalised frame.
        labels : numpy.ndarray
            (N,) int labels of ``points`` (0 = non-planar, ``i`` = ``planes[i - 1]``).
        planes : numpy.ndarray
            (P, 4) planes of the labels, normalised frame.
        radius : float
            Farthest a cloud point may lie from a query to count, normalised units.

        Returns
        -------
        numpy.ndarray
            (Q,) int32 labels.
        """
        queries = np.asarray(queries, dtype=np.float64).reshape(-1, 3)
        labels = np.asarray(labels)
        k = min(PROPAGATION_NEIGHBOURS, self.size) if len(planes) else 1
        out = np.zeros(queries.shape[0], dtype=np.int32)
        # Chunks bound the (Q, k) answers' memory on clouds of millions of points.
        for start in range(0, queries.shape[0], _LABEL_CHUNK):
            part = queries[start:start + _LABEL_CHUNK]
            d_k, n_k = self.tree.query(part, k=k, distance_upper_bound=radius)
            out[start:start + len(part)] = closest_plane(
                part, d_k.reshape(len(part), k), n_k.reshape(len(part), k), labels, planes)
        return out


def normalised_cloud(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Distinct points normalised into the unit ball: ``(X - center) / scale``.

    Parameters
    ----------
    points : numpy.ndarray
        (V, 3) float64 finite distinct points, any frame and unit.

    Returns
    -------
    normalised : numpy.ndarray
        (V, 3) float64 points, the farthest at distance 1 from the origin.
    center : numpy.ndarray
        (3,) centroid of ``points``.
    scale : float
        Largest distance of a point from ``center``, the points' unit.

    Raises
    ------
    InvalidInput
        When the points lie too close together to be normalised in float64.
    """
    center = points.mean(axis=0)
    extent = float(np.abs(points - center).max())
    # Points closer together than float64 resolves at their magnitude, or so close that their
    # squared distances underflow, cannot be put into the unit sphere.
    if not extent > max(1e-150, 1e-12 * float(np.abs(center).max())):
        raise InvalidInput(f"the cloud's {len(points)} distinct points lie within {extent:.3g} "
                           f"of their centre {center.tolist()}: too close together to fit "
                           "planes to")
    scale = float(np.sqrt(((points - center) ** 2).sum(axis=1).max()))
    return (points - center) / scale, center, scale
