"""Is a segmented plane really flat? The spread of the normal cue over its pixels.

The single-view stage paints planes on curved surfaces too (a sphere, a cylinder): RANSAC
accepts points within ``ε_n`` of a hypothesis normal, and the depth of a small curved patch is
close to a plane within the depth noise. The normal cue tells them apart. On a plane the
normals scatter around one direction by the cue's noise only; on a curved patch they turn
with position, so they spread far more than the noise. :func:`normal_spread_deg` measures the
spread of each plane's normals around their dominant direction (a mode, not the mean, so a
plane that also took in a strip of a neighbouring surface still measures its own noise), and
:func:`noise_floor_deg` the spread shared by most of a scene's planar pixels, against which
the fuser compares it (``fuser.max_extra_spread_deg``).

Why the spread and not a fit of the normal field as a linear function of position: on the
synthetic walks (640x480) the linear model's predicted turn across the plane overlapped
between curved and flat planes (flat planes that took in a strip of a neighbour have a large
fitted trend), while the spread around the mode kept them apart at both cue levels (see
docs/multiview.md, "Planes on curved surfaces").

Coordinates: normals are unit vectors in the camera frame (OpenCV axes); angles in degrees.
"""

from __future__ import annotations

import cv2
import numpy as np

from monoplane.jit import kernel

#: Fewest sampled interior pixels a plane needs for its spread to be measured.
MIN_SAMPLES = 30
#: Smallest quadric residual :func:`quadric_ratio` divides by, as a fraction of the extent.
QUADRIC_FLOOR = 3e-5


def interior_labels(labels: np.ndarray, radius: int) -> np.ndarray:
    """Labels with every pixel within ``radius`` px of another label (or of 0) set to 0.

    The normal cue is blurred across boundaries, so the pixels next to a neighbouring surface
    carry a mix of both surfaces' normals; only the interior measures the plane's own spread.

    Parameters
    ----------
    labels : numpy.ndarray
        (H, W) int label map, 0 = non-planar, values below 65536.
    radius : int
        Erosion radius in pixels (0 keeps every pixel).

    Returns
    -------
    numpy.ndarray
        (H, W) int32 label map.
    """
    labels = np.asarray(labels)
    if radius <= 0:
        return labels.astype(np.int32)
    kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    lab16 = labels.astype(np.uint16)
    # A pixel is interior when its whole window holds one label: the window's min equals max.
    same = cv2.erode(lab16, kernel, borderType=cv2.BORDER_REPLICATE) == cv2.dilate(
        lab16, kernel, borderType=cv2.BORDER_REPLICATE)
    return np.where(same, labels, 0).astype(np.int32)


def interior_samples(labels: np.ndarray, depth: np.ndarray, radius: int, step: int
                     ) -> np.ndarray:
    """:func:`interior_labels` at every ``step``-th row and column, 0 where the depth is not
    positive: ``(interior_labels(labels, radius) * (depth > 0))[::step, ::step].ravel()``
    without the full-resolution passes.

    Parameters
    ----------
    labels : numpy.ndarray
        (H, W) int label map, 0 = non-planar, values below 65536.
    depth : numpy.ndarray
        (H, W) depth, positive where valid.
    radius : int
        Erosion radius in pixels (0 keeps every pixel).
    step : int
        Sampling step, >= 1.

    Returns
    -------
    numpy.ndarray
        (ceil(H / step) * ceil(W / step),) int32 labels of the sampled pixels, row by row.
    """
    return _interior_samples(np.ascontiguousarray(labels, dtype=np.int32),
                             np.ascontiguousarray(depth, dtype=np.float32), max(int(radius), 0),
                             int(step))


@kernel
def _interior_samples(labels: np.ndarray, depth: np.ndarray, radius: int, step: int
                      ) -> np.ndarray:
    """:func:`interior_samples` of (H, W) int32 labels and float32 depth. A window (clipped
    to the image, as the erosion's replicated border) holds one label when each of its rows
    does and its centre column does: runs of equal labels along each row, then along each
    sampled column, tell both without visiting the window's pixels. Labels compare modulo
    65536, as the erosion's uint16 image does."""
    h, w = labels.shape
    rows, cols = (h + step - 1) // step, (w + step - 1) // step
    # flat[y, j]: row y holds one label across the window of sampled column j.
    flat = np.empty((h, cols), dtype=np.bool_)
    start = np.empty(w, dtype=np.int64)  # first column of the run of equal labels at x
    for y in range(h):
        s = 0
        for x in range(1, w):
            if (labels[y, x] - labels[y, x - 1]) % 65536 != 0:
                s = x
            start[x] = s
        start[0] = 0
        for j in range(cols):
            x = j * step
            flat[y, j] = start[min(x + radius, w - 1)] <= max(x - radius, 0)
    out = np.zeros(rows * cols, dtype=np.int32)
    first = np.empty(h, dtype=np.int64)  # first row of the run of flat, equal rows at y
    for j in range(cols):
        x = j * step
        s = 0
        for y in range(h):
            if not flat[y, j]:
                s = y + 1
            elif y > s and (labels[y, x] - labels[y - 1, x]) % 65536 != 0:
                s = y
            first[y] = s
        for i in range(rows):
            y = i * step
            if depth[y, x] > 0 and first[min(y + radius, h - 1)] <= max(y - radius, 0):
                out[i * cols + j] = labels[y, x]
    return out


def normal_spread_deg(normals: np.ndarray, labels: np.ndarray, num_planes: int,
                      radius: int = 1, step: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Median angle between each plane's pixel normals and their dominant direction.

    The dominant direction starts at the component-wise median of the normals and is refined
    three times as the mean of the normals within ``max(2 × median angle, 3°)`` of it, a
    mean-shift step that settles on the mode of the normals.

    Parameters
    ----------
    normals : numpy.ndarray
        (H, W, 3) unit normals, camera frame; zero vectors mark invalid pixels.
    labels : numpy.ndarray
        (H, W) int label map, 0 = non-planar, 1..P planes.
    num_planes : int
        P.
    radius : int
        Pixels within this distance of another label are left out (:func:`interior_labels`).
    step : int
        Use every ``step``-th row and column (speed at high resolution).

    Returns
    -------
    spread, samples : numpy.ndarray
        As :func:`spread_of_groups` returns them, over the sampled interior pixels.
    """
    lab = interior_labels(labels, radius)[::step, ::step].ravel()
    n = np.asarray(normals, dtype=np.float64)[::step, ::step].reshape(-1, 3)
    return spread_of_groups(n, lab, num_planes)


def _padded(values: np.ndarray, labels: np.ndarray, num_planes: int,
            max_samples: int | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The members of every group with at least :data:`MIN_SAMPLES` of them, one row a group.

    Parameters
    ----------
    values : numpy.ndarray
        (M, 3) per-member vectors.
    labels, num_planes, max_samples
        The groups, as for :func:`spread_of_groups`.

    Returns
    -------
    rows : numpy.ndarray
        (G, L, 3) float64 members, NaN after each group's count.
    counts : numpy.ndarray
        (P,) int64 members of every group (sampled), measured or not.
    plane : numpy.ndarray
        (G,) int64 plane index (label - 1) of each row.
    """
    order, starts = _grouped(np.ascontiguousarray(np.asarray(labels).ravel(), dtype=np.int64),
                             int(num_planes))
    counts = np.zeros(num_planes, dtype=np.int64)
    members = []
    for p in np.flatnonzero(np.diff(starts)):
        idx = order[starts[p]:starts[p + 1]]
        size = len(idx)
        if max_samples is not None and size > max_samples:
            idx = idx[np.linspace(0, size - 1, max_samples).astype(np.int64)]
        counts[p] = len(idx)
        if len(idx) >= MIN_SAMPLES:
            members.append((int(p), idx))
    length = max((len(idx) for _, idx in members), default=0)
    rows = np.full((len(members), length, 3), np.nan)
    for g, (_, idx) in enumerate(members):
        rows[g, :len(idx)] = values[idx]
    return rows, counts, np.array([p for p, _ in members], dtype=np.int64)


@kernel
def _grouped(labels: np.ndarray, num_planes: int) -> tuple[np.ndarray, np.ndarray]:
    """The members of labels 1..P grouped by label, each group in index order (a counting
    sort: what a stable argsort of the labels gives). ``labels`` (M,) int64. Returns the
    (K,) int64 member indices and the (P + 1,) int64 start of each label's group (label
    ``p + 1`` at ``order[starts[p]:starts[p + 1]]``)."""
    starts = np.zeros(num_planes + 1, dtype=np.int64)
    for v in range(labels.shape[0]):
        if 0 < labels[v] <= num_planes:
            starts[labels[v]] += 1
    for p in range(num_planes):
        starts[p + 1] += starts[p]
    fill = starts[:-1].copy()
    order = np.empty(starts[num_planes], dtype=np.int64)
    for v in range(labels.shape[0]):
        if 0 < labels[v] <= num_planes:
            order[fill[labels[v] - 1]] = v
            fill[labels[v] - 1] += 1
    return order, starts


def _row_median(a: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Median of each row's first ``count`` values ((G, L) with NaN after them), as
    ``numpy.median`` gives it (the mean of the two middle values of an even count)."""
    s = np.sort(a, axis=1)  # NaN sort last
    rows = np.arange(a.shape[0])
    return 0.5 * (s[rows, (count - 1) // 2] + s[rows, count // 2])


def spread_of_groups(normals: np.ndarray, labels: np.ndarray, num_planes: int,
                     max_samples: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Median angle between each group's normals and their dominant direction.

    The dominant direction starts at the component-wise median of the normals and is refined
    three times as the mean of the normals within ``max(2 × median angle, 3°)`` of it, a
    mean-shift step that settles on the mode of the normals. The angle is unsigned in the
    sense of a plane: a normal and its opposite are one direction. All groups are computed
    together, one row each.

    Parameters
    ----------
    normals : numpy.ndarray
        (M, 3) unit normals, any frame; rows of zeros are unknown and left out.
    labels : numpy.ndarray
        (M,) int group of each normal, 0 = none, 1..P.
    num_planes : int
        P.
    max_samples : int, optional
        Use at most this many evenly spaced members of a group.

    Returns
    -------
    spread : numpy.ndarray
        (P,) float64 degrees; NaN where a group has fewer than :data:`MIN_SAMPLES` normals.
    samples : numpy.ndarray
        (P,) int64 number of normals each spread was measured on.
    """
    spread = np.full(num_planes, np.nan)
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    lab = np.where(np.einsum("ij,ij->i", n, n) > 0.5, np.asarray(labels).ravel(), 0)
    x, samples, plane = _padded(n, lab, num_planes, max_samples)
    if plane.size == 0:
        return spread, samples
    count = samples[plane]
    filled = np.nan_to_num(x)
    # One side for all: flip each normal towards its group's first principal direction.
    axis = np.linalg.eigh(filled.transpose(0, 2, 1) @ filled)[1][:, :, -1]
    x = x * np.where(filled @ axis[..., None] < 0, -1.0, 1.0)
    centre = np.stack([_row_median(x[..., c], count) for c in range(3)], axis=1)

    def angles(c: np.ndarray) -> np.ndarray:
        c = c / np.maximum(np.linalg.norm(c, axis=1, keepdims=True), 1e-12)
        return np.degrees(np.arccos(np.clip((x @ c[..., None])[..., 0], -1.0, 1.0)))

    for _ in range(3):
        angle = angles(centre)
        near = angle <= np.maximum(2.0 * _row_median(angle, count), 3.0)[:, None]
        centre = np.where(near[..., None], x, 0.0).sum(axis=1) / near.sum(axis=1)[:, None]
    spread[plane] = _row_median(angles(centre), count)
    return spread, samples


def quadric_ratio(points: np.ndarray, labels: np.ndarray, num_planes: int,
                  max_samples: int | None = None) -> np.ndarray:
    """How much better a quadric fits each group's points than a plane: RMS ratio.

    In each group's principal frame (origin at the centroid, ``w`` along the smallest
    principal axis, ``u, v`` in the plane) the heights ``w`` are fitted by ``a + b u + c v``
    and by that plus ``d u² + e u v + f v²``, in least squares; the ratio is the plane's RMS
    residual over the quadric's. About 1 on a plane with noise (the three extra terms absorb
    next to nothing), large on a cap of a sphere or a strip of a cylinder once the bend
    exceeds the noise.

    Parameters
    ----------
    points : numpy.ndarray
        (M, 3) points, any frame and unit.
    labels, num_planes, max_samples
        The groups, as for :func:`spread_of_groups`.

    Returns
    -------
    numpy.ndarray
        (P,) float64 ratios, NaN where a group has fewer than :data:`MIN_SAMPLES` points.
    """
    out = np.full(num_planes, np.nan)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    lab = np.where(np.isfinite(pts).all(axis=1), np.asarray(labels).ravel(), 0)
    x, samples, plane = _padded(pts, lab, num_planes, max_samples)
    if plane.size == 0:
        return out
    count = samples[plane].astype(np.float64)
    valid = ~np.isnan(x[..., 0])
    x = np.nan_to_num(x - np.nansum(x, axis=1, keepdims=True) / count[:, None, None])
    # Scale-free: the fits are done in units of each group's extent.
    x /= np.maximum(np.abs(x).max(axis=(1, 2)), 1e-300)[:, None, None]
    basis = np.linalg.eigh(x.transpose(0, 2, 1) @ x)[1]
    frame = x @ basis
    w, u, v = frame[..., 0], frame[..., 2], frame[..., 1]
    # In the principal frame the best plane is w = 0 up to rounding (the centroid and the
    # smallest axis are its least-squares solution), so its residual is w itself.
    quad = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=-1) * valid[..., None]
    # Normal equations on coordinates within [-1, 1]; the pseudo-inverse copes with a group
    # whose points lie on a line.
    quad_t = quad.transpose(0, 2, 1)
    coef = np.linalg.pinv(quad_t @ quad) @ (quad_t @ w[..., None])
    r_quad = w - (quad @ coef)[..., 0]
    e_lin = np.sqrt((w ** 2).sum(axis=1) / count)
    e_quad = np.sqrt((r_quad ** 2).sum(axis=1) / count)
    # Residuals below QUADRIC_FLOOR of the extent are rounding (float32 depth is quantised in
    # a pattern a quadric partly fits), not a bend: an exact plane stays flat.
    out[plane] = e_lin / np.maximum(e_quad, QUADRIC_FLOOR)
    return out


def noise_floor_deg(spreads: np.ndarray, weights: np.ndarray) -> float:
    """The normal cue's noise: the weighted median of plane spreads (NaNs left out).

    Weighted by the pixels measured, it is the spread of the pixel in the middle: in indoor
    scenes most planar pixels lie on flat walls, floors and tables, so this is the spread the
    cue shows on a flat surface, whatever its noise level.

    Parameters
    ----------
    spreads : numpy.ndarray
        (P,) degrees, from :func:`normal_spread_deg` (of one or several views).
    weights : numpy.ndarray
        (P,) pixels measured.

    Returns
    -------
    float
        Degrees; NaN when no spread was measured.
    """
    spreads = np.asarray(spreads, dtype=np.float64).ravel()
    weights = np.asarray(weights, dtype=np.float64).ravel()
    ok = np.isfinite(spreads) & (weights > 0)
    if not np.any(ok):
        return float("nan")
    order = np.argsort(spreads[ok])
    cum = np.cumsum(weights[ok][order])
    return float(spreads[ok][order][np.searchsorted(cum, 0.5 * cum[-1])])
