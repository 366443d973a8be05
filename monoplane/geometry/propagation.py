"""Labels carried from a cloud's samples to the points or pixels left out of it: the
nearest samples vote, and among their planes the closest one wins (used by
:meth:`monoplane.geometry.cloud.PlaneCloud.propagate`).

Both that vote and the kNN graph of a frame's samples (:func:`image_knn`) find nearest
samples in 3D through the image: a point within distance ρ of a pixel's point projects
within a window the intrinsics bound (:func:`_reach`), so the samples bucketed by image tile
outside it need no distance.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import numpy as np

from monoplane.jit import chunks, inline, kernel, run_threaded


def closest_plane(x: np.ndarray, d_k: np.ndarray, n_k: np.ndarray, labels: np.ndarray,
                  planes: np.ndarray) -> np.ndarray:
    """Labels of pixels from their k nearest samples (point-index query with an upper bound).

    ``x`` (U, 3) pixel points, ``d_k``/``n_k`` (U, k) distances (inf beyond the bound) and
    sample indices, ``labels`` (N,), ``planes`` (P, 4). Non-planar if the nearest sample is
    non-planar or out of range, else the planar candidate label whose plane is closest.
    """
    found = np.isfinite(d_k)
    cand = np.where(found, labels[np.minimum(n_k, labels.size - 1)], 0)
    if not len(planes):
        return cand[:, 0]
    lab = np.maximum(cand - 1, 0)
    res_k = np.abs(np.einsum("vkc,vc->vk", planes[lab, :3], x) + planes[lab, 3])
    res_k[cand == 0] = np.inf
    best = cand[np.arange(len(x)), np.argmin(res_k, axis=1)]
    return np.where(cand[:, 0] > 0, best, 0).astype(np.int32)


@kernel
def mixed_samples(labels: np.ndarray, indptr: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """(N,) bool: True where a sample has a graph neighbour of another label.

    ``labels`` (N,) int32, ``indptr`` (N + 1,) and ``indices`` int64 the graph's adjacency.
    A pixel whose image-nearest sample is not mixed takes that sample's label whenever it lies
    within the radius (:func:`propagate_pixels`): its candidates all carry that label.
    """
    n = labels.shape[0]
    out = np.zeros(n, dtype=np.bool_)
    for s in range(n):
        for c in range(indptr[s], indptr[s + 1]):
            if labels[indices[c]] != labels[s]:
                out[s] = True
                break
    return out


#: Side in pixels of the image tiles :func:`sample_tiles` buckets the samples into for
#: :func:`propagate_pixels`.
TILE = 8
#: The same for :func:`image_knn`, whose windows are a few pixels across: smaller tiles
#: scan less beyond them (about 12 % faster than :data:`TILE` on 640x480 frames).
KNN_TILE = 4
#: :func:`image_knn` leaves a sample to the point index when its window would reach farther
#: than this many pixels from it (isolated samples: their windows hold hundreds of others).
KNN_MAX_REACH = 64
#: :func:`image_knn` sizes a sample's first window for this multiple of the previous
#: sample's k-th squared distance (neighbouring samples have similar ones): about 1 in 9
#: then needs a second window.
KNN_GROWTH = 1.5
#: Samples per thread below which :func:`image_knn` runs on one thread.
KNN_THREADED = 4096
#: :func:`image_knn` gives up on a frame whose samples are not near their 3D neighbours in
#: the image (depth noise as large as the samples' spacing, scattered valid pixels): from
#: the :data:`KNN_PROBE`-th sample of a thread's run on, before each sample, when more than
#: one in :data:`KNN_MISS_SHARE` of those searched so far was left to the point index or
#: their windows held more than :data:`KNN_BUDGET` samples each (45-110 on sensor frames).
#: The point index then answers for every sample.
KNN_PROBE = 512
KNN_MISS_SHARE = 8
KNN_BUDGET = 150


@kernel
def sample_tiles(pixels: np.ndarray, points: np.ndarray, w: int, h: int, tile: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The samples bucketed by image tile (a counting sort), for :func:`propagate_pixels`
    (``tile`` :data:`TILE`) and :func:`image_knn` (:data:`KNN_TILE`).

    ``pixels`` (N,) int64 flat pixels ``v * w + u`` and ``points`` (N, 3) float64 of the
    samples. Returns the (T + 1,) int64 start of each tile's samples (tiles of ``tile`` x
    ``tile`` pixels, row by row), and the (N, 3) points and (N,) int64 sample indices in that
    order (ascending within a tile).
    """
    across = (w + tile - 1) // tile
    tiles = across * ((h + tile - 1) // tile)
    n = pixels.shape[0]
    cell = np.empty(n, dtype=np.int64)
    start = np.zeros(tiles + 1, dtype=np.int64)
    for t in range(n):
        v, u = divmod(pixels[t], w)
        cell[t] = (v // tile) * across + u // tile
        start[cell[t] + 1] += 1
    for i in range(tiles):
        start[i + 1] += start[i]
    fill = start[:-1].copy()
    xyz = np.empty((n, 3))
    ids = np.empty(n, dtype=np.int64)
    for t in range(n):
        p = fill[cell[t]]
        fill[cell[t]] += 1
        xyz[p, 0], xyz[p, 1], xyz[p, 2] = points[t, 0], points[t, 1], points[t, 2]
        ids[p] = t
    return start, xyz, ids


@inline
def _reach(rho: float, z: float, ra: float, rb: float, cam: np.ndarray, w: int, h: int
           ) -> tuple[int, int]:
    """Column and row half-widths of the image window that holds the projection of every
    point within ``rho`` of the camera-frame point ``X = (x, y, z)``, given ``ra = √(z² +
    x²)`` and ``rb = √(z² + y²)``, for the intrinsics ``cam`` (3, 3) with last row ``[0, 0,
    1]``; the whole image when ``z <= rho``.

    With ``a = x / z`` and ``Y = X + δ``, ``|δ| <= rho``: ``|Δa| = |z δx - x δz| / (z (z +
    δz)) <= rho ra / (z (z - rho))``, likewise ``|Δb| <= rho rb / (z (z - rho))`` for ``b =
    y / z``; a pixel moves by ``K[0, 0] Δa + K[0, 1] Δb`` across and ``K[1, 0] Δa + K[1, 1]
    Δb`` down. One pixel more covers rounding.
    """
    if not z > rho:
        return w, h
    t = rho / (z * (z - rho))
    du = (abs(cam[0, 0]) * ra + abs(cam[0, 1]) * rb) * t
    dv = (abs(cam[1, 0]) * ra + abs(cam[1, 1]) * rb) * t
    return int(min(du * (1.0 + 1e-9), w)) + 1, int(min(dv * (1.0 + 1e-9), h)) + 1


@inline
def _camera_radii(x0: float, x1: float, x2: float, scale: float, center: np.ndarray
                  ) -> tuple[float, float, float]:
    """``(z, ra, rb)`` of :func:`_reach` for the normalised point ``(x0, x1, x2)`` of a cloud
    whose camera-frame points are ``x * scale + center`` (``center`` (3,) float64)."""
    z = x2 * scale + center[2]
    return (z, np.sqrt(z * z + (x0 * scale + center[0]) ** 2),
            np.sqrt(z * z + (x1 * scale + center[1]) ** 2))


@inline
def _nearest_in_image(pix: int, x0: float, x1: float, x2: float, start: np.ndarray,
                      xyz: np.ndarray, ids: np.ndarray, w: int, h: int, cam: np.ndarray,
                      scale: float, center: np.ndarray, bound2: float, best_d: np.ndarray,
                      best_i: np.ndarray) -> int:
    """The ``k = len(best_d)`` samples nearest to the normalised point ``(x0, x1, x2)`` of
    pixel ``pix`` with squared distance below ``bound2``, ordered by (squared distance,
    index) as :meth:`~monoplane.geometry.neighbours.PointIndex.query` orders them, into
    ``best_d`` / ``best_i``; returns how many were found.

    The samples are looked up in the image tiles (:func:`sample_tiles`: ``start``, ``xyz``,
    ``ids``), by rows of tiles outwards from the pixel's, within the window :func:`_reach`
    gives for the radius, and from the next row of tiles on for the k-th best distance so
    far: a sample outside it lies farther in 3D.
    """
    k = best_d.shape[0]
    across = (w + TILE - 1) // TILE
    v, u = divmod(pix, w)
    z, ra, rb = _camera_radii(x0, x1, x2, scale, center)
    du, dv = _reach(np.sqrt(bound2) * scale, z, ra, rb, cam, w, h)
    found = 0
    worst = bound2  # candidates must come before (worst, worst_i)
    worst_i = -1
    reach = bound2  # the distance the window was sized for
    home = v // TILE
    d = 0
    while True:
        top, bottom = max(v - dv, 0) // TILE, min(v + dv, h - 1) // TILE
        if home - d < top and home + d > bottom:
            break
        for side in range(2 if d else 1):
            ty = home - d if side else home + d
            if ty < top or ty > bottom:
                continue
            for tx in range(max(u - du, 0) // TILE, min(u + du, w - 1) // TILE + 1):
                c = ty * across + tx
                for p in range(start[c], start[c + 1]):
                    e0 = xyz[p, 0] - x0
                    e1 = xyz[p, 1] - x1
                    e2 = xyz[p, 2] - x2
                    d2 = e0 * e0 + e1 * e1 + e2 * e2
                    t = ids[p]
                    if d2 > worst or (d2 == worst and (found < k or t >= worst_i)):
                        continue
                    found = _insert(best_d, best_i, found, d2, t, True)
                    if found == k:
                        worst, worst_i = best_d[k - 1], best_i[k - 1]
        d += 1
        if worst < reach:  # the window shrinks to the k-th best distance
            reach = worst
            du, dv = _reach(np.sqrt(worst) * scale, z, ra, rb, cam, w, h)
    return found


@inline
def _insert(best_d: np.ndarray, best_i: np.ndarray, found: int, d2: float, t: int,
            by_index: bool) -> int:
    """Insert candidate ``t`` at squared distance ``d2`` into the ascending (k,) lists
    ``best_d`` / ``best_i`` that hold ``found`` of at most k candidates (the k-th drops out
    when they are full); returns the new count. Among equal distances ``by_index`` puts the
    lower index first (the point index's order), else the candidate inserted first."""
    k = best_d.shape[0]
    y = min(found, k - 1)
    while y > 0 and (best_d[y - 1] > d2
                     or (by_index and best_d[y - 1] == d2 and best_i[y - 1] > t)):
        best_d[y] = best_d[y - 1]
        best_i[y] = best_i[y - 1]
        y -= 1
    best_d[y] = d2
    best_i[y] = t
    return min(found + 1, k)


@inline
def _closest_of(best_i: np.ndarray, found: int, labels: np.ndarray, planes: np.ndarray,
                x0: float, x1: float, x2: float) -> int:
    """Non-planar (0) when the nearest of the ``found`` candidates ``best_i`` is non-planar
    or there is none, else the candidates' planar label whose plane lies closest to
    ``(x0, x1, x2)`` (the first of equals; the nearest's label when there are no planes)."""
    if found == 0 or labels[best_i[0]] == 0:
        return 0
    if planes.shape[0] == 0:
        return labels[best_i[0]]
    best = 0
    best_r = np.inf
    for y in range(found):
        lab = labels[best_i[y]]
        if lab > 0:
            q = planes[lab - 1]
            r = abs(q[0] * x0 + q[1] * x1 + q[2] * x2 + q[3])
            if r < best_r:
                best_r = r
                best = lab
    return best


@kernel
def propagate_pixels(out: np.ndarray, point_labels: np.ndarray, all_pixels: np.ndarray,
                     all_points: np.ndarray, near: np.ndarray, points: np.ndarray,
                     pixels: np.ndarray, labels: np.ndarray, planes: np.ndarray,
                     indptr: np.ndarray, indices: np.ndarray, mixed: np.ndarray,
                     radius2: float, tolerance: float, k: int,
                     tiles: tuple[np.ndarray, np.ndarray, np.ndarray],
                     shape: tuple[int, int], cam: np.ndarray, scale: float, center: np.ndarray,
                     start: int, stop: int) -> np.ndarray:
    """Label the valid pixels ``start:stop`` from their image-nearest samples ``near`` (see
    :meth:`~monoplane.geometry.cloud.PlaneCloud.propagate`), in place.

    A sampled pixel keeps its sample's label. Any other pixel takes its sample's label when
    the sample is within the radius and non-planar, or within ``tolerance`` of its plane, or
    has no graph neighbour of another label (``mixed``, :func:`mixed_samples`: then every
    candidate below carries that label). Otherwise its candidates are the sample and the
    sample's graph neighbours within the radius: non-planar if the nearest of them is, else
    the closest plane among the planar labels of the ``k`` nearest. A pixel whose sample lies
    beyond the radius (across a depth jump) takes the same rule on its ``k`` nearest samples
    in 3D within the radius, found in the image (:func:`_nearest_in_image`), when ``cam``
    holds the intrinsics; with an empty ``cam`` it is left at 0 and returned.

    ``out`` (H * W,) int32 label image and ``point_labels`` (V,) int32 labels of the valid
    pixels are written at ``all_pixels[v]`` and ``v``; ``all_pixels`` (V,) int64 and
    ``all_points`` (V, 3) float64 the valid pixels and their normalised points, ``near``
    (V,) int64 the image-nearest sample, ``points`` (N, 3) float64, ``pixels`` (N,) int64 and
    ``labels`` (N,) int32 the samples, ``planes`` (P, 4) float64, ``indptr`` / ``indices``
    int64 the graph's adjacency, ``tiles`` the samples by image tile (:func:`sample_tiles`),
    ``shape`` (H, W), ``cam`` (3, 3) float64 intrinsics (or (0, 3)), ``scale`` and
    ``center`` the normalisation. Returns the (G,) int64 rows ``v`` left for a point index.
    """
    h, w = shape
    tile_start, tile_xyz, tile_ids = tiles
    in_image = cam.shape[0] == 3
    gap = np.empty(0 if in_image else stop - start, dtype=np.int64)
    n_gap = 0
    best_d = np.empty(k)
    best_i = np.empty(k, dtype=np.int64)
    no_planes = planes.shape[0] == 0
    for v in range(start, stop):
        s = near[v]
        pix = all_pixels[v]
        lab = labels[s]
        if pixels[s] == pix:  # a sampled pixel keeps its own label
            out[pix] = lab
            point_labels[v] = lab
            continue
        x0, x1, x2 = all_points[v, 0], all_points[v, 1], all_points[v, 2]
        d2 = (x0 - points[s, 0]) ** 2 + (x1 - points[s, 1]) ** 2 + (x2 - points[s, 2]) ** 2
        if d2 > radius2:
            lab = 0
            if in_image:
                found = _nearest_in_image(pix, x0, x1, x2, tile_start, tile_xyz, tile_ids, w,
                                          h, cam, scale, center, radius2, best_d, best_i)
                lab = _closest_of(best_i, found, labels, planes, x0, x1, x2)
            else:
                gap[n_gap] = v
                n_gap += 1
            out[pix] = lab
            point_labels[v] = lab
            continue
        if lab == 0 or no_planes or not mixed[s]:
            out[pix] = lab
            point_labels[v] = lab
            continue
        q = planes[lab - 1]
        if abs(q[0] * x0 + q[1] * x1 + q[2] * x2 + q[3]) <= tolerance:
            out[pix] = lab
            point_labels[v] = lab
            continue
        # The k nearest candidates within the radius, by insertion into a sorted list.
        found = 0
        for c in range(indptr[s] - 1, indptr[s + 1]):
            t = s if c < indptr[s] else indices[c]
            dt = (x0 - points[t, 0]) ** 2 + (x1 - points[t, 1]) ** 2 + (x2 - points[t, 2]) ** 2
            if dt > radius2 or (found == k and dt >= best_d[k - 1]):
                continue
            found = _insert(best_d, best_i, found, dt, t, False)
        lab = _closest_of(best_i, found, labels, planes, x0, x1, x2)
        out[pix] = lab
        point_labels[v] = lab
    return gap[:n_gap]


class SampleImage(NamedTuple):
    """Where a frame's samples lie in its image: what :func:`image_knn` needs to find their
    nearest neighbours through the image (:attr:`monoplane.geometry.cloud.PlaneCloud
    .sample_image`).

    Attributes
    ----------
    pixels : numpy.ndarray
        (N,) int64 flat pixel ``v * W + u`` of each sample.
    shape : tuple of int
        ``(H, W)`` of the image.
    intrinsics : numpy.ndarray
        (3, 3) float64 pinhole intrinsics (last row ``[0, 0, 1]``) the samples' camera-frame
        points ``X = z K^-1 [u, v, 1]`` were unprojected with.
    center : numpy.ndarray
        (3,) float64 centre and ``scale`` the float factor of the normalised points
        ``(X - center) / scale``.
    scale : float
    """

    pixels: np.ndarray
    shape: tuple[int, int]
    intrinsics: np.ndarray
    center: np.ndarray
    scale: float


def image_knn(points: np.ndarray, image: SampleImage, k: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``k`` nearest samples of every sample, found through the image, for those whose
    search stays within :data:`KNN_MAX_REACH` pixels.

    The answer of :meth:`monoplane.geometry.neighbours.PointIndex.query_indexed`, row for row:
    the same squared distances, ordered by (squared distance, index). Unlike that grid of 3D
    cells, whose width suits one density, the image holds the randomly drawn samples at an
    even density whatever their depth: on the TUM and SUN frames, whose depth spans 1-9 m,
    the grid's near cells hold a hundred points and a query took 3-4 times as long as on the
    living room's.

    Parameters
    ----------
    points : numpy.ndarray
        (N, 3) float64 normalised points of the samples.
    image : SampleImage
        Their pixels and the camera.
    k : int
        Neighbours per sample (the sample itself among them, at distance 0).

    Returns
    -------
    d2 : numpy.ndarray
        (N, k) float64 squared distances, ascending; rows of ``missed`` are not written.
    idx : numpy.ndarray
        (N, k) int64 sample indices.
    missed : numpy.ndarray
        (M,) int64 samples left to the point index: isolated ones, or all of them when the
        search gave up on the frame (see :data:`KNN_PROBE`).
    """
    h, w = image.shape
    n = points.shape[0]
    start, xyz, ids = sample_tiles(image.pixels, points, w, h, KNN_TILE)
    d2 = np.empty((n, k))
    idx = np.empty((n, k), dtype=np.int64)
    missed = np.empty(n, dtype=np.int64)
    cam = np.ascontiguousarray(image.intrinsics, dtype=np.float64)
    center = np.ascontiguousarray(image.center, dtype=np.float64)
    # Contiguous runs of tiles on parallel threads: each writes the rows of its own samples.
    parts = chunks(n, KNN_THREADED)
    counts: list[int] = run_threaded([
        partial(_image_knn, start, xyz, ids, image.pixels, w, h, cam, float(image.scale),
                center, int(k), a, b, d2, idx, missed[a:b])
        for a, b in parts])
    if min(counts) < 0:
        return d2, idx, np.arange(n, dtype=np.int64)
    return d2, idx, np.concatenate([missed[a:a + c]
                                    for (a, _), c in zip(parts, counts, strict=True)])


@inline
def _kth_smallest(values: np.ndarray, m: int, best: np.ndarray) -> float:
    """The ``k = len(best)``-th smallest of ``values[:m]`` (m >= k), by insertion into
    ``best`` (overwritten)."""
    k = best.shape[0]
    best[:] = np.inf
    for a in range(m):
        x = values[a]
        if x < best[k - 1]:
            y = k - 1
            while y > 0 and best[y - 1] > x:
                best[y] = best[y - 1]
                y -= 1
            best[y] = x
    return best[k - 1]


@inline
def _window_scan(start: np.ndarray, xyz: np.ndarray, ids: np.ndarray, w: int, h: int,
                 u: int, v: int, du: int, dv: int, qx: float, qy: float, qz: float,
                 limit: float, kept_d2: np.ndarray, kept_i: np.ndarray) -> tuple[int, int]:
    """The samples of the tiles that cover the pixels ``u ± du``, ``v ± dv`` within squared
    distance ``limit`` of ``(qx, qy, qz)``, into ``kept_d2`` / ``kept_i``: returns how many,
    and how many the tiles hold. (The tile's side is the constant :data:`KNN_TILE`: divisions
    by it compile to shifts.)"""
    across = (w + KNN_TILE - 1) // KNN_TILE
    kept = m = 0
    for ty in range(max(v - dv, 0) // KNN_TILE, min(v + dv, h - 1) // KNN_TILE + 1):
        row = ty * across
        a0 = start[row + max(u - du, 0) // KNN_TILE]
        a1 = start[row + min(u + du, w - 1) // KNN_TILE + 1]
        for p in range(a0, a1):
            # candidate - query, as the point index computes it (the same bits)
            dx = xyz[p, 0] - qx
            dy = xyz[p, 1] - qy
            dz = xyz[p, 2] - qz
            d2 = dx * dx + dy * dy + dz * dz
            kept_d2[kept] = d2
            kept_i[kept] = ids[p]
            kept += d2 <= limit
        m += a1 - a0
    return kept, m


@kernel
def _image_knn(start: np.ndarray, xyz: np.ndarray, ids: np.ndarray, pixels: np.ndarray,
               w: int, h: int, cam: np.ndarray, scale: float, center: np.ndarray, k: int,
               lo: int, hi: int, out_d2: np.ndarray, out_i: np.ndarray, missed: np.ndarray
               ) -> int:
    """:func:`image_knn` of the samples at tile-sorted positions ``[lo, hi)``
    (:func:`sample_tiles` with :data:`KNN_TILE`: ``start``, ``xyz``, ``ids``); writes rows
    ``ids[p]`` of the (N, k) ``out_d2`` / ``out_i``, lists the samples left to the point
    index in ``missed`` and returns how many, or -1 when it gave up (:data:`KNN_PROBE`).

    A sample's window is sized for a squared distance ``limit`` (:func:`_reach`): every
    sample within it lies inside, so when at least k of the window's samples are within
    ``limit`` the k nearest are among them, and they are ranked as
    :func:`monoplane.geometry.neighbours._cell_knn` ranks its candidates (without
    data-dependent branches). The first limit is :data:`KNN_GROWTH` times the previous
    sample's k-th squared distance (the first sample of a run gets a window of two tiles and
    no certificate, twice as wide while it holds fewer than k samples); a window with fewer
    than k within its limit gives the next one the k-th smallest distance it holds, which
    holds k; one with fewer than k samples at all, four times the limit.
    """
    n = ids.shape[0]
    kept_d2 = np.empty(n + 8)
    kept_i = np.empty(n + 8, dtype=np.int64)
    bd = np.empty(k + 1)  # the last slot takes every rank past the k-th
    bi = np.empty(k + 1, dtype=np.int64)
    prev = np.inf
    count = scanned = 0
    for p0 in range(lo, hi):
        searched = p0 - lo
        if searched >= KNN_PROBE and (KNN_MISS_SHARE * count > searched
                                      or scanned > KNN_BUDGET * searched):
            return -1
        qx, qy, qz = xyz[p0, 0], xyz[p0, 1], xyz[p0, 2]
        v, u = divmod(pixels[ids[p0]], w)
        z, ra, rb = _camera_radii(qx, qy, qz, scale, center)
        limit = prev * KNN_GROWTH
        certified = False
        du = dv = 2 * KNN_TILE
        if limit < np.inf:
            ru, rv = _reach(np.sqrt(limit) * scale, z, ra, rb, cam, w, h)
            if ru <= KNN_MAX_REACH and rv <= KNN_MAX_REACH:
                du, dv, certified = ru, rv, True
        done = False
        for _ in range(3):
            kept, m = _window_scan(start, xyz, ids, w, h, u, v, du, dv, qx, qy, qz, limit,
                                   kept_d2, kept_i)
            scanned += m
            if certified and kept >= k:
                if kept > 4 * k:  # a wide window: keep the k-th best and its ties to rank
                    t = _kth_smallest(kept_d2, kept, bd[:k])
                    c = 0
                    for a in range(kept):
                        kept_d2[c] = kept_d2[a]
                        kept_i[c] = kept_i[a]
                        c += kept_d2[a] <= t
                    kept = c
                # Padded to whole vectors for the ranking loop; the pads rank after every one.
                padded = (kept + 7) // 8 * 8
                kept_d2[kept:padded] = np.inf
                kept_i[kept:padded] = n
                for a in range(kept):
                    da = kept_d2[a]
                    ia = kept_i[a]
                    rank = 0
                    for b in range(padded):
                        rank += (kept_d2[b] < da) | ((kept_d2[b] == da) & (kept_i[b] < ia))
                    slot = min(rank, k)
                    bd[slot] = da
                    bi[slot] = ia
                done = True
                break
            if m >= k:
                if kept < m:  # the window's distances again, all of them (a rare case)
                    _window_scan(start, xyz, ids, w, h, u, v, du, dv, qx, qy, qz, np.inf,
                                 kept_d2, kept_i)
                limit = _kth_smallest(kept_d2, m, bd[:k])
            elif certified:
                limit *= 4.0
            else:  # no limit yet (a run's first sample) and fewer than k here: a wider one
                du, dv = 2 * du, 2 * dv
                if du > KNN_MAX_REACH or dv > KNN_MAX_REACH:
                    break
                continue
            du, dv = _reach(np.sqrt(limit) * scale, z, ra, rb, cam, w, h)
            certified = True
            if du > KNN_MAX_REACH or dv > KNN_MAX_REACH:
                break
        if done:
            prev = bd[k - 1]
            out_d2[ids[p0]] = bd[:k]
            out_i[ids[p0]] = bi[:k]
        else:
            missed[count] = ids[p0]
            count += 1
    return count
