"""Epipolar checks and refinement of a pose hypothesis from keypoint matches (relative depth).

Monocular depth warps; the epipolar geometry of keypoint matches does not depend on depth at
all. :func:`epipolar_support` counts the matches a pose explains, :func:`depth_disagreement`
measures how far the depths it triangulates stray from the views' own, and
:func:`refine_epipolar` refines its rotation and translation direction on its inliers.

Frames: OpenCV camera axes; pixel centres at integer coordinates; poses
``s·X_v = R·X_r + t`` (:class:`~monoplane.geometry.view_agreement.Hypothesis`).
"""

from __future__ import annotations

import numpy as np

from monoplane.geometry.alignment import sample_depth
from monoplane.geometry.view_agreement import Hypothesis, ViewGeometry


def _sampson(R: np.ndarray, t: np.ndarray, nr: np.ndarray, nv: np.ndarray) -> np.ndarray:
    """Sampson distances (normalised image units) of matches under ``E = [t]× R``."""
    tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    E = tx @ R
    Ex = nr @ E.T                 # E x_r
    Etx = nv @ E                  # Eᵀ x_v
    num = np.einsum("ij,ij->i", nv, Ex)
    den = Ex[:, 0] ** 2 + Ex[:, 1] ** 2 + Etx[:, 0] ** 2 + Etx[:, 1] ** 2
    return num / np.sqrt(np.maximum(den, 1e-300))


def _normalised(pixels: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(m, 3) homogeneous normalised image coordinates of (m, 2) pixels."""
    return np.c_[np.linalg.solve(K, np.c_[pixels, np.ones(len(pixels))].T).T[:, :2],
                 np.ones(len(pixels))]


def epipolar_support(hyp: Hypothesis, px_ref: np.ndarray, px_other: np.ndarray,
                     K_ref: np.ndarray, K_other: np.ndarray, threshold_px: float) -> int:
    """How many matches lie within ``threshold_px`` (Sampson distance, pixels) of the
    epipolar geometry of a pose: a count that depends on the rotation and the translation's
    direction only, not on any depth.

    Parameters
    ----------
    hyp : Hypothesis
        The pose (``t`` may have any non-zero length).
    px_ref, px_other : numpy.ndarray
        (m, 2) matched pixels in the reference and the other view.
    K_ref, K_other : numpy.ndarray
        (3, 3) intrinsics.
    threshold_px : float
        Inlier threshold in pixels.
    """
    norm_t = float(np.linalg.norm(hyp.t))
    if len(px_ref) == 0 or norm_t == 0.0:
        return 0
    focal = 0.5 * (K_ref[0, 0] + K_other[0, 0])
    d = _sampson(hyp.R, hyp.t / norm_t, _normalised(px_ref, K_ref), _normalised(px_other,
                                                                                  K_other))
    return int((np.abs(d) * focal < threshold_px).sum())


def depth_disagreement(hyp: Hypothesis, px_ref: np.ndarray, px_other: np.ndarray,
                       ref: ViewGeometry, other: ViewGeometry, threshold_px: float) -> float:
    """How far the depths a pose triangulates stray from the views' own relative depths.

    The matches within ``threshold_px`` of the pose's epipolar geometry are triangulated
    (unit baseline); in each view, the log-ratio of triangulated to given depth is a constant
    (the unknown scale) plus the depth's warp, so its median absolute deviation is a few
    percent under the right pose. Poses that explain the matches about as well but are
    degrees off (the rotation traded against the translation, as near-planar scenes allow)
    bend the triangulated depths and spread the ratio further. Lower is better.

    Parameters
    ----------
    hyp : Hypothesis
        The pose; only ``R`` and the direction of ``t`` are used.
    px_ref, px_other : numpy.ndarray
        (m, 2) matched pixels.
    ref, other : ViewGeometry
        The two views (their ``K`` and ``depth``, in any scale).
    threshold_px : float
        Epipolar inlier threshold in pixels.

    Returns
    -------
    float
        The sum over both views of the median absolute deviation of the log depth ratio;
        ``inf`` with fewer than 8 usable matches.
    """
    norm_t = float(np.linalg.norm(hyp.t))
    if len(px_ref) < 8 or norm_t == 0.0:
        return float("inf")
    t = hyp.t / norm_t
    nr, nv = _normalised(px_ref, ref.K), _normalised(px_other, other.K)
    focal = 0.5 * (ref.K[0, 0] + other.K[0, 0])
    inl = np.abs(_sampson(hyp.R, t, nr, nv)) * focal < threshold_px
    nr, nv = nr[inl], nv[inl]
    # Midpoint-free linear triangulation along each ray of the reference: z_r x_v (R x_r) + x_v
    # t = 0 in the cross-product sense, solved per match in least squares.
    a = np.cross(nv, nr @ hyp.R.T)
    b = -np.cross(nv, np.broadcast_to(t, nv.shape))
    with np.errstate(divide="ignore", invalid="ignore"):
        z_ref = np.einsum("ij,ij->i", a, b) / np.einsum("ij,ij->i", a, a)
    z_other = ((nr * z_ref[:, None]) @ hyp.R.T + t)[:, 2]
    d_ref = sample_depth(ref.depth, px_ref[inl])
    d_other = sample_depth(other.depth, px_other[inl])
    ok = (z_ref > 0) & (z_other > 0) & (d_ref > 0) & (d_other > 0) & np.isfinite(z_ref)
    if ok.sum() < 8:
        return float("inf")
    spread = 0.0
    for z, d in ((z_ref[ok], d_ref[ok]), (z_other[ok], d_other[ok])):
        ratio = np.log(z / d)
        spread += float(np.median(np.abs(ratio - np.median(ratio))))
    return spread


def refine_epipolar(hyp: Hypothesis, px_ref: np.ndarray, px_other: np.ndarray,
                    K_ref: np.ndarray, K_other: np.ndarray, threshold_px: float = 2.0,
                    min_inliers: int = 8) -> tuple[Hypothesis, int] | None:
    """Refine the rotation and translation direction of a hypothesis on its epipolar inliers.

    Monocular depth warps, so a pose fitted on depth-lifted points inherits the warp; the
    epipolar geometry of the keypoint matches does not depend on depth at all. The matches
    within ``threshold_px`` (Sampson distance) of the hypothesis's epipolar geometry are its
    inliers; the rotation and the translation's direction then minimise their Sampson
    distances (``scipy.optimize.least_squares``, soft L1), and the translation keeps its
    length (which only depth can give).

    Parameters
    ----------
    hyp : Hypothesis
        Starting pose.
    px_ref, px_other : numpy.ndarray
        (m, 2) matched pixels in each view.
    K_ref, K_other : numpy.ndarray
        (3, 3) intrinsics.
    threshold_px : float
        Inlier threshold in pixels.
    min_inliers : int
        Fewest inliers to refine on.

    Returns
    -------
    (Hypothesis, int) or None
        The refined hypothesis and its inlier count, or None with too few inliers.
    """
    import cv2
    from scipy.optimize import least_squares

    norm_t = float(np.linalg.norm(hyp.t))
    if len(px_ref) < min_inliers or norm_t == 0.0:
        return None
    nr, nv = _normalised(px_ref, K_ref), _normalised(px_other, K_other)
    focal = 0.5 * (K_ref[0, 0] + K_other[0, 0])
    thr = threshold_px / focal
    inl = np.abs(_sampson(hyp.R, hyp.t / norm_t, nr, nv)) < thr
    if inl.sum() < min_inliers:
        return None
    t0 = hyp.t / norm_t

    def pose(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        R = cv2.Rodrigues(x[:3])[0] @ hyp.R
        t = t0 + x[3:]
        return R, t / np.linalg.norm(t)

    def residuals(x: np.ndarray) -> np.ndarray:
        R, t = pose(x)
        # The last residual pins the translation update orthogonal to t0 (its length is
        # the scale's, not the epipolar geometry's).
        return np.r_[_sampson(R, t, nr[inl], nv[inl]) * focal, 10.0 * (x[3:] @ t0)]

    sol = least_squares(residuals, np.zeros(6), loss="soft_l1", f_scale=threshold_px,
                        max_nfev=50)
    R, t = pose(sol.x)
    n_in = int((np.abs(_sampson(R, t, nr, nv)) < thr).sum())
    return Hypothesis(R=R, t=t * norm_t, s=hyp.s, source=hyp.source, support=hyp.support), n_in
