"""Feature-based relative pose of two views that structure from motion could not connect.

SIFT keypoints (OpenCV, :func:`sift_features`) matched with Lowe's ratio test and a mutual
check (:func:`match_features`). An essential matrix with OpenCV's USAC MAGSAC++ and the
cheirality check (``recoverPose``) gives the rotation and the translation direction
(:func:`essential_pose`); :func:`pnp_pose` is its counterpart for short baselines. The
translation's length, which two views alone cannot give, comes from the monocular depth: the
inliers lifted with the reference view's scale-aligned depth must reproject onto their
matches, which fixes the length per point (median over the inliers); the second view's own
depth scale follows from the same points seen from it.

Frames: ``x_j = R x_i + t`` with OpenCV camera axes; pixel centres at integer coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from monoplane.geometry.alignment import sample_depth


@dataclass(frozen=True)
class FallbackPose:
    """Result of :func:`essential_pose` or :func:`pnp_pose`.

    Attributes
    ----------
    R, t : numpy.ndarray
        (3, 3), (3,) pose of view ``j`` relative to view ``i`` (``x_j = R x_i + t``), ``t`` in
        the units of the reference depth.
    depth_scale_j : float
        Factor bringing view ``j``'s depth into the same units.
    inliers : int
        Essential-matrix inliers used.
    matches : int
        Putative matches before the robust fit.
    estimator : str
        ``"essential"`` or ``"pnp"``.
    """

    R: np.ndarray
    t: np.ndarray
    depth_scale_j: float
    inliers: int
    matches: int
    estimator: str = "essential"


def _gray(rgb: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2GRAY)


@dataclass(frozen=True)
class Features:
    """SIFT keypoints of one image: (n, 2) float64 ``(u, v)`` pixels and (n, 128) float32
    descriptors."""

    pixels: np.ndarray
    descriptors: np.ndarray


def sift_features(rgb: np.ndarray, max_features: int = 4000) -> Features:
    """OpenCV SIFT keypoints and descriptors of an (H, W, 3) uint8 image."""
    kp, des = cv2.SIFT_create(nfeatures=max_features).detectAndCompute(_gray(rgb), None)
    if des is None or len(kp) < 2:
        return Features(np.zeros((0, 2)), np.zeros((0, 128), np.float32))
    return Features(np.array([k.pt for k in kp], dtype=np.float64), des)


def match_features(fi: Features, fj: Features, ratio: float = 0.8
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Mutual ratio-test matches of two images' SIFT features.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        (m, 2) float64 pixel coordinates ``(u, v)`` in view ``i`` and in view ``j``.
    """
    if len(fi.pixels) < 2 or len(fj.pixels) < 2:
        return np.zeros((0, 2)), np.zeros((0, 2))
    bf = cv2.BFMatcher(cv2.NORM_L2)
    fwd = bf.knnMatch(fi.descriptors, fj.descriptors, k=2)
    back = {m.queryIdx: m.trainIdx for m in bf.match(fj.descriptors, fi.descriptors)}
    pairs = [(m.queryIdx, m.trainIdx) for m, n in (p for p in fwd if len(p) == 2)
             if m.distance < ratio * n.distance and back.get(m.trainIdx) == m.queryIdx]
    if not pairs:
        return np.zeros((0, 2)), np.zeros((0, 2))
    idx = np.array(pairs)
    return fi.pixels[idx[:, 0]], fj.pixels[idx[:, 1]]


def pnp_pose(pi: np.ndarray, pj: np.ndarray, K_i: np.ndarray, depth_i: np.ndarray,
              K_j: np.ndarray, depth_j: np.ndarray, min_inliers: int) -> FallbackPose | None:
    """Pose of j from view i's depth-lifted keypoints and their matches in j (PnP RANSAC)."""
    d_i = sample_depth(depth_i, pi)
    ok = d_i > 0
    if ok.sum() < min_inliers:
        return None
    ni = cv2.undistortPoints(pi[ok].reshape(-1, 1, 2), K_i, None).reshape(-1, 2)
    X = np.concatenate([ni, np.ones((len(ni), 1))], axis=1) * d_i[ok, None]
    done, rvec, tvec, inliers = cv2.solvePnPRansac(
        X, pj[ok].reshape(-1, 1, 2), K_j, None, reprojectionError=2.0, iterationsCount=500,
        confidence=0.999, flags=cv2.SOLVEPNP_SQPNP)
    if not done or inliers is None or len(inliers) < min_inliers:
        return None
    R = cv2.Rodrigues(rvec)[0]
    t = tvec.reshape(3)
    idx = inliers.reshape(-1)
    z_j = (X[idx] @ R.T + t)[:, 2]
    d_j = sample_depth(depth_j, pj[ok][idx])
    good = (z_j > 0) & (d_j > 0)
    if good.sum() < min_inliers:
        return None
    return FallbackPose(R=R, t=t, depth_scale_j=float(np.median(z_j[good] / d_j[good])),
                        inliers=int(len(idx)), matches=int(len(pi)), estimator="pnp")


def essential_pose(pi: np.ndarray, pj: np.ndarray, K_i: np.ndarray, depth_i: np.ndarray,
                    K_j: np.ndarray, depth_j: np.ndarray, min_inliers: int,
                    threshold_px: float = 1.0, estimator: str = "magsac") -> FallbackPose | None:
    """Essential matrix rotation and direction, baseline from the depth.

    ``estimator`` is the robust fit: ``"magsac"`` (OpenCV's USAC MAGSAC++), ``"accurate"``
    (USAC with local optimisation) or ``"ransac"``; ``threshold_px`` its inlier threshold.
    """
    ni = cv2.undistortPoints(pi.reshape(-1, 1, 2), K_i, None).reshape(-1, 2)
    nj = cv2.undistortPoints(pj.reshape(-1, 1, 2), K_j, None).reshape(-1, 2)
    focal = 0.5 * (K_i[0, 0] + K_j[0, 0])
    method = {"magsac": cv2.USAC_MAGSAC, "accurate": cv2.USAC_ACCURATE,
              "ransac": cv2.RANSAC}[estimator]
    E, mask = cv2.findEssentialMat(ni, nj, np.eye(3), method=method, prob=0.999,
                                   threshold=threshold_px / focal)
    if E is None or E.shape != (3, 3):
        return None
    _, R, t, mask = cv2.recoverPose(E, ni, nj, np.eye(3), mask=mask)
    inl = mask.reshape(-1) > 0
    if inl.sum() < min_inliers:
        return None
    t = t.reshape(3)
    # Baseline length: lift the inliers with view i's depth and, per point, find the length
    # along t that makes them reproject onto their match in j (least squares of the cross
    # product); the median is robust to depth outliers. Triangulating instead would make
    # the length hostage to the small angle errors of a short baseline.
    d_i = sample_depth(depth_i, pi[inl])
    d_j = sample_depth(depth_j, pj[inl])
    X = np.concatenate([ni[inl], np.ones((int(inl.sum()), 1))], axis=1) * d_i[:, None]
    u = np.concatenate([nj[inl], np.ones((int(inl.sum()), 1))], axis=1)
    A = X @ R.T
    ub, ua = np.cross(u, t), np.cross(u, A)
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = -np.einsum("ij,ij->i", ub, ua) / np.einsum("ij,ij->i", ub, ub)
    ok = (d_i > 0) & (d_j > 0) & np.isfinite(lam) & (lam > 0)
    if ok.sum() < min_inliers:
        return None
    baseline = float(np.median(lam[ok]))
    z_j = (A + baseline * t)[:, 2]
    ok &= z_j > 0
    if ok.sum() < min_inliers:
        return None
    scale_j = float(np.median(z_j[ok] / d_j[ok]))
    return FallbackPose(R=R, t=t * baseline, depth_scale_j=scale_j, inliers=int(ok.sum()),
                        matches=int(len(pi)))


def guided_matches(fi: Features, fj: Features, predicted: np.ndarray, radius: float,
                   ratio: float = 0.9) -> tuple[np.ndarray, np.ndarray]:
    """Matches of view ``i``'s keypoints searched near where a pose predicts them in ``j``.

    Guided matching: a pose hypothesis (and view ``i``'s depth) predicts where each keypoint
    of ``i`` appears in ``j``; only ``j``'s keypoints within ``radius`` pixels of that place
    compete, so the ratio test compares a handful of local candidates instead of the whole
    image, and far more correct matches pass it than unguided matching finds.

    Parameters
    ----------
    fi, fj : Features
        Keypoints and descriptors of both views.
    predicted : numpy.ndarray
        (n_i, 2) predicted pixel in ``j`` of each keypoint of ``i``; NaN where there is no
        prediction (no depth, behind the camera).
    radius : float
        Search radius in pixels.
    ratio : float
        Lowe's ratio between the best and the second-best local candidate.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        (m, 2) pixels in ``i`` and their matches in ``j``, each keypoint of ``j`` used once.
    """
    from scipy.spatial import cKDTree

    empty = (np.zeros((0, 2)), np.zeros((0, 2)))
    ok = np.flatnonzero(np.all(np.isfinite(predicted), axis=1))
    if len(ok) == 0 or len(fj.pixels) < 2:
        return empty
    near = cKDTree(fj.pixels).query_ball_point(predicted[ok], radius)
    best_i, best_j, best_d = [], [], []
    for k, cands in zip(ok, near, strict=True):
        if not cands:
            continue
        d = np.linalg.norm(fj.descriptors[cands] - fi.descriptors[k], axis=1)
        order = np.argsort(d)
        if len(order) > 1 and d[order[0]] >= ratio * d[order[1]]:
            continue
        best_i.append(k)
        best_j.append(cands[order[0]])
        best_d.append(d[order[0]])
    if not best_i:
        return empty
    # One match per keypoint of j: the closest descriptor wins.
    order = np.argsort(best_d)
    used: set[int] = set()
    keep = []
    for k in order:
        if best_j[k] not in used:
            used.add(best_j[k])
            keep.append(k)
    keep_i = np.array(best_i)[keep]
    keep_j = np.array(best_j)[keep]
    return fi.pixels[keep_i], fj.pixels[keep_j]
