"""Region clean-up after image-level refinement (paper appendix, "Dense CRFs", last paragraph).

A plane label can cover several disconnected image regions after RANSAC and the CRF. Each such
region becomes its own plane, regions below a minimum area become non-planar, and every plane
is refit by least squares on the pixels it finally covers.

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
from monoplane.geometry.planes import fit_plane
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
    mask = valid & (labels > 0)
    lab = labels[mask]
    pts = points[mask].astype(np.float64)
    order = np.argsort(lab, kind="stable")
    support = np.bincount(lab, minlength=num + 1)[1:].astype(np.int64)
    groups = np.split(pts[order], np.cumsum(support)[:-1])
    params = fallback.copy()
    rmse = np.zeros(num)
    for k, group in enumerate(groups):
        if len(group) >= 3:
            params[k], rmse[k] = fit_plane(group)
        elif len(group):
            n, d = params[k, :3], params[k, 3]
            rmse[k] = float(np.sqrt(np.mean((group @ n + d) ** 2)))
    return params, rmse, support


def clean_regions(rec: Reconstruction, labels: np.ndarray, min_area: int,
                  connectivity: int = 8, split: bool = True) -> Reconstruction:
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
    final, kept = remove_small_regions(pieces, min_area)
    source = origin[kept - 1]
    if not split:
        # Merge the surviving regions of each original label back into one plane.
        source, merged = np.unique(source, return_inverse=True)
        final = np.concatenate([[0], merged + 1]).astype(np.int32)[final]
    inherited = rec.params[source - 1] if source.size else np.zeros((0, 4))
    params, rmse, support = refit_planes(frame.points(), frame.depth > 0, final, inherited)
    return Reconstruction(frame=frame, labels=final, params=params, rmse=rmse, support=support,
                          config=rec.config, timings=dict(rec.timings))
