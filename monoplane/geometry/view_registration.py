"""Relative pose of two views from their depth, normals and planes, with or without features.

Two views that structure from motion could not connect still carry dense geometry: a depth map
(metric, or known up to a scale), per-pixel normals and a plane segmentation. This module turns
that into pose hypotheses and checks each hypothesis against all of it.

Hypotheses (``s·X_v = R·X_r + t``: a point ``X_r`` of the reference camera, in the reference
depth's units, seen by the other view at ``X_v`` in that view's own depth units; ``s`` is the
other view's depth scale, fixed to the reference's when both depths are metric):

* **3D feature matches**: putative keypoint matches lifted with both depths; a rigid (metric) or
  similarity (relative depth) fit on three matches, RANSAC (:func:`feature_hypotheses`);
* **plane-pair rotations**: two non-parallel planes of one view matched to two planes of the
  other with the same dihedral angle give the rotation without any scale; the dominant
  directions of a room (Manhattan or Atlanta frames) are the common case
  (:func:`rotation_hypotheses`). The translation and scale then come
  - from feature matches, two of which fix them once the rotation is known
    (:func:`translation_from_matches`), or
  - from the plane offsets: planes matched by their rotated normals satisfy
    ``n_v·t + s·d_v = d_r``, linear in ``(t, s)`` (:func:`translation_from_planes`);
* **FPFH + RANSAC** (Open3D's global registration) on metric depth (:func:`fpfh_hypothesis`).

Every hypothesis is verified by dense agreement (:func:`agreement`): each view's points moved
into the other view must land on its depth (relative depth error and normal angle), and points
landing in front of the surface the other view sees are free-space violations. The best one is
refined by ICP (Open3D, point-to-plane on metric depth, point-to-point with scale otherwise) and
kept only if the refinement does not lower its agreement.

Frames: OpenCV camera axes (x right, y down, z forward); pixel centres at integer coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from monoplane.datamodel import pixel_rays
from monoplane.geometry.alignment import sample_depth


@dataclass
class ViewGeometry:
    """What registration uses of one view, on a subsampled pixel grid.

    Attributes
    ----------
    K : numpy.ndarray
        (3, 3) intrinsics at the view's native resolution.
    depth : numpy.ndarray
        (H, W) float32 z-depth in the view's own units (0 = invalid).
    normals : numpy.ndarray
        (H, W, 3) float32 unit normals, camera frame, facing the camera.
    points, point_normals : numpy.ndarray
        (M, 3) grid points (camera frame, the view's units) with valid depth, and their normals.
    colors : numpy.ndarray
        (M, 3) float32 colour of those points, each channel divided by the image's mean (so
        that a change of exposure or white balance between views cancels).
    image : numpy.ndarray
        (H, W, 3) float32 the whole image, normalised the same way.
    planes : numpy.ndarray
        (P, 4) planes ``n·X + d = 0`` in the camera frame and the view's units.
    plane_areas : numpy.ndarray
        (P,) pixel count of each plane.
    metric : bool
        Whether the depth is metric (then two metric views share their scale).
    """

    K: np.ndarray
    depth: np.ndarray
    normals: np.ndarray
    points: np.ndarray
    point_normals: np.ndarray
    colors: np.ndarray
    image: np.ndarray
    planes: np.ndarray
    plane_areas: np.ndarray
    metric: bool
    _index: object = field(default=None, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        return self.depth.shape  # type: ignore[return-value]


def view_geometry(K: np.ndarray, depth: np.ndarray, normals: np.ndarray, rgb: np.ndarray | None,
                  planes: np.ndarray, plane_areas: np.ndarray, metric: bool,
                  grid: int = 96) -> ViewGeometry:
    """Sample a view for registration: every ``W // grid``-th pixel of valid depth.

    Parameters
    ----------
    K : numpy.ndarray
        (3, 3) intrinsics.
    depth : numpy.ndarray
        (H, W) z-depth in the view's units (0 or non-finite = invalid).
    normals : numpy.ndarray
        (H, W, 3) unit normals in the camera frame.
    rgb : numpy.ndarray or None
        (H, W, 3) uint8 image.
    planes, plane_areas : numpy.ndarray
        (P, 4) camera-frame planes and (P,) their pixel counts.
    metric : bool
        Whether the depth is metric.
    grid : int
        Samples across the image width.
    """
    h, w = depth.shape
    step = max(1, w // grid)
    d = np.nan_to_num(np.asarray(depth, np.float32)[::step, ::step])
    ok = d > 0
    rays = pixel_rays(K, h, w)[::step, ::step]
    pts = (rays[ok] * d[ok, None]).astype(np.float64)
    nrm = np.asarray(normals, np.float64)[::step, ::step][ok]
    if rgb is None:
        image = np.ones((h, w, 3), np.float32)
    else:
        image = np.asarray(rgb, np.float32)
        image = image / np.maximum(image.reshape(-1, 3).mean(axis=0), 1.0)
    col = image[::step, ::step][ok]
    return ViewGeometry(K=np.asarray(K, np.float64), depth=np.nan_to_num(depth).astype(np.float32),
                        normals=np.asarray(normals, np.float32), points=pts,
                        point_normals=nrm, colors=col, image=image,
                        planes=np.asarray(planes, np.float64).reshape(-1, 4),
                        plane_areas=np.asarray(plane_areas, np.float64).reshape(-1),
                        metric=metric)


@dataclass(frozen=True)
class Hypothesis:
    """A relative pose ``s·X_v = R·X_r + t`` and where it came from.

    Attributes
    ----------
    R : numpy.ndarray
        (3, 3) rotation from the reference camera to the other view's camera.
    t : numpy.ndarray
        (3,) translation, in the reference view's units.
    s : float
        Factor bringing the other view's depth into the reference view's units.
    source : str
        The generator: ``"features"``, ``"planes+features"``, ``"planes"``, ``"fpfh"``.
    support : int
        Its generator's own inlier count (feature matches or planes).
    """

    R: np.ndarray
    t: np.ndarray
    s: float
    source: str
    support: int = 0


@dataclass(frozen=True)
class Agreement:
    """Dense agreement of a hypothesis, both directions summed.

    Attributes
    ----------
    visible : int
        Grid points that land inside the other image, in front of it, on valid depth.
    agree : int
        Of those, points within the depth tolerance and normal angle of the other view's
        surface.
    violate : int
        Points landing clearly in front of the surface the other view sees (free space).
    colour : float
        Normalised cross-correlation of the grey levels of the agreeing points in both views
        (1: the images agree where the geometry does; near 0: another place of the same shape).
    total : int
        Grid points of both views.
    """

    visible: int
    agree: int
    violate: int
    colour: float
    total: int

    @property
    def overlap(self) -> float:
        """Share of both views' points that agree: the verified overlap."""
        return self.agree / max(self.total, 1)

    @property
    def violation(self) -> float:
        """Violations per agreeing point."""
        return self.violate / max(self.agree, 1)

    @property
    def score(self) -> float:
        """Ranking score, per point: the agreeing points weighted by how well the images agree
        on them, minus twice the violations. The colour term is what tells a room from its
        mirror or rotated twin, which fit the same walls."""
        return (self.agree * max(self.colour, 0.0) - 2.0 * self.violate) / max(self.total, 1)


def _one_way(src: ViewGeometry, dst: ViewGeometry, R: np.ndarray, t: np.ndarray,
             scale_dst: float, tol: float, cos_normal: float
             ) -> tuple[int, int, int, np.ndarray]:
    """Move ``src``'s points (in units where ``dst``'s depth is multiplied by ``scale_dst``)
    into ``dst`` and count visible, agreeing and violating points; also the sums of the grey
    levels of the agreeing points in both views (Σx, Σy, Σx², Σy², Σxy)."""
    q = src.points @ R.T + t
    z = q[:, 2]
    front = z > 1e-9
    q, z = q[front], z[front]
    u = dst.K[0, 0] * q[:, 0] / z + dst.K[0, 2]
    v = dst.K[1, 1] * q[:, 1] / z + dst.K[1, 2]
    h, w = dst.shape
    ui, vi = np.rint(u).astype(np.int64), np.rint(v).astype(np.int64)
    inside = (ui >= 0) & (ui < w) & (vi >= 0) & (vi < h)
    ui, vi, z = ui[inside], vi[inside], z[inside]
    z_obs = dst.depth[vi, ui].astype(np.float64) * scale_dst
    valid = z_obs > 0
    z, z_obs = z[valid], z_obs[valid]
    rel = (z - z_obs) / z_obs
    n_src = (src.point_normals[front][inside][valid]) @ R.T
    n_dst = dst.normals[vi[valid], ui[valid]]
    close = np.abs(rel) < tol
    agree = close & (np.einsum("ij,ij->i", n_src, n_dst) > cos_normal)
    violate = rel < -3.0 * tol
    g_src = src.colors[front][inside][valid][agree].mean(axis=1).astype(np.float64)
    g_dst = dst.image[vi[valid][agree], ui[valid][agree]].mean(axis=1).astype(np.float64)
    sums = np.array([g_src.sum(), g_dst.sum(), (g_src * g_src).sum(), (g_dst * g_dst).sum(),
                     (g_src * g_dst).sum()])
    return int(valid.sum()), int(agree.sum()), int(violate.sum()), sums


def agreement(ref: ViewGeometry, other: ViewGeometry, hyp: Hypothesis, tol: float = 0.05,
              normal_deg: float = 30.0) -> Agreement:
    """Dense agreement of two views under ``hyp`` (module docstring).

    Parameters
    ----------
    ref, other : ViewGeometry
        The reference view and the view being placed.
    hyp : Hypothesis
        ``s·X_other = R·X_ref + t``.
    tol : float
        Relative depth tolerance (a point agrees when ``|z − z_obs| < tol·z_obs``).
    normal_deg : float
        Largest normal angle of an agreeing point.
    """
    cos_n = float(np.cos(np.radians(normal_deg)))
    a = _one_way(ref, other, hyp.R, hyp.t, hyp.s, tol, cos_n)
    # other -> ref: X_ref = R^T (s X_other - t)
    b = _one_way(other, ref, hyp.R.T, -hyp.R.T @ hyp.t / hyp.s, 1.0 / hyp.s, tol, cos_n)
    n = a[1] + b[1]
    sx, sy, sxx, syy, sxy = a[3] + b[3]
    var_x, var_y = sxx - sx * sx / max(n, 1), syy - sy * sy / max(n, 1)
    ncc = (sxy - sx * sy / max(n, 1)) / np.sqrt(max(var_x * var_y, 1e-300)) if n > 2 else 0.0
    return Agreement(visible=a[0] + b[0], agree=n, violate=a[2] + b[2], colour=float(ncc),
                     total=len(ref.points) + len(other.points))


# ----------------------------------------------------------------------------------------------
# Minimal solvers


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
        if np.isfinite(hyp.s) and hyp.s > 0 and all(_rotation_deg(hyp.R, h.R) > 2.0
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


def _rotation_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
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
                if _rotation_deg(entry[0], R) < merge_deg:
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


# ----------------------------------------------------------------------------------------------
# Open3D: global registration and ICP


def _o3d_cloud(g: ViewGeometry, scale: float = 1.0):
    import open3d as o3d

    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(g.points * scale)
    pc.normals = o3d.utility.Vector3dVector(g.point_normals)
    pc.colors = o3d.utility.Vector3dVector(g.colors.astype(np.float64))
    return pc


def _median_depth(g: ViewGeometry) -> float:
    return float(np.median(g.points[:, 2])) if len(g.points) else 1.0


def fpfh_hypothesis(ref: ViewGeometry, other: ViewGeometry, scale: float,
                    seed: int = 0) -> Hypothesis | None:
    """Open3D's FPFH + RANSAC global registration, for two views of one metric scale.

    ``scale`` brings ``other``'s depth into ``ref``'s units. The voxel size is 2 % of the
    reference view's median depth.
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    voxel = 0.02 * _median_depth(ref)
    clouds = []
    for g, s in ((ref, 1.0), (other, scale)):
        pc = _o3d_cloud(g, s).voxel_down_sample(voxel)
        feat = reg.compute_fpfh_feature(
            pc, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100))
        clouds.append((pc, feat))
    (src, fs), (dst, fd) = clouds
    if len(src.points) < 10 or len(dst.points) < 10:
        return None
    o3d.utility.random.seed(seed)
    result = reg.registration_ransac_based_on_feature_matching(
        src, dst, fs, fd, True, 1.5 * voxel,
        reg.TransformationEstimationPointToPoint(False), 3,
        [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
         reg.CorrespondenceCheckerBasedOnDistance(1.5 * voxel)],
        reg.RANSACConvergenceCriteria(100000, 0.999))
    if len(result.correspondence_set) < 3:
        return None
    T = np.asarray(result.transformation)
    # T maps ref points onto other·scale: scale X_o = R X_r + t.
    return Hypothesis(R=T[:3, :3].copy(), t=T[:3, 3].copy(), s=float(scale), source="fpfh",
                      support=int(len(result.correspondence_set)))


def refine_icp(ref: ViewGeometry, other: ViewGeometry, hyp: Hypothesis, metric: bool,
               iterations: int = 30) -> Hypothesis:
    """Refine a hypothesis by ICP on the two views' grid clouds (Open3D).

    Metric depth: point-to-plane ICP at the known scale. Relative depth: point-to-point ICP
    with a scale (Umeyama), since the other view's scale is one of the unknowns. The
    correspondence distance is 5 % of the reference view's median depth.
    """
    import open3d as o3d

    reg = o3d.pipelines.registration
    src = _o3d_cloud(ref)
    dst = _o3d_cloud(other, hyp.s)
    init = np.eye(4)
    init[:3, :3], init[:3, 3] = hyp.R, hyp.t
    dist = 0.05 * _median_depth(ref)
    est = (reg.TransformationEstimationPointToPlane() if metric
           else reg.TransformationEstimationPointToPoint(with_scaling=True))
    result = reg.registration_icp(src, dst, dist, init, est,
                                  reg.ICPConvergenceCriteria(max_iteration=iterations))
    T = np.asarray(result.transformation)
    A = T[:3, :3]
    c = float(np.cbrt(np.linalg.det(A)))
    if not c > 0:
        return hyp
    # T maps ref onto s·other with an extra factor c: c R X_r + t = s X_o, so
    # R X_r + t/c = (s/c) X_o.
    return Hypothesis(R=A / c, t=T[:3, 3] / c, s=hyp.s / c, source=hyp.source,
                      support=hyp.support)


# ----------------------------------------------------------------------------------------------
# Epipolar refinement (relative depth)


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
