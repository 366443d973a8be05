"""Matching planes between views and fusing matched planes (paper §III-C and appendix).

Two criteria decide that plane ``p`` of view ``i`` and plane ``q`` of view ``j`` are the same
surface:

* **keypoints**: more than ``min_matches`` SfM keypoint matches fall in ``p`` (view ``i``) and in
  ``q`` (view ``j``), and a mutual check holds: at least ``mutual_ratio`` of ``p``'s matched
  keypoints that land on any plane of ``j`` land in ``q``, and the same from ``q``'s side;
* **reprojection**: ``p`` warped into view ``j`` through its plane parameters and the relative
  pose overlaps ``q`` with a large IoU, measured only where ``p`` is visible from ``j``.

A third, looser criterion (:func:`geometric_matches`) accepts pairs that overlap some and agree
in 3D (normals, and each plane's world centroid, :func:`world_centroids`, near the other plane).

Fusion follows the paper (after Jin et al., SparsePlanes): the fused normal maximises
``Σ_i (nᵀ n_i)²``, i.e. it is the principal eigenvector of ``Σ_i n_i n_iᵀ``, and the fused
offset is the mean offset. This holds for any number of planes.

Coordinates: camera frames are OpenCV's (x right, y down, z forward); pixel centres are at
integer ``(u, v)``; poses are world-to-camera ``x_cam = R x_world + t``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol

import numpy as np

from monoplane.datamodel import Reconstruction, pixel_rays
from monoplane.errors import InvalidInput


def keypoint_counts(labels_i: np.ndarray, labels_j: np.ndarray, keypoints_i: np.ndarray,
                    keypoints_j: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Count keypoint matches between every plane of view ``i`` and every plane of view ``j``.

    Parameters
    ----------
    labels_i, labels_j : numpy.ndarray
        (H_i, W_i) and (H_j, W_j) int label maps, 0 = non-planar, 1..P planes.
    keypoints_i, keypoints_j : numpy.ndarray
        (k_i, 2) and (k_j, 2) keypoint pixel coordinates ``(u, v)``.
    pairs : numpy.ndarray
        (m, 2) int keypoint index pairs ``(index in i, index in j)``.

    Returns
    -------
    numpy.ndarray
        (P_i + 1, P_j + 1) int64 counts; row/column 0 counts matches on non-planar pixels or
        outside the image.
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    li = _labels_at(labels_i, np.asarray(keypoints_i)[pairs[:, 0]])
    lj = _labels_at(labels_j, np.asarray(keypoints_j)[pairs[:, 1]])
    ni, nj = int(labels_i.max()) + 1, int(labels_j.max()) + 1
    return np.bincount(li * nj + lj, minlength=ni * nj).reshape(ni, nj).astype(np.int64)


def _labels_at(labels: np.ndarray, pixels: np.ndarray) -> np.ndarray:
    h, w = labels.shape
    uv = np.rint(np.asarray(pixels, dtype=np.float64)).astype(np.int64).reshape(-1, 2)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    out = np.zeros(len(uv), dtype=np.int64)
    out[inside] = labels[uv[inside, 1], uv[inside, 0]]
    return out


def keypoint_plane_matches(counts: np.ndarray, min_matches: int = 10,
                           mutual_ratio: float = 0.6) -> np.ndarray:
    """Plane pairs accepted by the keypoint criterion with the mutual check.

    Parameters
    ----------
    counts : numpy.ndarray
        (P_i + 1, P_j + 1) counts from :func:`keypoint_counts`.
    min_matches : int
        A pair needs strictly more matches than this (paper: 10).
    mutual_ratio : float
        Share of a plane's plane-to-plane matches that must go to the candidate, checked from
        both sides (paper: 60 %).

    Returns
    -------
    numpy.ndarray
        (K, 2) int64 1-based plane ids ``(p in i, q in j)``.
    """
    c = np.asarray(counts, dtype=np.float64)[1:, 1:]
    if c.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    row = c.sum(axis=1, keepdims=True)
    col = c.sum(axis=0, keepdims=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        ok = (c > min_matches) & (c >= mutual_ratio * row) & (c >= mutual_ratio * col)
    return np.argwhere(ok).astype(np.int64) + 1


def relative_pose(R_i: np.ndarray, t_i: np.ndarray, R_j: np.ndarray,
                  t_j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pose of camera ``j`` relative to camera ``i``: ``x_j = R x_i + t``.

    Parameters
    ----------
    R_i, t_i, R_j, t_j : numpy.ndarray
        World-to-camera rotations (3, 3) and translations (3,).

    Returns
    -------
    R, t : numpy.ndarray
        (3, 3) and (3,) float64.
    """
    R = np.asarray(R_j) @ np.asarray(R_i).T
    return R, np.asarray(t_j) - R @ np.asarray(t_i)


def reprojection_iou(labels_i: np.ndarray, params_i: np.ndarray, K_i: np.ndarray,
                     labels_j: np.ndarray, K_j: np.ndarray, R_ji: np.ndarray,
                     t_ji: np.ndarray, step: int = 1,
                     num_planes_j: int | None = None) -> np.ndarray:
    """IoU of every plane of view ``i`` warped into view ``j`` with every plane of view ``j``.

    For each plane ``p`` of view ``i``, every (sub-sampled) pixel of view ``j`` is back-projected
    onto ``p`` (expressed in camera ``j``), moved into camera ``i`` and projected there. The
    pixel is *visible* when the plane point is in front of both cameras and inside image ``i``;
    it is *warped* when it also lands on ``p``'s mask. Then
    ``IoU(p, q) = |warped ∩ q| / |warped ∪ (q ∩ visible)|``.

    Parameters
    ----------
    labels_i : numpy.ndarray
        (H_i, W_i) int label map of view ``i``.
    params_i : numpy.ndarray
        (P_i, 4) planes of view ``i`` in camera ``i``'s frame, in the SfM units of ``t_ji``.
    K_i, K_j : numpy.ndarray
        (3, 3) intrinsics.
    labels_j : numpy.ndarray
        (H_j, W_j) int label map of view ``j``.
    R_ji, t_ji : numpy.ndarray
        Relative pose ``x_j = R_ji x_i + t_ji``.
    step : int
        Evaluate every ``step``-th row and column of view ``j`` (speed at native resolution).
    num_planes_j : int, optional
        P_j, when view ``j`` has planes without pixels (default: ``labels_j.max()``).

    Returns
    -------
    numpy.ndarray
        (P_i, P_j) float64 IoUs in [0, 1].
    """
    params_i = np.asarray(params_i, dtype=np.float64).reshape(-1, 4)
    p_i = params_i.shape[0]
    p_j = int(labels_j.max()) if num_planes_j is None else int(num_planes_j)
    out = np.zeros((p_i, p_j))
    if p_i == 0 or p_j == 0:
        return out
    h_i, w_i = labels_i.shape
    rows, cols = np.arange(0, labels_j.shape[0], step), np.arange(0, labels_j.shape[1], step)
    u, v = np.meshgrid(cols.astype(np.float64), rows.astype(np.float64))
    rays = np.stack([u.ravel(), v.ravel(), np.ones(u.size)], axis=1) @ np.linalg.inv(K_j).T
    lab_j = labels_j[::step, ::step].reshape(-1).astype(np.int64)
    # Plane p in camera j: n_j = R n_i, d_j = d_i − n_j · t. A ray r of camera j meets it at
    # x_j = z r, z = −d_j / (n_j · r), and x_i = Rᵀ (x_j − t) = z Rᵀ (I + t n_jᵀ / d_j) r, so
    # view i's homogeneous pixel is z H_p r with H_p = K_i Rᵀ (I + t n_jᵀ / d_j): one (3, 3)
    # product per plane and ray instead of lifting, moving and projecting.
    n_j = params_i[:, :3] @ R_ji.T
    d_j = params_i[:, 3] - n_j @ t_ji
    d_safe = np.where(np.abs(d_j) > 1e-12, d_j, 1e-12)
    H = np.asarray(K_i, dtype=np.float64) @ R_ji.T @ (
        np.eye(3)[None] + t_ji[None, :, None] * (n_j / d_safe[:, None])[:, None, :])
    w = (rays @ H.reshape(3 * p_i, 3).T).reshape(-1, p_i, 3)     # (N, P_i, 3)
    ray_n = rays @ n_j.T                                           # (N, P_i)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = -d_safe[None, :] / ray_n
        front = np.isfinite(z) & (z > 0)
        ok = front & (z * w[..., 2] > 1e-9)
        u = np.rint(np.where(ok, w[..., 0] / w[..., 2], -1.0))
        v = np.rint(np.where(ok, w[..., 1] / w[..., 2], -1.0))
    visible = ok & (u >= 0) & (u < w_i) & (v >= 0) & (v < h_i)
    plane_of = np.broadcast_to(np.arange(1, p_i + 1)[None, :], visible.shape)
    hit = np.zeros(visible.shape, dtype=bool)
    hit[visible] = labels_i[v[visible].astype(np.int64),
                            u[visible].astype(np.int64)] == plane_of[visible]
    bins = p_j + 1
    lab = lab_j[:, None] + (np.arange(p_i) * bins)[None, :]
    inter = np.bincount(lab[hit], minlength=p_i * bins).reshape(p_i, bins)[:, 1:]
    area_visible = np.bincount(lab[visible], minlength=p_i * bins).reshape(p_i, bins)[:, 1:]
    n_warped = hit.sum(axis=0)
    union = n_warped[:, None] + area_visible - inter
    out[:] = np.where(n_warped[:, None] > 0, inter / np.maximum(union, 1), 0.0)
    return out


def normal_angles_deg(normals_a: np.ndarray, normals_b: np.ndarray) -> np.ndarray:
    """Unsigned angle between every pair of normals, in degrees.

    Parameters
    ----------
    normals_a, normals_b : numpy.ndarray
        (A, 3) and (B, 3) unit normals in one frame.

    Returns
    -------
    numpy.ndarray
        (A, B) float64 angles in [0, 180].
    """
    cos = np.clip(np.atleast_2d(normals_a) @ np.atleast_2d(normals_b).T, -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def reprojection_plane_matches(iou_ij: np.ndarray, iou_ji: np.ndarray,
                               min_iou: float = 0.5) -> np.ndarray:
    """Plane pairs accepted by the reprojection criterion.

    The score of ``(p, q)`` is the larger of the two warping directions; a pair is accepted when
    its score reaches ``min_iou`` and each plane is the other's best-scoring candidate.

    Parameters
    ----------
    iou_ij : numpy.ndarray
        (P_i, P_j) IoUs of view ``i``'s planes warped into view ``j``.
    iou_ji : numpy.ndarray
        (P_j, P_i) IoUs of view ``j``'s planes warped into view ``i``.
    min_iou : float
        Threshold on the score.

    Returns
    -------
    numpy.ndarray
        (K, 2) int64 1-based plane ids ``(p in i, q in j)``.
    """
    score = np.maximum(np.asarray(iou_ij), np.asarray(iou_ji).T)
    if score.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    best_q = score.argmax(axis=1)
    best_p = score.argmax(axis=0)
    p = np.arange(score.shape[0])
    mutual = (best_p[best_q] == p) & (score[p, best_q] >= min_iou)
    return np.stack([p[mutual] + 1, best_q[mutual] + 1], axis=1).astype(np.int64)


def fuse_planes(planes: np.ndarray) -> np.ndarray:
    """Average several estimates of one plane, all in the same (world) frame.

    The fused normal maximises ``Σ_i (nᵀ n_i)²``: the principal eigenvector of
    ``Σ_i n_i n_iᵀ`` (insensitive to each estimate's sign). Each estimate is then oriented to
    agree with it and the fused offset is the mean of their offsets (paper appendix).

    Parameters
    ----------
    planes : numpy.ndarray
        (N, 4) planes ``n_i · x + d_i = 0`` with unit normals, N >= 1.

    Returns
    -------
    numpy.ndarray
        (4,) float64 fused plane with a unit normal, oriented like the majority of the inputs.
    """
    p = np.atleast_2d(np.asarray(planes, dtype=np.float64))
    if p.shape[0] == 0 or p.shape[1] != 4:
        raise InvalidInput(f"fuse_planes needs (N>=1, 4) planes, got {p.shape}")
    n = p[:, :3] / np.linalg.norm(p[:, :3], axis=1, keepdims=True)
    d = p[:, 3] / np.linalg.norm(p[:, :3], axis=1)
    _, vecs = np.linalg.eigh(n.T @ n)
    fused = vecs[:, -1]
    signs = np.where(n @ fused >= 0, 1.0, -1.0)
    if signs.sum() < 0:
        fused, signs = -fused, -signs
    return np.concatenate([fused, [float(np.mean(signs * d))]])


def consistent_groups(node_views: np.ndarray, edges: np.ndarray, strengths: np.ndarray,
                      share_view: Callable[[list[int], list[int]], bool] | None = None
                      ) -> list[list[int]]:
    """Group matched view planes into global planes, guarding against wrong transitive merges.

    Edges are merged greedily, strongest first (Kruskal-style). Two groups that already hold
    planes of a common view are merged only if ``share_view(group_a, group_b)`` accepts their
    union (e.g. a coplanarity check: two pieces of one wall that an occluder splits in one
    view are one surface); without ``share_view`` such an edge is always skipped, so every
    group has at most one plane per view. Either way a weak wrong match cannot chain two
    different planes of one view into one global plane, which a plain transitive closure
    would do.

    Parameters
    ----------
    node_views : numpy.ndarray
        (N,) int view index of each node (view plane).
    edges : numpy.ndarray
        (E, 2) int node index pairs (accepted plane matches).
    strengths : numpy.ndarray
        (E,) float match strength, larger is more certain.
    share_view : callable, optional
        ``share_view(nodes_a, nodes_b) -> bool`` on the node indices of two groups that share
        a view.

    Returns
    -------
    list of list of int
        Node indices of each group, every group sorted, groups ordered by their first node.
    """
    from scipy.cluster.hierarchy import DisjointSet

    node_views = np.asarray(node_views, dtype=np.int64).reshape(-1)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    strengths = np.asarray(strengths, dtype=np.float64).reshape(-1)
    if len(edges) != len(strengths):
        raise InvalidInput(f"{len(edges)} edges but {len(strengths)} strengths")
    sets = DisjointSet(range(len(node_views)))
    views: dict[int, set[int]] = {k: {int(v)} for k, v in enumerate(node_views)}
    for e in np.argsort(-strengths, kind="stable"):
        a, b = int(sets[int(edges[e, 0])]), int(sets[int(edges[e, 1])])
        if a == b:
            continue
        if views[a] & views[b] and (share_view is None or not share_view(
                sorted(int(k) for k in sets.subset(a)), sorted(int(k) for k in sets.subset(b)))):
            continue
        sets.merge(a, b)
        root = int(sets[a])
        views[root] = views.pop(a if root == b else b) | views[root]
    groups = [sorted(int(k) for k in subset) for subset in sets.subsets()]
    return sorted(groups, key=lambda g: g[0])


class GeometricMatchSettings(Protocol):
    """What :func:`geometric_matches` reads (the ``average`` fuser's config has these
    fields)."""

    geometry_min_iou: float
    geometry_max_angle_deg: float
    geometry_max_distance: float


def world_centroids(rec: Reconstruction, cam: object) -> np.ndarray:
    """(P, 4) world centroid of each plane's pixels (lifted on its plane) and its mean depth."""
    out = np.full((rec.num_planes, 4), np.nan)
    if rec.num_planes == 0:
        return out
    depth = rec.planar_depth()[::2, ::2]
    labels = rec.labels[::2, ::2]
    rays = pixel_rays(cam.K, cam.height, cam.width)[::2, ::2]
    ok = (labels > 0) & (depth > 0)
    x = rays[ok] * depth[ok, None]
    lab = labels[ok] - 1
    count = np.bincount(lab, minlength=rec.num_planes)
    has = count > 0
    for axis in range(3):
        out[has, axis] = np.bincount(lab, weights=x[:, axis], minlength=rec.num_planes)[
            has] / count[has]
    out[has, 3] = out[has, 2]
    out[:, :3] = (out[:, :3] - cam.t) @ cam.R
    return out


def geometric_matches(score: np.ndarray, angles: np.ndarray, cent_i: np.ndarray,
                       cent_j: np.ndarray, world_i: np.ndarray, world_j: np.ndarray,
                       cfg: GeometricMatchSettings) -> list[tuple[int, int]]:
    """Plane pairs that overlap some (IoU) and agree in 3D: normals and centroid distances.

    This catches a plane that one view segments larger than another (e.g. together with a
    coplanar neighbour), whose IoU stays below the reprojection threshold.
    """
    out = []
    for p, q in np.argwhere(score >= cfg.geometry_min_iou):
        if angles[p, q] > cfg.geometry_max_angle_deg:
            continue
        ci, cj = cent_i[p], cent_j[q]
        if not (np.isfinite(ci).all() and np.isfinite(cj).all()):
            continue
        d_ij = abs(world_j[q, :3] @ ci[:3] + world_j[q, 3]) / max(ci[3], 1e-9)
        d_ji = abs(world_i[p, :3] @ cj[:3] + world_i[p, 3]) / max(cj[3], 1e-9)
        if max(d_ij, d_ji) <= cfg.geometry_max_distance:
            out.append((int(p) + 1, int(q) + 1))
    return out
