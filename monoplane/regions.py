"""Region clean-up after image-level refinement (paper appendix, "Dense CRFs", last paragraph).

A plane label can cover several disconnected image regions after RANSAC and the CRF. Each such
region becomes its own plane, regions below a minimum area become non-planar, and every plane
is refit by least squares on the pixels it finally covers.

Two optional deviations from the paper (see ``docs/design.md``, "Refiner: deviations from the
paper"), both decided by a point-to-plane residual test in units of the scene radius (the
largest distance of a valid 3D point from their centroid, the same normalisation as the RANSAC
thresholds):

* re-merging (:func:`merge_coplanar`): regions split from one label whose refit planes agree
  become one plane again, so the split only separates genuinely different planes (a floor seen
  on both sides of a box stays one floor);
* absorbing (:func:`absorb_small_regions`): a region below the minimum area joins an adjacent
  plane when its 3D points lie on that plane, and becomes non-planar only otherwise.

Connectivity: 8-connectivity by default (pixels touching at a corner belong to the same
region), so that a region is not cut along a one-pixel diagonal staircase; 4-connectivity is
available for stricter splitting.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from monoplane.densecrf import REFERENCE_AREA
from monoplane.errors import InvalidInput
from monoplane.geometry.planes import fit_planes_per_label, point_plane_distances
from monoplane.types import Reconstruction

#: The paper's minimum region size, in pixels at 256 x 192 (appendix).
MIN_AREA_AT_REFERENCE = 300


def scaled_min_area(shape: tuple[int, int], area_at_reference: float = MIN_AREA_AT_REFERENCE
                    ) -> int:
    """Minimum region area for an image of ``shape``, scaled from the 256 x 192 reference.

    Parameters
    ----------
    shape : tuple of int
        ``(H, W)`` in pixels.
    area_at_reference : float
        Minimum area in pixels at 256 x 192 (paper: 300).

    Returns
    -------
    int
        ``round(area_at_reference · H W / (256 · 192))``, e.g. 1875 at 640 x 480.
    """
    if area_at_reference < 0:
        raise InvalidInput(f"minimum area must be >= 0, got {area_at_reference}")
    h, w = shape
    return int(round(area_at_reference * h * w / REFERENCE_AREA))


def split_components(labels: np.ndarray, connectivity: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Give every connected region of every plane label its own label.

    Parameters
    ----------
    labels : numpy.ndarray
        (H, W) int label map, 0 = non-planar.
    connectivity : {4, 8}
        Pixel neighbourhood that connects a region.

    Returns
    -------
    new_labels : numpy.ndarray
        (H, W) int32 map with labels 1..P'. Regions are numbered by their original label,
        then by the raster position (row-major) of their first pixel; 0 stays 0.
    origin : numpy.ndarray
        (P',) int64 original label of each new label (``origin[k - 1]`` for label ``k``).
    """
    lab = np.asarray(labels)
    if lab.ndim != 2:
        raise InvalidInput(f"labels must be (H, W), got {lab.shape}")
    if connectivity not in (4, 8):
        raise InvalidInput(f"connectivity must be 4 or 8, got {connectivity}")
    h, w = lab.shape
    index = np.arange(h * w).reshape(h, w)
    offsets = [(0, 1), (1, 0)] + ([(1, 1), (1, -1)] if connectivity == 8 else [])
    src, dst = [], []
    for dy, dx in offsets:
        # Pair each pixel (y, x) with (y + dy, x + dx) where both exist.
        ys, yd = slice(0, h - dy), slice(dy, h)
        xs, xd = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
        a, b = lab[ys, xs], lab[yd, xd]
        same = (a == b) & (a > 0)
        src.append(index[ys, xs][same])
        dst.append(index[yd, xd][same])
    s, d = np.concatenate(src), np.concatenate(dst)
    graph = sp.coo_matrix((np.ones(s.size, dtype=np.int8), (s, d)), shape=(h * w, h * w))
    _, comp = connected_components(graph, directed=False)
    flat = lab.ravel()
    planar = np.flatnonzero(flat > 0)
    comps, first = np.unique(comp[planar], return_index=True)
    first_pixel = planar[first]
    orig = flat[first_pixel].astype(np.int64)
    order = np.lexsort((first_pixel, orig))
    new_id = np.zeros(comp.max() + 1, dtype=np.int32)
    new_id[comps[order]] = np.arange(1, order.size + 1, dtype=np.int32)
    out = np.zeros(h * w, dtype=np.int32)
    out[planar] = new_id[comp[planar]]
    return out.reshape(h, w), orig[order]


def remove_small_regions(labels: np.ndarray, min_area: int) -> tuple[np.ndarray, np.ndarray]:
    """Set labels covering fewer than ``min_area`` pixels to 0 and renumber the rest.

    Parameters
    ----------
    labels : numpy.ndarray
        (H, W) int label map with labels 0..P.
    min_area : int
        Smallest area kept, in pixels (0 keeps everything).

    Returns
    -------
    new_labels : numpy.ndarray
        (H, W) int32 map with labels 1..P'' in the original order.
    kept : numpy.ndarray
        (P'',) int64 old label of each new label.
    """
    lab = np.asarray(labels)
    num = int(lab.max()) if lab.size else 0
    area = np.bincount(lab.ravel(), minlength=num + 1)
    kept = np.flatnonzero(area[1:] >= min_area) + 1
    remap = np.zeros(num + 1, dtype=np.int32)
    remap[kept] = np.arange(1, kept.size + 1, dtype=np.int32)
    return remap[lab], kept.astype(np.int64)


def refit_planes(points: np.ndarray, valid: np.ndarray, labels: np.ndarray,
                 fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares plane of each label on its valid pixels' 3D points.

    Parameters
    ----------
    points : numpy.ndarray
        (H, W, 3) camera-frame points (OpenCV axes), in depth units.
    valid : numpy.ndarray
        (H, W) bool, pixels with a valid depth.
    labels : numpy.ndarray
        (H, W) int labels 0..P.
    fallback : numpy.ndarray
        (P, 4) planes kept for labels with fewer than 3 valid points (e.g. regions the CRF
        grew over invalid depth).

    Returns
    -------
    params : numpy.ndarray
        (P, 4) float64 planes ``n · X + d = 0``, unit normal facing the camera.
    rmse : numpy.ndarray
        (P,) float64 RMS point-to-plane distance of the label's valid points, depth units
        (0 when it has none).
    support : numpy.ndarray
        (P,) int64 number of valid points of each label.
    """
    fallback = np.asarray(fallback, dtype=np.float64).reshape(-1, 4)
    num = fallback.shape[0]
    lab = np.where(valid, labels, 0)
    params, rmse, support = fit_planes_per_label(points, lab, num)
    unfit = np.isnan(rmse)
    params[unfit] = fallback[unfit]
    rmse[unfit] = 0.0
    # A label with 1-2 valid points keeps its previous plane; its RMSE is measured against it.
    for k in np.flatnonzero(unfit & (support > 0)):
        group = points[lab == k + 1].astype(np.float64)
        rmse[k] = float(np.sqrt(np.mean((group @ params[k, :3] + params[k, 3]) ** 2)))
    return params, rmse, support


def scene_radius(points: np.ndarray, valid: np.ndarray) -> float:
    """Largest distance of a valid 3D point from the valid points' centroid.

    The RANSAC normalises the cloud by this radius into the unit sphere; expressing the
    region tolerances as a fraction of it makes them free of the depth's unit and scale.

    Parameters
    ----------
    points : numpy.ndarray
        (H, W, 3) camera-frame points (OpenCV axes), depth units.
    valid : numpy.ndarray
        (H, W) bool, pixels with a valid depth.

    Returns
    -------
    float
        Radius in depth units; 0 when there are no valid points.
    """
    pts = points[valid].astype(np.float64)
    if not len(pts):
        return 0.0
    return float(np.sqrt(((pts - pts.mean(axis=0)) ** 2).sum(axis=1).max()))


def _rms_to_planes(points: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """(H,) RMS distance of (N, 3) points to each of (H, 4) planes; inf when N = 0."""
    if not len(points):
        return np.full(len(planes), np.inf)
    return np.sqrt(np.mean(point_plane_distances(points, planes) ** 2, axis=1))


def _groups(points: np.ndarray, valid: np.ndarray, labels: np.ndarray, num: int
            ) -> list[np.ndarray]:
    """Valid (n_k, 3) float64 points of each label 1..num, in label order."""
    mask = valid & (labels > 0)
    lab = labels[mask]
    order = np.argsort(lab, kind="stable")
    counts = np.bincount(lab, minlength=num + 1)[1:num + 1]
    return np.split(points[mask].astype(np.float64)[order], np.cumsum(counts)[:-1])


def merge_coplanar(points: np.ndarray, valid: np.ndarray, labels: np.ndarray,
                   origin: np.ndarray, params: np.ndarray, max_angle_deg: float,
                   max_distance: float, extra_pairs: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Merge regions that came from the same plane label (or ``extra_pairs``) and share a plane.

    Two regions ``a`` and ``b`` with ``origin[a] == origin[b]`` are joined when the angle
    between their refit normals is at most ``max_angle_deg`` and the RMS distance of each
    region's valid points to the other's plane is at most ``max_distance``. Joins are
    transitive (union-find); regions need not touch in the image, since an occluder can cut a
    plane into parts that only meet behind it.

    Parameters
    ----------
    points : numpy.ndarray
        (H, W, 3) camera-frame points (OpenCV axes), depth units.
    valid : numpy.ndarray
        (H, W) bool, pixels with a valid depth.
    labels : numpy.ndarray
        (H, W) int region labels 0..R (0 = non-planar), e.g. from :func:`split_components`.
    origin : numpy.ndarray
        (R,) original plane label of each region.
    params : numpy.ndarray
        (R, 4) plane of each region (``n · X + d = 0``, unit n), e.g. from
        :func:`refit_planes`.
    max_angle_deg : float
        Largest normal angle between merged regions, degrees.
    max_distance : float
        Largest RMS point-to-plane distance, depth units.

    extra_pairs : numpy.ndarray, optional
        (E, 2) further region pairs (labels 1..R, e.g. :func:`region_adjacency`) to test the
        same way whatever their origin: touching regions of two RANSAC planes that turn out to
        be one plane.

    Returns
    -------
    new_labels : numpy.ndarray
        (H, W) int32 labels 1..G. Each group is represented by its largest region (ties: the
        lower label), and groups are numbered in the order of their representatives' labels.
    origin : numpy.ndarray
        (G,) int64 original plane label of each group's representative.
    """
    origin = np.asarray(origin, dtype=np.int64)
    num = origin.size
    parent = np.arange(num)

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = int(parent[i])
        return i

    groups = _groups(points, valid, labels, num)
    area = np.bincount(np.asarray(labels).ravel(), minlength=num + 1)[1:num + 1]

    def union(a: int, b: int) -> None:
        # The larger region (then the lower label) represents the group: it names the group's
        # position in the numbering and its original plane.
        ra, rb = root(a), root(b)
        if ra != rb:
            keep, drop = sorted((ra, rb), key=lambda r: (-area[r], r))
            parent[drop] = keep

    cos_min = np.cos(np.deg2rad(max_angle_deg))
    for o in np.unique(origin):
        members = np.flatnonzero(origin == o)
        if members.size < 2:
            continue
        normals = params[members, :3]
        cos = np.abs(normals @ normals.T)
        # rms[i, j]: RMS distance of region members[i]'s points to members[j]'s plane.
        rms = np.stack([_rms_to_planes(groups[m], params[members]) for m in members])
        ok = (cos >= cos_min) & (rms <= max_distance) & (rms.T <= max_distance)
        for i, j in zip(*np.nonzero(np.triu(ok, 1)), strict=True):
            union(int(members[i]), int(members[j]))
    if extra_pairs is not None:
        for a, b in np.asarray(extra_pairs, dtype=np.int64).reshape(-1, 2) - 1:
            pa, pb = params[[a, b]]
            if (abs(pa[:3] @ pb[:3]) >= cos_min
                    and _rms_to_planes(groups[a], pb[None])[0] <= max_distance
                    and _rms_to_planes(groups[b], pa[None])[0] <= max_distance):
                union(int(a), int(b))
    roots = np.array([root(i) for i in range(num)], dtype=np.int64)
    kept, group_of = np.unique(roots, return_inverse=True)
    remap = np.concatenate([[0], group_of + 1]).astype(np.int32)
    return remap[labels], origin[kept]


def region_adjacency(labels: np.ndarray, connectivity: int = 8) -> np.ndarray:
    """Pairs of distinct plane labels that touch in the image.

    Parameters
    ----------
    labels : numpy.ndarray
        (H, W) int labels, 0 = non-planar (never part of a pair).
    connectivity : {4, 8}
        Pixel neighbourhood.

    Returns
    -------
    numpy.ndarray
        (E, 2) int64 sorted, distinct pairs ``(a, b)`` with ``0 < a < b``.
    """
    lab = np.asarray(labels)
    h, w = lab.shape
    offsets = [(0, 1), (1, 0)] + ([(1, 1), (1, -1)] if connectivity == 8 else [])
    pairs = []
    for dy, dx in offsets:
        ys, yd = slice(0, h - dy), slice(dy, h)
        xs, xd = (slice(0, w - dx), slice(dx, w)) if dx >= 0 else (slice(-dx, w), slice(0, w + dx))
        a, b = lab[ys, xs].ravel(), lab[yd, xd].ravel()
        touch = (a != b) & (a > 0) & (b > 0)
        pairs.append(np.stack([np.minimum(a, b)[touch], np.maximum(a, b)[touch]], axis=1))
    return np.unique(np.concatenate(pairs).astype(np.int64).reshape(-1, 2), axis=0)


def absorb_small_regions(points: np.ndarray, valid: np.ndarray, labels: np.ndarray,
                         params: np.ndarray, min_area: int, max_distance: float,
                         connectivity: int = 8) -> np.ndarray:
    """Give each region below ``min_area`` to the adjacent plane its points lie on.

    A small region's candidates are the regions of at least ``min_area`` pixels that touch it.
    It joins the candidate whose plane its valid points fit best (lowest RMS distance) when
    that RMS is at most ``max_distance``; otherwise (no candidate, no valid point, or no fit)
    it becomes non-planar, as in the paper. Large regions are not changed.

    Parameters
    ----------
    points : numpy.ndarray
        (H, W, 3) camera-frame points (OpenCV axes), depth units.
    valid : numpy.ndarray
        (H, W) bool, pixels with a valid depth.
    labels : numpy.ndarray
        (H, W) int labels 0..R.
    params : numpy.ndarray
        (R, 4) plane of each label (``n · X + d = 0``, unit n).
    min_area : int
        Smallest area, in pixels, that a region needs to stand on its own.
    max_distance : float
        Largest RMS point-to-plane distance for a region to join a plane, depth units.
    connectivity : {4, 8}
        Pixel neighbourhood of "adjacent".

    Returns
    -------
    numpy.ndarray
        (H, W) int32 labels 0..R in which every label is either empty or at least ``min_area``
        pixels (not renumbered; see :func:`remove_small_regions`).
    """
    lab = np.asarray(labels)
    num = params.shape[0]
    area = np.bincount(lab.ravel(), minlength=num + 1)[1:num + 1]
    small = (area > 0) & (area < min_area)
    remap = np.arange(num + 1, dtype=np.int32)
    remap[1:][small] = 0
    if not small.any():
        return remap[lab]
    edges = region_adjacency(lab, connectivity)
    groups = _groups(points, valid, lab, num)
    for s in np.flatnonzero(small) + 1:
        other = np.concatenate([edges[edges[:, 0] == s, 1], edges[edges[:, 1] == s, 0]])
        cand = other[~small[other - 1]]
        if not cand.size:
            continue
        rms = _rms_to_planes(groups[s - 1], params[cand - 1])
        best = int(np.argmin(rms))
        if rms[best] <= max_distance:
            remap[s] = cand[best]
    return remap[lab]


def gate_filled_pixels(points: np.ndarray, valid: np.ndarray, before: np.ndarray,
                       after: np.ndarray, params: np.ndarray, max_distance: float
                       ) -> np.ndarray:
    """Keep a refinement's move from non-planar to a plane only where the point fits the plane.

    Parameters
    ----------
    points : numpy.ndarray
        (H, W, 3) camera-frame points (OpenCV axes), depth units.
    valid : numpy.ndarray
        (H, W) bool, pixels with a valid depth.
    before : numpy.ndarray
        (H, W) int labels 0..P before refinement (the RANSAC's).
    after : numpy.ndarray
        (H, W) int labels 0..P after refinement, same plane numbering.
    params : numpy.ndarray
        (P, 4) planes ``n · X + d = 0`` (unit n) of labels 1..P, depth units.
    max_distance : float
        Largest point-to-plane distance of a filled pixel, depth units.

    Returns
    -------
    numpy.ndarray
        (H, W) int32 ``after``, with 0 restored at pixels that were 0 in ``before`` and whose
        point lies farther than ``max_distance`` from their new plane (or whose depth is
        invalid).
    """
    out = np.asarray(after, dtype=np.int32).copy()
    filled = (np.asarray(before) == 0) & (out > 0)
    plane = params[out[filled] - 1]
    dist = np.abs(np.einsum("nc,nc->n", points[filled], plane[:, :3]) + plane[:, 3])
    out[filled] = np.where(valid[filled] & (dist <= max_distance), out[filled], 0)
    return out


def clean_regions(rec: Reconstruction, labels: np.ndarray, min_area: int,
                  connectivity: int = 8, split: bool = True, merge: bool = False,
                  absorb: bool = False, max_angle_deg: float = 10.0,
                  max_distance: float = 0.02, inliers_only: bool = False,
                  merge_adjacent: bool = False) -> Reconstruction:
    """Split, filter and refit the planes of a refined label map.

    Parameters
    ----------
    rec : Reconstruction
        The reconstruction ``labels`` was refined from; its ``params`` are inherited by a new
        region that has too few valid points to be refit.
    labels : numpy.ndarray
        (H, W) int refined label map, labels 0..rec.num_planes.
    min_area : int
        Smallest region kept, in pixels of this image (see :func:`scaled_min_area`).
    connectivity : {4, 8}
        Neighbourhood for :func:`split_components`.
    split : bool
        True (paper): every surviving region becomes its own plane. False: regions below
        ``min_area`` are still removed, but the surviving regions of one label stay one plane.
    merge : bool
        With ``split``: re-join regions of one label whose refit planes agree
        (:func:`merge_coplanar`) before the area test, which then applies to the merged plane.
    absorb : bool
        With ``split``: a region below ``min_area`` joins an adjacent plane its points fit
        (:func:`absorb_small_regions`) instead of always becoming non-planar.
    max_angle_deg : float
        Normal tolerance of ``merge``, degrees.
    max_distance : float
        RMS point-to-plane tolerance of ``merge`` and ``absorb``, as a fraction of the scene
        radius (:func:`scene_radius`), like the RANSAC's ε.
    inliers_only : bool
        Fit planes, and run the residual tests, only on pixels that ``rec`` labelled planar
        (its RANSAC inliers). Pixels the refinement moved from non-planar to a plane keep their
        new label but do not bend its plane; support and RMSE count the fitted pixels only.

    Returns
    -------
    Reconstruction
        New reconstruction on ``rec.frame`` with labels 1..P' (by original plane, then raster
        order), parameters, RMSE and support refit on the final pixels; ``config`` and
        ``timings`` are carried over.
    """
    frame = rec.frame
    if frame.depth is None:
        raise InvalidInput(f"{frame.name}: refitting planes needs a depth map")
    pieces, origin = split_components(labels, connectivity)
    points, valid = frame.points(), frame.depth > 0
    if inliers_only:
        # RANSAC outliers carry no evidence about any plane: they may be labelled, not fitted.
        valid = valid & (np.asarray(rec.labels) > 0)
    if split and (merge or absorb):
        tolerance = max_distance * scene_radius(points, valid)
        if merge:
            fitted, _, _ = refit_planes(points, valid, pieces, rec.params[origin - 1])
            extra = region_adjacency(pieces, connectivity) if merge_adjacent else None
            pieces, origin = merge_coplanar(points, valid, pieces, origin, fitted,
                                            max_angle_deg, tolerance, extra)
        if absorb:
            fitted, _, _ = refit_planes(points, valid, pieces, rec.params[origin - 1])
            pieces = absorb_small_regions(points, valid, pieces, fitted, min_area, tolerance,
                                          connectivity)
    final, kept = remove_small_regions(pieces, min_area)
    source = origin[kept - 1]
    if not split:
        # Merge the surviving regions of each original label back into one plane.
        source, merged = np.unique(source, return_inverse=True)
        final = np.concatenate([[0], merged + 1]).astype(np.int32)[final]
    inherited = rec.params[source - 1] if source.size else np.zeros((0, 4))
    params, rmse, support = refit_planes(points, valid, final, inherited)
    return Reconstruction(frame=frame, labels=final, params=params, rmse=rmse, support=support,
                          config=rec.config, timings=dict(rec.timings))
