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

#: Fewest sampled interior pixels a plane needs for its spread to be measured.
MIN_SAMPLES = 30


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
    spread : numpy.ndarray
        (P,) float64 degrees; NaN where a plane has fewer than :data:`MIN_SAMPLES` samples.
    samples : numpy.ndarray
        (P,) int64 number of pixels each spread was measured on.
    """
    spread = np.full(num_planes, np.nan)
    samples = np.zeros(num_planes, dtype=np.int64)
    if num_planes == 0:
        return spread, samples
    lab = interior_labels(labels, radius)[::step, ::step].ravel()
    n = np.asarray(normals, dtype=np.float64)[::step, ::step].reshape(-1, 3)
    ok = (lab > 0) & (np.einsum("ij,ij->i", n, n) > 0.5)
    lab, n = lab[ok], n[ok]
    order = np.argsort(lab, kind="stable")
    ids, starts = np.unique(lab[order], return_index=True)
    for p, idx in zip(ids, np.split(order, starts[1:]), strict=True):
        samples[p - 1] = len(idx)
        if len(idx) < MIN_SAMPLES:
            continue
        x = n[idx]
        centre = np.median(x, axis=0)
        for _ in range(3):
            centre /= max(np.linalg.norm(centre), 1e-12)
            angle = np.degrees(np.arccos(np.clip(x @ centre, -1.0, 1.0)))
            near = angle <= max(2.0 * float(np.median(angle)), 3.0)
            centre = x[near].mean(axis=0)
        centre /= max(np.linalg.norm(centre), 1e-12)
        spread[p - 1] = float(np.median(np.degrees(np.arccos(np.clip(x @ centre, -1.0, 1.0)))))
    return spread, samples


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
