"""Labels carried from a cloud's samples to the points or pixels left out of it: the
nearest samples vote, and among their planes the closest one wins (used by
:meth:`monoplane.geometry.cloud.PlaneCloud.propagate`).
"""

from __future__ import annotations

import numpy as np

from monoplane.jit import kernel


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
def propagate_labels(all_points: np.ndarray, near: np.ndarray, points: np.ndarray,
                     labels: np.ndarray, planes: np.ndarray, indptr: np.ndarray,
                     indices: np.ndarray, radius2: float, tolerance: float,
                     k: int) -> tuple[np.ndarray, np.ndarray]:
    """Label every valid pixel from its image-nearest sample ``near`` (see
    :meth:`~monoplane.geometry.cloud.PlaneCloud.propagate`).

    A pixel takes its sample's label when the sample is within the radius and non-planar or
    within ``tolerance`` of its plane. Otherwise its candidates are the sample and the
    sample's graph neighbours within the radius: non-planar if the nearest of them is, else
    the closest plane among the planar labels of the ``k`` nearest. Returns the (V,) int32
    labels and a (V,) bool mask of pixels whose sample is beyond the radius (left at 0).
    """
    n_pix = all_points.shape[0]
    full = np.zeros(n_pix, dtype=np.int32)
    gap = np.zeros(n_pix, dtype=np.bool_)
    best_d = np.empty(k)
    best_i = np.empty(k, dtype=np.int64)
    for v in range(n_pix):
        s = near[v]
        x0, x1, x2 = all_points[v, 0], all_points[v, 1], all_points[v, 2]
        d2 = (x0 - points[s, 0]) ** 2 + (x1 - points[s, 1]) ** 2 + (x2 - points[s, 2]) ** 2
        if d2 > radius2:
            gap[v] = True
            continue
        lab = labels[s]
        if lab == 0 or planes.shape[0] == 0:
            full[v] = lab
            continue
        q = planes[lab - 1]
        if abs(q[0] * x0 + q[1] * x1 + q[2] * x2 + q[3]) <= tolerance:
            full[v] = lab
            continue
        # The k nearest candidates within the radius, by insertion into a sorted list.
        found = 0
        for c in range(indptr[s] - 1, indptr[s + 1]):
            t = s if c < indptr[s] else indices[c]
            dt = (x0 - points[t, 0]) ** 2 + (x1 - points[t, 1]) ** 2 + (x2 - points[t, 2]) ** 2
            if dt > radius2 or (found == k and dt >= best_d[k - 1]):
                continue
            y = min(found, k - 1)
            while y > 0 and best_d[y - 1] > dt:
                best_d[y] = best_d[y - 1]
                best_i[y] = best_i[y - 1]
                y -= 1
            best_d[y] = dt
            best_i[y] = t
            found = min(found + 1, k)
        if labels[best_i[0]] == 0:
            continue
        best_r = np.inf
        for y in range(found):
            lab = labels[best_i[y]]
            if lab > 0:
                q = planes[lab - 1]
                r = abs(q[0] * x0 + q[1] * x1 + q[2] * x2 + q[3])
                if r < best_r:
                    best_r = r
                    full[v] = lab
    return full, gap
