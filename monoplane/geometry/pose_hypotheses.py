"""Relative pose hypotheses of two views from lifted feature matches and matched planes.

``s·X_v = R·X_r + t`` (see :class:`~monoplane.geometry.view_agreement.Hypothesis`):

* **3D feature matches**: putative keypoint matches lifted with both depths; a rigid (metric) or
  similarity (relative depth) fit on three matches, RANSAC (:func:`feature_hypotheses`);
* **plane-pair rotations**: two non-parallel planes of one view matched to two planes of the
  other with the same dihedral angle give the rotation without any scale
  (:func:`rotation_hypotheses`); the translation and scale then come from feature matches
  (:func:`translation_from_matches`) or from the plane offsets
  (:func:`translation_from_planes`).

Frames: OpenCV camera axes (x right, y down, z forward).
"""

from __future__ import annotations

import numpy as np

from monoplane.geometry.view_agreement import Hypothesis, ViewGeometry


def _kabsch(a: np.ndarray, b: np.ndarray, with_scale: bool
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batched least-squares ``b ≈ c·R a + t`` (Umeyama) on (B, k, 3) point sets.

    Returns (B, 3, 3) rotations, (B, 3) translations and (B,) scales ``c`` (ones when
    ``with_scale`` is False).
    """
    ma, mb = a.mean(axis=1, keepdims=True), b.mean(axis=1, keepdims=True)
    a0, b0 = a - ma, b - mb
    cov = np.einsum("bki,bkj->bij", b0, a0)
    u, sig, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    fix = np.ones_like(sig)
    fix[:, 2] = d
    R = u @ (fix[:, :, None] * vt)
    if with_scale:
        var = np.einsum("bki,bki->b", a0, a0)
        c = np.einsum("bi,bi->b", sig, fix) / np.maximum(var, 1e-300)
    else:
        c = np.ones(len(a))
    t = mb[:, 0] - c[:, None] * np.einsum("bij,bj->bi", R, ma[:, 0])
    return R, t, c


def feature_hypotheses(x_ref: np.ndarray, x_other: np.ndarray, fixed_scale: float | None,
                       tol: float, iterations: int = 400, seed: int = 0,
                       keep: int = 3) -> list[Hypothesis]:
    """Rigid or similarity RANSAC on lifted 3D matches.

    Parameters
    ----------
    x_ref, x_other : numpy.ndarray
        (m, 3) matched points in each camera (each view's own depth units).
    fixed_scale : float or None
        The other view's depth scale when known (both depths metric); None estimates it.
    tol : float
        Inlier tolerance relative to the point's depth.
    iterations : int
        Minimal samples of three matches.
    seed : int
        Random seed.
    keep : int
        Distinct best hypotheses returned (by inlier count).

    Returns
    -------
    list of Hypothesis
        Source ``"features"``; support = inliers. Empty with fewer than 3 matches.
    """
    m = len(x_ref)
    if m < 3:
        return []
    rng = np.random.default_rng(seed)
    idx = np.array([rng.choice(m, 3, replace=False) for _ in range(iterations)])
    R, t, s = _fit(x_ref[idx], x_other[idx], fixed_scale)
    good = np.isfinite(s) & (s > 0)
    R, t, s = R[good], t[good], s[good]
    counts, inl = _inliers(R, t, s, x_ref, x_other, tol)
    out: list[Hypothesis] = []
    for k in np.argsort(-counts, kind="stable"):
        if counts[k] < 3 or len(out) >= keep:
            break
        Rk, tk, sk = _fit(x_ref[inl[k]][None], x_other[inl[k]][None], fixed_scale)
        hyp = Hypothesis(R=Rk[0], t=tk[0], s=float(sk[0]), source="features",
                         support=int(counts[k]))
        if np.isfinite(hyp.s) and hyp.s > 0 and all(rotation_deg(hyp.R, h.R) > 2.0
                                                    for h in out):
            out.append(hyp)
    return out


def _fit(x_ref: np.ndarray, x_other: np.ndarray, fixed_scale: float | None
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batched ``s·x_other ≈ R·x_ref + t`` on (B, k, 3) sets; ``s`` fixed or fitted."""
    if fixed_scale is not None:
        R, t, _ = _kabsch(x_ref, x_other * fixed_scale, with_scale=False)
        return R, t, np.full(len(x_ref), float(fixed_scale))
    # x_other ≈ c R x_ref + t'  <=>  (1/c) x_other ≈ R x_ref + t'/c
    R, t, c = _kabsch(x_ref, x_other, with_scale=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = 1.0 / c
    return R, t * s[:, None], s


def _inliers(R: np.ndarray, t: np.ndarray, s: np.ndarray, x_ref: np.ndarray,
             x_other: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """(B,) inlier counts and (B, m) masks of B hypotheses: ``|R x_r + t − s x_o|`` within
    ``tol`` of the other point's scaled depth."""
    pred = np.einsum("bij,mj->bmi", R, x_ref) + t[:, None, :]
    err = np.linalg.norm(pred - s[:, None, None] * x_other[None], axis=2)
    inl = err < tol * s[:, None] * np.maximum(x_other[None, :, 2], 1e-9)
    return inl.sum(axis=1), inl


def rotation_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle of ``Ra Rbᵀ`` in degrees: how far apart two (3, 3) rotations are."""
    c = (np.trace(Ra @ Rb.T) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def rotation_hypotheses(ref: ViewGeometry, other: ViewGeometry, max_planes: int = 10,
                        min_sine: float = 0.35, angle_tol_deg: float = 6.0,
                        merge_deg: float = 3.0) -> list[tuple[np.ndarray, float]]:
    """Rotations that take two non-parallel planes of ``ref`` onto two planes of ``other``.

    Each view's planes are taken largest first (``max_planes``); pairs whose normals are
    nearly parallel (sine below ``min_sine``) give no rotation. A pair of ``ref`` and a pair of
    ``other`` whose dihedral angles agree within ``angle_tol_deg`` give one rotation (the
    normals face their cameras, so there is no sign ambiguity). Rotations within
    ``merge_deg`` of one another are merged, their weights (the product of the four planes'
    areas' square roots) summed; in a Manhattan room the three dominant directions produce the
    same rotation from many pairs, which is what lifts it to the top.

    Returns
    -------
    list of (numpy.ndarray, float)
        (3, 3) rotations ``X_other = R X_ref`` (up to translation and scale) with their
        weights, heaviest first.
    """
    def top(g: ViewGeometry) -> tuple[np.ndarray, np.ndarray]:
        order = np.argsort(-g.plane_areas)[:max_planes]
        return g.planes[order, :3], np.sqrt(g.plane_areas[order])

    na, wa = top(ref)
    nb, wb = top(other)

    def pairs(n: np.ndarray, w: np.ndarray) -> list[tuple[int, int, float, float]]:
        out = []
        for i in range(len(n)):
            for j in range(len(n)):
                if i == j:
                    continue
                c = float(np.clip(n[i] @ n[j], -1.0, 1.0))
                if np.sqrt(1.0 - c * c) >= min_sine:
                    out.append((i, j, float(np.degrees(np.arccos(c))), w[i] * w[j]))
        return out

    pa, pb = pairs(na, wa), pairs(nb, wb)
    found: list[list] = []
    for i, j, ang_a, w_a in pa:
        if i > j:  # each unordered ref pair once; the other view's pairs come in both orders
            continue
        for k, m, ang_b, w_b in pb:
            if abs(ang_a - ang_b) > angle_tol_deg:
                continue
            R = _procrustes(na[i], na[j], nb[k], nb[m])
            weight = w_a * w_b
            for entry in found:
                if rotation_deg(entry[0], R) < merge_deg:
                    entry[1] += weight
                    break
            else:
                found.append([R, weight])
    found.sort(key=lambda e: -e[1])
    return [(R, float(w)) for R, w in found]


def _procrustes(a1: np.ndarray, a2: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> np.ndarray:
    """Rotation R minimising ``|R a1 − b1|² + |R a2 − b2|²`` (the cross products included, so
    the two pairs fix all three axes)."""
    fa = np.stack([a1, a2, np.cross(a1, a2)])
    fb = np.stack([b1, b2, np.cross(b1, b2)])
    u, _, vt = np.linalg.svd(fb.T @ fa)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def translation_from_matches(R: np.ndarray, x_ref: np.ndarray, x_other: np.ndarray,
                             fixed_scale: float | None, tol: float, max_samples: int = 2000,
                             seed: int = 0) -> tuple[np.ndarray, float, int] | None:
    """Translation (and scale) of a known rotation from lifted matches, by minimal samples:
    one match when the scale is fixed, two otherwise.

    ``s·x_other = R·x_ref + t``. Every minimal sample is tried while there are at most
    ``max_samples`` of them; beyond that (learned features give hundreds of matches, and
    every pair of them scored on every match grows with the cube of their number) that many
    pairs are drawn at random (``seed``). Returns ``(t, s, inliers)`` of the sample with most
    inliers (re-fitted on them), or None without a consistent pair.
    """
    m = len(x_ref)
    if m < (1 if fixed_scale is not None else 2):
        return None
    rx = x_ref @ R.T
    if fixed_scale is not None:
        t_all = fixed_scale * x_other - rx                                   # (m, 3)
        s_all = np.full(m, float(fixed_scale))
    else:
        i, j = np.triu_indices(m, 1)
        if len(i) > max_samples:
            pick = np.random.default_rng(seed).choice(len(i), max_samples, replace=False)
            i, j = i[np.sort(pick)], j[np.sort(pick)]
        a = x_other[i] - x_other[j]
        b = rx[i] - rx[j]
        s_all = np.einsum("ij,ij->i", a, b) / np.maximum(np.einsum("ij,ij->i", a, a), 1e-300)
        good = s_all > 0
        i, j, s_all = i[good], j[good], s_all[good]
        if len(s_all) == 0:
            return None
        t_all = 0.5 * (s_all[:, None] * (x_other[i] + x_other[j]) - rx[i] - rx[j])
    # Inliers of every sample at once: |s x_other - (R x_ref + t)| < tol * depth.
    pred = s_all[:, None, None] * x_other[None] - rx[None] - t_all[:, None, :]
    err = np.linalg.norm(pred, axis=2)
    depth = s_all[:, None] * np.maximum(x_other[None, :, 2], 1e-9)
    inl = err < tol * depth
    counts = inl.sum(axis=1)
    best = int(np.argmax(counts))
    sel = inl[best]
    if counts[best] < (2 if fixed_scale is not None else 3):
        return None
    if fixed_scale is not None:
        s = float(fixed_scale)
    else:
        a = x_other[sel] - x_other[sel].mean(axis=0)
        b = rx[sel] - rx[sel].mean(axis=0)
        s = float(np.sum(a * b) / max(np.sum(a * a), 1e-300))
        if s <= 0:
            return None
    t = (s * x_other[sel] - rx[sel]).mean(axis=0)
    return t, s, int(counts[best])


def translation_from_planes(R: np.ndarray, ref: ViewGeometry, other: ViewGeometry,
                            fixed_scale: float | None, max_planes: int = 10,
                            normal_deg: float = 8.0, keep: int = 8
                            ) -> list[tuple[np.ndarray, float, int]]:
    """Translations (and scales) of a known rotation from plane offsets.

    A plane ``(n_r, d_r)`` of ``ref`` and a plane ``(n_o, d_o)`` of ``other`` whose normals
    agree under ``R`` (``R n_r ≈ n_o``) are one surface only if ``n_o·t + s·d_o = d_r``. Planes
    spanning three directions fix ``t`` when the scale is known; a fourth correspondence, on a
    plane parallel to another (floor and ceiling, a wall and the opposite one, a table top and
    the floor), fixes ``s`` too. Every minimal set of candidate correspondences is solved and
    scored by the area of the correspondences it explains (offset within 5 % of the plane's
    distance); the best ``keep`` distinct solutions are returned.

    Returns
    -------
    list of (t, s, support)
        ``support`` is the number of plane correspondences explained.
    """
    from itertools import combinations

    def top(g: ViewGeometry) -> tuple[np.ndarray, np.ndarray]:
        order = np.argsort(-g.plane_areas)[:max_planes]
        return g.planes[order], np.sqrt(g.plane_areas[order])

    pr, wr = top(ref)
    po, wo = top(other)
    cos_tol = np.cos(np.radians(normal_deg))
    rot_n = pr[:, :3] @ R.T
    cand = [(i, k) for i in range(len(pr)) for k in range(len(po))
            if rot_n[i] @ po[k, :3] > cos_tol]
    if not cand:
        return []
    rows = np.array([np.r_[po[k, :3], po[k, 3]] for _, k in cand])        # n_o, d_o
    rhs = np.array([pr[i, 3] for i, _ in cand])                           # d_r
    weight = np.array([wr[i] * wo[k] for i, k in cand])
    size = 3 if fixed_scale is not None else 4
    results: list[tuple[np.ndarray, float, float, int]] = []
    for combo in combinations(range(len(cand)), size):
        used_r = {cand[c][0] for c in combo}
        used_o = {cand[c][1] for c in combo}
        if len(used_r) < size or len(used_o) < size:
            continue
        A = rows[list(combo)]
        b = rhs[list(combo)]
        if fixed_scale is not None:
            A3 = A[:, :3]
            if abs(np.linalg.det(A3)) < 0.2:
                continue
            t = np.linalg.solve(A3, b - fixed_scale * A[:, 3])
            s = float(fixed_scale)
        else:
            if abs(np.linalg.det(A)) < 1e-6:
                continue
            x = np.linalg.solve(A, b)
            t, s = x[:3], float(x[3])
            if s <= 0:
                continue
        resid = np.abs(rows[:, :3] @ t + s * rows[:, 3] - rhs)
        ok = resid < 0.05 * np.maximum(np.abs(rhs), 1e-9)
        results.append((t, s, float(weight[ok].sum()), int(ok.sum())))
    results.sort(key=lambda r: -r[2])
    out: list[tuple[np.ndarray, float, int]] = []
    for t, s, _, n in results:
        if len(out) >= keep:
            break
        if all(np.linalg.norm(t - u) > 0.05 * max(np.linalg.norm(u), 1e-9) for u, _, _ in out):
            out.append((t, s, n))
    return out
