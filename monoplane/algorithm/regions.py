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

from functools import partial

import cv2
import numpy as np

from monoplane.algorithm.densecrf import REFERENCE_AREA

# refit_planes is not used here: it stays importable from this module, where it lived until the
# moments moved to region_moments.py.
from monoplane.algorithm.region_moments import (  # noqa: F401
    RegionMoments,
    refit_planes,
    scene_radius,
)
from monoplane.algorithm.region_scan import scan_pieces
from monoplane.datamodel import Reconstruction
from monoplane.errors import InvalidInput
from monoplane.geometry.components import graph_components, label_regions
from monoplane.jit import chunks, kernel, run_threaded

#: Rows per threaded piece of the fill gate, below which one thread does the whole image.
_THREADED_ROWS = 64

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
    return label_regions(labels, connectivity)


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


def merge_coplanar(points: np.ndarray, valid: np.ndarray, labels: np.ndarray,
                   origin: np.ndarray, params: np.ndarray, max_angle_deg: float,
                   max_distance: float, extra_pairs: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Merge regions that came from the same plane label (or ``extra_pairs``) and share a plane.

    Two regions ``a`` and ``b`` with ``origin[a] == origin[b]`` are joined when the angle
    between their refit normals is at most ``max_angle_deg`` and the RMS distance of each
    region's valid points to the other's plane is at most ``max_distance``. Joins are
    transitive (connected components of the graph of agreeing pairs); regions need not touch in
    the image, since an occluder can cut a plane into parts that only meet behind it.

    Parameters
    ----------
    points, valid : numpy.ndarray
        As for :func:`scene_radius`.
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
    moments = RegionMoments.of(points, valid, labels, origin.size)
    area = np.bincount(np.asarray(labels).ravel(), minlength=origin.size + 1)[1:origin.size + 1]
    remap, new_origin = _merge_groups(moments, area, origin, params, max_angle_deg,
                                      max_distance, extra_pairs)
    return remap[labels], new_origin


def _merge_groups(moments: RegionMoments, area: np.ndarray, origin: np.ndarray,
                  params: np.ndarray, max_angle_deg: float, max_distance: float,
                  extra_pairs: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`merge_coplanar` on region moments: ``(remap (R+1,) int32, origin (G,))``."""
    num = origin.size
    rms = moments.rms(params)  # rms[a, b]: region a's points to region b's plane
    cos_min = np.cos(np.deg2rad(max_angle_deg))
    pairs = np.argwhere(np.triu(origin[:, None] == origin[None, :], 1))
    if extra_pairs is not None:
        pairs = np.concatenate([pairs, np.asarray(extra_pairs, np.int64).reshape(-1, 2) - 1])
    a, b = pairs[:, 0], pairs[:, 1]
    ok = ((np.abs(np.einsum("ek,ek->e", params[a, :3], params[b, :3])) >= cos_min)
          & (rms[a, b] <= max_distance) & (rms[b, a] <= max_distance))
    group = graph_components(num, np.stack([a[ok], b[ok]], axis=1))
    # The largest region (then the lower label) of a group represents it: it names the group's
    # position in the numbering and its original plane.
    order = np.lexsort((np.arange(num), -area, group))
    first = np.ones(num, bool)
    first[1:] = group[order][1:] != group[order][:-1]
    rep = order[first]  # one representative per group, groups in component-id order
    rep_of_group = np.empty(rep.size, np.int64)
    rep_of_group[group[rep]] = rep
    rank = np.argsort(np.argsort(rep_of_group))  # groups numbered by representative label
    remap = np.concatenate([[0], rank[group] + 1]).astype(np.int32)
    return remap, origin[np.sort(rep_of_group)]


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
    lab = np.ascontiguousarray(labels, dtype=np.int64)
    if lab.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    touch = _touching(lab, int(lab.max()), connectivity == 8)
    return np.argwhere(np.triu(touch, 1)).astype(np.int64)


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
    points, valid : numpy.ndarray
        As for :func:`scene_radius`.
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
    moments = RegionMoments.of(points, valid, lab, num)
    edges = region_adjacency(lab, connectivity)
    return _absorb_remap(moments, area, edges, params, min_area, max_distance)[lab]


def _absorb_remap(moments: RegionMoments, area: np.ndarray, edges: np.ndarray,
                  params: np.ndarray, min_area: int, max_distance: float) -> np.ndarray:
    """:func:`absorb_small_regions` on region moments and (E, 2) adjacency: (R+1,) remap."""
    num = area.size
    small = (area > 0) & (area < min_area)
    remap = np.arange(num + 1, dtype=np.int32)
    remap[1:][small] = 0
    if not small.any():
        return remap
    _absorb_into(small, moments.rms(params), np.ascontiguousarray(edges, dtype=np.int64),
                 float(max_distance), remap)
    return remap


@kernel
def _absorb_into(small: np.ndarray, rms: np.ndarray, edges: np.ndarray, max_distance: float,
                 remap: np.ndarray) -> None:
    """Set ``remap[s]`` (R+1,) int32 of each region ``s`` flagged in the (R,) bool ``small``
    to the adjacent region that is not small whose plane its points fit best, when the
    (R, R) float64 ``rms[s - 1, b - 1]`` is at most ``max_distance``.

    The candidates are the pairs of the sorted (E, 2) int64 ``edges`` with ``s`` first, then
    those with ``s`` second, and the first smallest RMS (a NaN, as ``numpy.argmin``) wins.
    """
    for s in range(1, small.size + 1):
        if not small[s - 1]:
            continue
        best = -1
        fit = np.inf
        found = False
        for side in range(2):
            for e in range(edges.shape[0]):
                if edges[e, side] != s:
                    continue
                b = edges[e, 1 - side]
                if small[b - 1]:
                    continue
                v = rms[s - 1, b - 1]
                if not found or (fit == fit and (v != v or v < fit)):
                    best, fit, found = b, v, True
        if found and fit <= max_distance:
            remap[s] = best


def gate_filled_pixels(points: np.ndarray, valid: np.ndarray, before: np.ndarray,
                       after: np.ndarray, params: np.ndarray, max_distance: float,
                       normals: np.ndarray | None = None, max_angle_deg: float = 180.0,
                       patch_px: int = 0) -> np.ndarray:
    """Keep a refinement's change of a pixel's plane only where the pixel fits its new plane.

    A refiner (a CRF, label propagation) decides labels from smoothness and appearance; it
    must not grow a plane onto a surface that is not on it: a curved object, or an object
    standing in front of the plane. So every pixel whose label the refinement changed, from
    non-planar or from another plane, keeps its new plane only when its point lies within
    ``max_distance`` of it and its normal within ``max_angle_deg`` of the plane's normal;
    otherwise it gets back its label from ``before``.

    Parameters
    ----------
    points, valid : numpy.ndarray
        As for :func:`scene_radius`.
    before : numpy.ndarray
        (H, W) int labels 0..P before refinement (the RANSAC's).
    after : numpy.ndarray
        (H, W) int labels 0..P after refinement, same plane numbering.
    params : numpy.ndarray
        (P, 4) planes ``n · X + d = 0`` (unit n) of labels 1..P, depth units.
    max_distance : float
        Largest point-to-plane distance of a pixel given a new plane, depth units.
    normals : numpy.ndarray, optional
        (H, W, 3) unit normals, camera frame (zero where unknown: no angle test there).
    max_angle_deg : float
        Largest angle between a pixel's normal and its new plane's normal, degrees (unsigned:
        the plane's side does not matter). 180 (or no ``normals``) tests distance only.
    patch_px : int
        With ``patch_px`` > 0 a pixel that fails is sent back only when it lies in a patch of
        failing pixels at least ``2 patch_px + 1`` wide (a morphological opening of the
        failures with that square); 0 sends back every failing pixel.

    Returns
    -------
    numpy.ndarray
        (H, W) int32 ``after``, with ``before``'s label restored where the new plane does
        not fit (or the depth is invalid).
    """
    out = np.array(after, dtype=np.int32)
    # Labels are small: int32 (no copy when they are, as the RANSAC's are).
    before = np.ascontiguousarray(before, dtype=np.int32)
    test_angle = normals is not None and max_angle_deg < 180.0
    fail = np.empty(out.shape, np.uint8)
    # Pixels are independent: row blocks on the frame's threads.
    args = (out, before, np.ascontiguousarray(points, dtype=np.float64),
            np.asarray(valid, dtype=bool), np.ascontiguousarray(params, dtype=np.float64),
            float(max_distance),
            np.asarray(normals, dtype=np.float32) if test_angle
            else np.zeros((1, 1, 3), np.float32),
            float(np.cos(np.radians(max_angle_deg))), test_angle)
    failed = sum(run_threaded([partial(_gate_failures, *args, y0, y1, fail)
                               for y0, y1 in chunks(out.shape[0], _THREADED_ROWS)]))
    if not failed:
        return out
    if patch_px > 0:
        # A morphological opening keeps the failures that form patches: a blob of a curved
        # object or of an object in front, not the thin band along a crease where the cue's
        # blurred normals lie between the two planes' and the CRF is right.
        kernel = np.ones((2 * patch_px + 1, 2 * patch_px + 1), np.uint8)
        fail = cv2.morphologyEx(fail, cv2.MORPH_OPEN, kernel)
    np.copyto(out, before, where=fail.view(bool))  # fail holds 0 and 1
    return out


@kernel
def _gate_failures(after: np.ndarray, before: np.ndarray, points: np.ndarray, valid: np.ndarray,
                   params: np.ndarray, max_distance: float, normals: np.ndarray,
                   cos_limit: float, test_angle: bool, y0: int, y1: int,
                   fail: np.ndarray) -> int:
    """Rows ``y0:y1`` of the (H, W) uint8 ``fail``: 1 at the pixels
    :func:`gate_filled_pixels` sends back before any opening, else 0; returns how many.

    ``after`` and ``before`` (H, W) int32 labels, ``points`` (H, W, 3) float64,
    ``valid`` (H, W) bool, ``params`` (P, 4) float64, ``normals`` (H, W, 3) float32 (read
    only when ``test_angle``). The sums run in the order (and the float32 normal length in
    the precision) of the numpy einsums they replace, so the failures are the same.
    """
    w = after.shape[1]
    failed = 0
    half = np.float32(0.5)
    for y in range(y0, y1):
        for x in range(w):
            fail[y, x] = 0
            lab = after[y, x]
            if lab <= 0 or lab == before[y, x]:
                continue
            a, b, c, d = params[lab - 1, 0], params[lab - 1, 1], params[lab - 1, 2], \
                params[lab - 1, 3]
            dist = abs(points[y, x, 0] * a + points[y, x, 1] * b + points[y, x, 2] * c + d)
            fits = valid[y, x] and dist <= max_distance
            if fits and test_angle:
                nx, ny, nz = normals[y, x, 0], normals[y, x, 1], normals[y, x, 2]
                known = nx * nx + ny * ny + nz * nz > half
                cos = abs(np.float64(nx) * a + np.float64(ny) * b + np.float64(nz) * c)
                fits = not known or cos >= cos_limit
            if not fits:
                fail[y, x] = 1
                failed += 1
    return failed


def clean_regions(rec: Reconstruction, labels: np.ndarray, min_area: int,
                  connectivity: int = 8, split: bool = True, merge: bool = False,
                  absorb: bool = False, max_angle_deg: float = 10.0,
                  max_distance: float = 0.02, inliers_only: bool = False,
                  merge_adjacent: bool = False, points: np.ndarray | None = None
                  ) -> Reconstruction:
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
    points : numpy.ndarray, optional
        (H, W, 3) ``rec.frame.points()``, when the caller has them already.

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
    points = frame.points() if points is None else points
    valid = frame.depth > 0
    if inliers_only:
        # RANSAC outliers carry no evidence about any plane: they may be labelled, not fitted.
        valid = valid & (np.asarray(rec.labels) > 0)
    # Every later step works on the pieces' point moments; regions only ever grow by union.
    # One scan reads them, the areas, the scene radius and which pieces touch.
    scan = scan_pieces(points, valid, pieces, origin.size,
                       connectivity if split and (absorb or (merge and merge_adjacent))
                       else None)
    moments, area = scan.moments, scan.area
    # Merging and absorbing renumber regions: ``to`` maps each piece to its region, and the
    # pieces' image is renumbered once, at the end.
    to = np.arange(origin.size + 1, dtype=np.int32)
    if split and (merge or absorb):
        tolerance = max_distance * scan.radius
        touching = scan.touching
        if merge:
            fitted, _, _ = moments.planes(rec.planes[origin - 1])
            remap, origin = _merge_groups(moments, area, origin, fitted, max_angle_deg,
                                          tolerance, touching if merge_adjacent else None)
            to, moments, area = _regrouped(to, moments, area, remap, origin.size)
            touching = None if touching is None else _renumbered_pairs(touching, remap)
        if absorb:
            fitted, _, _ = moments.planes(rec.planes[origin - 1])
            remap = _absorb_remap(moments, area, touching, fitted, min_area, tolerance)
            to, moments, area = _regrouped(to, moments, area, remap, origin.size)
    kept = np.flatnonzero(area >= min_area) + 1
    remap = np.zeros(area.size + 1, dtype=np.int32)
    remap[kept] = np.arange(1, kept.size + 1, dtype=np.int32)
    final = np.take(remap[to], pieces)  # remap[to][pieces], without an intp copy of pieces
    moments = moments.combine(remap[1:], kept.size)
    source = origin[kept - 1]
    if not split:
        # Merge the surviving regions of each original label back into one plane.
        source, merged = np.unique(source, return_inverse=True)
        final = np.concatenate([[0], merged + 1]).astype(np.int32)[final]
        moments = moments.combine(merged + 1, source.size)
    inherited = rec.planes[source - 1] if source.size else np.zeros((0, 4))
    params, rmse, support = moments.planes(inherited)
    return Reconstruction(frame=frame, labels=final, planes=params, rmse=rmse, support=support,
                          config=rec.config, timings=dict(rec.timings))


def _regrouped(to: np.ndarray, moments: RegionMoments, area: np.ndarray, remap: np.ndarray,
               num: int) -> tuple[np.ndarray, RegionMoments, np.ndarray]:
    """Pieces' regions ``to`` (P+1,), moments and (R,) areas after the (R+1,) ``remap`` of
    regions into ``num`` groups."""
    area = np.bincount(remap[1:], area, num + 1)[1:].astype(np.int64)
    return remap[to], moments.combine(remap[1:], num), area


def _renumbered_pairs(pairs: np.ndarray, remap: np.ndarray) -> np.ndarray:
    """:func:`region_adjacency` of ``remap[labels]``, from the (E, 2) pairs of ``labels``.

    Two new labels touch exactly when two old labels that map to them touch, so the
    renumbered pairs (without 0 and without a label paired with itself) are the new ones;
    sorted and distinct as :func:`region_adjacency` returns them.
    """
    a = remap[pairs[:, 0]].astype(np.int64)
    b = remap[pairs[:, 1]].astype(np.int64)
    keep = (a > 0) & (b > 0) & (a != b)
    new = np.stack([np.minimum(a, b)[keep], np.maximum(a, b)[keep]], axis=1)
    return np.unique(new, axis=0).reshape(-1, 2)


@kernel
def _touching(labels: np.ndarray, top: int, diagonal: bool) -> np.ndarray:
    """(top+1, top+1) bool: labels a != b, both > 0, at 4- (or 8-, ``diagonal``) neighbouring
    pixels of the (H, W) int64 map, symmetric."""
    h, w = labels.shape
    touch = np.zeros((top + 1, top + 1), dtype=np.bool_)
    for y in range(h):
        for x in range(w):
            a = labels[y, x]
            if a <= 0:
                continue
            for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
                if dx != 0 and dy != 0 and not diagonal:
                    continue
                yy, xx = y + dy, x + dx
                if yy >= h or xx < 0 or xx >= w:
                    continue
                b = labels[yy, xx]
                if b > 0 and b != a:
                    touch[a, b] = True
                    touch[b, a] = True
    return touch

