"""Plane hypotheses from minimal samples, compiled: the inner loop of the RANSAC search.

* :func:`draw_triplets`: 3-point samples drawn without replacement from a pool, optionally only
  those whose three normals agree pairwise;
* :func:`sample_hypotheses`: the exact plane of each sample and its model normal;
* :func:`hypothesis_costs`: inlier / MSAC / MSAC-plus-normal costs of many hypotheses on a set
  of points; :func:`bin_by_normal` and :func:`binned_costs`: the MSAC-plus-normal cost on points
  grouped by normal direction, visiting only the groups a hypothesis' normal can reach;
* :func:`search_batches`: a whole plane search, batch after batch with the adaptive stopping
  rule :func:`needed_samples`, in one call, its scalars in one :class:`SearchRule`. The RANSAC
  driver uses it when its sampler and scorer state that they draw and score as above
  (:attr:`monoplane.contracts.Sampler.draws`, :attr:`monoplane.contracts.Scorer.scores`);
  it gives what calling them batch by batch gives, without the interpreter between batches.

Why one module: numba inlines the helpers a kernel calls and caches the kernel by its own source
file, so a helper must live beside every kernel that inlines it.

Frames and units are the caller's (the RANSAC's normalised cloud); planes are ``(n, d)`` rows
with ``n · X + d = 0``, ``|n| = 1`` and ``d >= 0``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.geometry.normal_bins import (
    BinnedPoints,
    bin_by_normal,  # noqa: F401  (re-exported)
)
from monoplane.jit import inline, kernel

#: Cost kinds of :func:`hypothesis_costs`.
INLIERS, MSAC, MSAC_NORMAL = 0, 1, 2
#: Relative slack by which a running sum of a hypothesis' terms must exceed the best cost
#: before it is given up (:func:`_binned_batch`): far wider than the rounding by which that
#: sum and the final one, added in another order, can differ (about 1e-12 at 10^4 terms).
_PRUNE_MARGIN = 1e-9


def draw_triplets(rng: np.random.Generator, pool: np.ndarray, first: int, budget: int,
                  limit: int, normals: np.ndarray | None = None, cos_min: float = -2.0
                  ) -> np.ndarray:
    """Uniform samples of three distinct pool points, optionally normal-checked.

    ``first`` candidates are drawn; when fewer than ``limit`` of them pass and ``budget``
    exceeds ``first``, the other ``budget - first`` are drawn in one more round.

    Parameters
    ----------
    rng : numpy.random.Generator
        Drawn from inside the kernel (numba's ``Generator.integers`` gives numpy's stream).
    pool : numpy.ndarray
        (M,) int64 point indices, M >= 3.
    first, budget, limit : int
        Candidates of the first round, of both rounds together, and samples wanted at most.
    normals : numpy.ndarray, optional
        (N, 3) unit normals; when given, a sample is kept only when its three normals'
        pairwise dot products all reach ``cos_min``.
    cos_min : float
        See ``normals``.

    Returns
    -------
    numpy.ndarray
        (S, 3) int64 point indices in draw order, S <= ``limit``.
    """
    return _drawn_triplets(rng, np.ascontiguousarray(pool, dtype=np.int64), int(first),
                           max(int(first), int(budget)), int(limit),
                           np.zeros((0, 3)) if normals is None else normals,
                           normals is not None, float(cos_min))


@inline
def _keep_triplets(rng: np.random.Generator, pool: np.ndarray, count: int, normals: np.ndarray,
                   check: bool, cos_min: float, out: np.ndarray, kept: int) -> int:
    """Draw ``count`` candidate samples and append those that pass to ``out`` from row
    ``kept`` on, until it is full; returns the new number of rows.

    Draws without replacement per row by offsetting: a in [0, m), b in [0, m-1), c in
    [0, m-2), then b shifted past a and c past the two others; this is exact and needs no
    rejection. With ``check``, a sample is kept only when its three normals' pairwise dot
    products all reach ``cos_min``.
    """
    m = pool.shape[0]
    a = rng.integers(0, m, size=count)
    b = rng.integers(0, m - 1, size=count)
    c = rng.integers(0, m - 2, size=count)
    for s in range(count):
        if kept == out.shape[0]:
            break
        pa, pb, pc = a[s], b[s], c[s]
        if pb >= pa:
            pb += 1
        lo, hi = min(pa, pb), max(pa, pb)
        if pc >= lo:
            pc += 1
        if pc >= hi:
            pc += 1
        i, j, k = pool[pa], pool[pb], pool[pc]
        if check:
            ij = ik = jk = 0.0
            for d in range(3):
                ij += normals[i, d] * normals[j, d]
                ik += normals[i, d] * normals[k, d]
                jk += normals[j, d] * normals[k, d]
            if not (ij >= cos_min and ik >= cos_min and jk >= cos_min):
                continue
        out[kept, 0], out[kept, 1], out[kept, 2] = i, j, k
        kept += 1
    return kept


@kernel
def _drawn_triplets(rng: np.random.Generator, pool: np.ndarray, first: int, budget: int,
                    limit: int, normals: np.ndarray, check: bool, cos_min: float
                    ) -> np.ndarray:
    """:func:`draw_triplets` in one call: the generator is drawn from here, as numpy draws
    (numba's ``Generator.integers`` gives numpy's stream), so no Python runs between rounds.

    ``first`` candidates, then the other ``budget - first`` when fewer than ``limit`` passed;
    (K, 3) int64 rows, K <= ``limit``.
    """
    out = np.empty((max(min(budget, limit), 0), 3), dtype=np.int64)
    kept = _keep_triplets(rng, pool, first, normals, check, cos_min, out, 0)
    if kept < out.shape[0] and budget > first:
        kept = _keep_triplets(rng, pool, budget - first, normals, check, cos_min, out, kept)
    return out[:kept].copy()


@inline
def _plane_through(ax: float, ay: float, az: float, bx: float, by: float, bz: float,
                   cx: float, cy: float, cz: float
                   ) -> tuple[float, float, float, float, bool]:
    """Unit-normal plane ``(n, d)`` with ``d >= 0`` through points a, b, c, and whether they
    are far enough from collinear to define one."""
    u0, u1, u2 = bx - ax, by - ay, bz - az
    v0, v1, v2 = cx - ax, cy - ay, cz - az
    n0, n1, n2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0
    norm = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    # Scale-aware degeneracy test: |cross| is twice the triangle area, compare to edge².
    edge2 = max(u0 * u0 + u1 * u1 + u2 * u2, v0 * v0 + v1 * v1 + v2 * v2)
    if not norm > 1e-9 * max(edge2, 1e-300):
        return 0.0, 0.0, 0.0, 0.0, False
    n0, n1, n2 = n0 / norm, n1 / norm, n2 / norm
    d = -(n0 * ax + n1 * ay + n2 * az)
    if d < 0:
        n0, n1, n2, d = -n0, -n1, -n2, -d
    return n0, n1, n2, d, True


@kernel
def triplet_planes(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exact planes of (S, 3, 3) float64 point triplets (sample, point, coordinate), one at a
    time: (S, 4) planes, zero where degenerate, and (S,) bool validity (see
    :func:`monoplane.geometry.planes.planes_from_triplets`)."""
    planes = np.zeros((t.shape[0], 4))
    valid = np.zeros(t.shape[0], dtype=np.bool_)
    for s in range(t.shape[0]):
        n0, n1, n2, d, ok = _plane_through(t[s, 0, 0], t[s, 0, 1], t[s, 0, 2], t[s, 1, 0],
                                           t[s, 1, 1], t[s, 1, 2], t[s, 2, 0], t[s, 2, 1],
                                           t[s, 2, 2])
        if ok:
            planes[s, 0], planes[s, 1], planes[s, 2], planes[s, 3] = n0, n1, n2, d
            valid[s] = True
    return planes, valid


def sample_hypotheses(points: np.ndarray, normals: np.ndarray, samples: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The plane hypotheses of 3-point samples: each exact plane and its model normal.

    The model normal θ_n of a sample is the normalised mean of its three point normals (the
    plane's own normal where that mean vanishes). Degenerate (nearly collinear) samples are
    left out.

    Parameters
    ----------
    points, normals : numpy.ndarray
        (N, 3) float64 points and unit normals, one frame.
    samples : numpy.ndarray
        (S, 3) int64 point indices.

    Returns
    -------
    planes : numpy.ndarray
        (V, 4) float64 unit-normal planes with ``d >= 0``, V <= S, in sample order:
        :func:`monoplane.geometry.planes.planes_from_triplets` of the valid samples.
    model_normals : numpy.ndarray
        (V, 3) float64 unit model normals.
    """
    return _sample_hypotheses(points, normals, np.ascontiguousarray(samples, dtype=np.int64))


@inline
def _hypotheses_into(points: np.ndarray, normals: np.ndarray, samples: np.ndarray,
                     planes: np.ndarray, model: np.ndarray) -> int:
    """Write the planes and model normals of the valid ``samples`` into the first rows of
    ``planes`` (S, 4) and ``model`` (S, 3); returns how many. The mean normal is summed,
    divided and normalised in numpy's order for ``normals[s].mean(0)`` and its norm, so it
    has the same value."""
    m = np.empty(3)
    kept = 0
    for s in range(samples.shape[0]):
        i, j, k = samples[s, 0], samples[s, 1], samples[s, 2]
        n0, n1, n2, d, ok = _plane_through(points[i, 0], points[i, 1], points[i, 2],
                                           points[j, 0], points[j, 1], points[j, 2],
                                           points[k, 0], points[k, 1], points[k, 2])
        if not ok:
            continue
        planes[kept, 0], planes[kept, 1], planes[kept, 2], planes[kept, 3] = n0, n1, n2, d
        for c in range(3):
            m[c] = (normals[i, c] + normals[j, c] + normals[k, c]) / 3.0
        norm = np.sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2])
        for c in range(3):
            model[kept, c] = m[c] / max(norm, 1e-300) if norm > 1e-9 else planes[kept, c]
        kept += 1
    return kept


@kernel
def _sample_hypotheses(points: np.ndarray, normals: np.ndarray, samples: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`sample_hypotheses` without gathering the samples' points first."""
    planes = np.empty((samples.shape[0], 4))
    model = np.empty((samples.shape[0], 3))
    kept = _hypotheses_into(points, normals, samples, planes, model)
    return planes[:kept].copy(), model[:kept].copy()


@inline
def _sum4(term: np.ndarray, n: int) -> float:
    """Sum of ``term[:n]`` in four interleaved partial sums, which the CPU adds independently
    (one running sum waits for each addition); the order of the additions is fixed, so the
    scores do not depend on the compiler."""
    s0 = s1 = s2 = s3 = 0.0
    j = 0
    while j + 4 <= n:
        s0 += term[j]
        s1 += term[j + 1]
        s2 += term[j + 2]
        s3 += term[j + 3]
        j += 4
    total = (s0 + s1) + (s2 + s3)
    while j < n:
        total += term[j]
        j += 1
    return total


@inline
def _binned_batch(coords: np.ndarray, start: np.ndarray, centres: np.ndarray,
                  cos_reach: np.ndarray, planes: np.ndarray, model_normals: np.ndarray,
                  epsilon: float, epsilon_n: float, prune: bool, bound: float,
                  out: np.ndarray) -> None:
    """Write the msac-normal costs of (H, 4) planes with (H, 3) model normals on binned
    points into ``out[:H]``, or a lower bound of a cost that cannot be the least.

    ``coords`` and ``start`` come from :func:`bin_by_normal`; ``centres`` (C, 3) and
    ``cos_reach`` (C,) are each cell's centre direction and the cosine of its radius plus ε_n
    (plus a margin): a cell whose centre is farther from the model normal than that holds
    only normals farther than ε_n from it, each point of which costs exactly 1 (see
    :func:`hypothesis_costs`). The others' terms are summed as that function sums them.

    With ``prune``, only the least cost below ``bound`` (the caller's best so far) is wanted:
    the far points alone cost their count and the other terms are non-negative, so a
    hypothesis whose far count exceeds ``bound`` or a cost already written is not visited,
    and its count is written instead. The first least cost, and which hypothesis has it, are
    then those of visiting all, bit for bit, whenever it is below ``bound``.
    """
    m = coords.shape[1]
    x, y, z = coords[0], coords[1], coords[2]
    nx, ny, nz = coords[3], coords[4], coords[5]
    # The occupied cells only, as runs (first point, end) with their centre and reach.
    occupied = np.flatnonzero(start[1:] > start[:-1])
    n_cells = occupied.shape[0]
    lo_of = start[occupied]
    hi_of = start[occupied + 1]
    cx, cy, cz = centres[occupied, 0], centres[occupied, 1], centres[occupied, 2]
    reach = cos_reach[occupied]
    near = np.empty(n_cells, dtype=np.bool_)
    cos_n = np.cos(epsilon_n)
    term = np.empty(m)
    least = bound
    for h in range(planes.shape[0]):
        a, b, c, d = planes[h, 0], planes[h, 1], planes[h, 2], planes[h, 3]
        m0, m1, m2 = model_normals[h, 0], model_normals[h, 1], model_normals[h, 2]
        far = 0
        for j in range(n_cells):
            near[j] = m0 * cx[j] + m1 * cy[j] + m2 * cz[j] >= reach[j]
            if not near[j]:
                far += hi_of[j] - lo_of[j]
        if prune and far > least:
            out[h] = far
            continue
        k = 0
        seen = 0.0
        for j in range(n_cells):
            lo, hi = lo_of[j], hi_of[j]
            if not near[j]:
                continue
            # Slices indexed from 0: with offsets into the whole arrays the loop does not
            # vectorise (7 times slower).
            xs, ys, zs = x[lo:hi], y[lo:hi], z[lo:hi]
            nxs, nys, nzs = nx[lo:hi], ny[lo:hi], nz[lo:hi]
            run = term[k:k + hi - lo]
            for t in range(hi - lo):
                phi = abs(a * xs[t] + b * ys[t] + c * zs[t] + d)
                cos = m0 * nxs[t] + m1 * nys[t] + m2 * nzs[t]
                q = min((phi / epsilon) ** 2, 1.0)
                run[t] = q if cos > cos_n else 1.0
            k += hi - lo
            if prune:
                seen += _sum4(run, hi - lo)
                if (far + seen) * (1.0 - _PRUNE_MARGIN) > least:
                    break
        if prune and (far + seen) * (1.0 - _PRUNE_MARGIN) > least:
            out[h] = far + seen
            continue
        out[h] = _sum4(term, k) + far
        least = min(least, out[h])


@kernel
def binned_costs(coords: np.ndarray, start: np.ndarray, centres: np.ndarray,
                 cos_reach: np.ndarray, planes: np.ndarray, model_normals: np.ndarray,
                 epsilon: float, epsilon_n: float) -> np.ndarray:
    """(H,) msac-normal costs of (H, 4) float64 planes with (H, 3) model normals on points
    binned by :func:`bin_by_normal`; ``centres`` and ``cos_reach`` as for
    :func:`_binned_batch`, ε in the points' unit, ε_n in radians."""
    out = np.empty(planes.shape[0])
    _binned_batch(coords, start, centres, cos_reach, planes, model_normals, epsilon,
                  epsilon_n, False, np.inf, out)
    return out


@kernel
def hypothesis_costs(points: np.ndarray, normals: np.ndarray, pool: np.ndarray, planes: np.ndarray,
           model_normals: np.ndarray, epsilon: float, epsilon_n: float, kind: int
           ) -> np.ndarray:
    """(H,) costs of (H, 4) planes with (H, 3) model normals on the (M,) ``pool`` points.

    ``points`` and ``normals`` are the cloud's (N, 3) float64 arrays. ``kind`` is
    :data:`INLIERS`, :data:`MSAC` or :data:`MSAC_NORMAL`.

    The normal term needs no arccos: g(1, p) = exp(ρ/ε_n - 1) is 0 below ε_n and at least 1
    from ε_n on, so min(φ²/ε² + g, 1) is 1 exactly where ρ >= ε_n, i.e. where the cosine of
    the point normal with the model normal is at most cos ε_n.

    Speed: the pool is gathered once into contiguous coordinate arrays, each hypothesis fills
    a branch-free (M,) buffer of per-point terms (which the compiler vectorises), and the
    buffer is summed in four interleaved partial sums. A single running sum would be bound by
    the latency of one addition per point; the four sums change the result only by rounding
    (about 1e-15 relative).
    """
    m = pool.shape[0]
    x, y, z = np.empty(m), np.empty(m), np.empty(m)
    nx, ny, nz = np.empty(m), np.empty(m), np.empty(m)
    for i in range(m):
        p = pool[i]
        x[i], y[i], z[i] = points[p, 0], points[p, 1], points[p, 2]
        nx[i], ny[i], nz[i] = normals[p, 0], normals[p, 1], normals[p, 2]
    n_planes = planes.shape[0]
    out = np.empty(n_planes)
    cos_n = np.cos(epsilon_n)
    term = np.empty(m)
    for h in range(n_planes):
        a, b, c, d = planes[h, 0], planes[h, 1], planes[h, 2], planes[h, 3]
        m0, m1, m2 = model_normals[h, 0], model_normals[h, 1], model_normals[h, 2]
        if kind == INLIERS:
            for i in range(m):
                phi = abs(a * x[i] + b * y[i] + c * z[i] + d)
                term[i] = -1.0 if phi < epsilon else 0.0
        elif kind == MSAC:
            for i in range(m):
                phi = abs(a * x[i] + b * y[i] + c * z[i] + d)
                term[i] = min((phi / epsilon) ** 2, 1.0)
        else:
            for i in range(m):
                phi = abs(a * x[i] + b * y[i] + c * z[i] + d)
                cos = m0 * nx[i] + m1 * ny[i] + m2 * nz[i]
                # Both operands first, then a select: a conditional expression around min()
                # compiles to a branch, which keeps the loop from being vectorised.
                q = min((phi / epsilon) ** 2, 1.0)
                term[i] = q if cos > cos_n else 1.0
        out[h] = _sum4(term, m)
    return out


def refit_hypothesis(points: np.ndarray, normals: np.ndarray, members: np.ndarray,
                     fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The hypothesis of a labelling, for the local optimisation: the total-least-squares plane
    of its inliers and their mean normal.

    One kernel reads the inliers in place; on thousands of points the numpy passes over a
    gathered copy cost about ten times as much. The scatter's sums run in another order than
    numpy's matrix product, so the plane can differ from
    :func:`monoplane.geometry.planes.fit_plane`'s in the last bits; the mean normal is summed
    as numpy sums it.

    Parameters
    ----------
    points, normals : numpy.ndarray
        (N, 3) float64 points and unit normals.
    members : numpy.ndarray
        (M,) int64 indices of the inliers, M >= 3.
    fallback : numpy.ndarray
        (3,) model normal to keep where the mean normal vanishes.

    Returns
    -------
    plane : numpy.ndarray
        (4,) float64 ``(n, d)``, ``|n| = 1``, ``d >= 0``.
    model_normal : numpy.ndarray
        (3,) float64 unit mean normal of the inliers.
    """
    members = np.ascontiguousarray(members, dtype=np.int64)
    if members.shape[0] < 3:
        raise InvalidInput(f"a plane needs at least 3 inliers, got {members.shape[0]}")
    centroid, scatter, model = _member_moments(points, normals, members,
                                               np.asarray(fallback, dtype=np.float64))
    normal = np.linalg.eigh(scatter)[1][:, 0]
    d = -float(normal @ centroid)
    if d < 0:
        normal, d = -normal, -d
    return np.concatenate([normal, [d]]), model


@kernel
def _member_moments(points: np.ndarray, normals: np.ndarray, members: np.ndarray,
                    fallback: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centroid (3,) and scatter matrix (3, 3) about it of ``points[members]`` (two passes,
    centroid first, as stable as numpy's centred product), and the normalised mean of
    ``normals[members]`` (``fallback`` where it vanishes)."""
    m = members.shape[0]
    centroid = np.zeros(3)
    mean = np.zeros(3)
    for i in range(m):
        for c in range(3):
            centroid[c] += points[members[i], c]
            mean[c] += normals[members[i], c]
    centroid /= m
    mean /= m
    scatter = np.zeros((3, 3))
    for i in range(m):
        x = points[members[i], 0] - centroid[0]
        y = points[members[i], 1] - centroid[1]
        z = points[members[i], 2] - centroid[2]
        scatter[0, 0] += x * x
        scatter[0, 1] += x * y
        scatter[0, 2] += x * z
        scatter[1, 1] += y * y
        scatter[1, 2] += y * z
        scatter[2, 2] += z * z
    scatter[1, 0], scatter[2, 0], scatter[2, 1] = scatter[0, 1], scatter[0, 2], scatter[1, 2]
    norm = np.sqrt(mean[0] * mean[0] + mean[1] * mean[1] + mean[2] * mean[2])
    model = np.empty(3)
    for c in range(3):
        model[c] = mean[c] / max(norm, 1e-300) if norm > 1e-9 else fallback[c]
    return centroid, scatter, model


@inline
def needed_samples(inlier_ratio: float, confidence: float, sample_size: int = 3) -> float:
    """Samples needed to draw one all-inlier sample with the given confidence.

    Parameters
    ----------
    inlier_ratio : float
        Fraction w of inliers in the pool.
    confidence : float
        Wanted probability of success.
    sample_size : int
        Points per minimal sample.

    Returns
    -------
    float
        ``log(1 - confidence) / log(1 - w^s)``; ``inf`` when w = 0, 1 when w = 1.
    """
    good = math.pow(inlier_ratio, sample_size)
    if good <= 0:
        return math.inf
    if good >= 1:
        return 1.0
    return math.log(1.0 - confidence) / math.log1p(-good)


@inline
def _ratio_within(points: np.ndarray, subset: np.ndarray, plane: np.ndarray,
                  epsilon: float) -> float:
    """Fraction of ``points[subset]`` closer than ε to ``plane``."""
    count = 0
    for i in range(subset.shape[0]):
        p = subset[i]
        phi = abs(plane[0] * points[p, 0] + plane[1] * points[p, 1] + plane[2] * points[p, 2]
                  + plane[3])
        if phi < epsilon:
            count += 1
    return count / subset.shape[0]


@kernel
def inlier_ratio(points: np.ndarray, subset: np.ndarray, plane: np.ndarray,
                 epsilon: float) -> float:
    """Fraction of the (N, 3) float64 ``points[subset]`` ((M,) int64) within ε of a (4,)
    plane: the w of the RANSAC's stopping rule :func:`needed_samples`."""
    return _ratio_within(points, subset, plane, epsilon)


class SearchRule(NamedTuple):
    """The scalars of one plane search (:func:`search_batches`): how it draws, scores and
    stops."""

    batch: int
    """Samples wanted per batch."""
    first: int
    """Candidates drawn first in a batch (see :func:`draw_triplets`)."""
    budget: int
    """Candidates drawn at most in a batch, ``>= first``."""
    check: bool
    """Keep only candidates whose normals agree (``cos_min``)."""
    cos_min: float
    """Least pairwise dot product of a kept candidate's normals, with ``check``."""
    epsilon: float
    """Inlier distance ε, the points' unit."""
    epsilon_n: float
    """Normal threshold ε_n, radians."""
    min_iterations: int
    """Fewest candidates drawn."""
    max_iterations: int
    """Most candidates drawn."""
    confidence: float
    """Wanted probability of an all-inlier sample (:func:`needed_samples`)."""


@kernel
def search_batches(rng: np.random.Generator, points: np.ndarray, normals: np.ndarray,
                   pool: np.ndarray, scored: np.ndarray, binned: BinnedPoints,
                   rule: SearchRule) -> tuple[bool, np.ndarray, np.ndarray]:
    """One plane search: batches of samples until the stopping rule is met.

    Each batch is what :func:`draw_triplets` draws (``rule.first``, ``rule.budget``,
    ``rule.batch`` wanted, ``rule.check`` / ``rule.cos_min`` as its normal test) from the
    (M,) int64 ``pool`` of the (N, 3) float64 ``points`` and unit ``normals``, turned into
    hypotheses by :func:`sample_hypotheses` and scored by :func:`binned_costs` on ``binned``,
    the points of ``scored`` ((K,) int64) grouped by
    :func:`~monoplane.geometry.normal_bins.bin_points`. The best hypothesis so far sets the
    number of samples needed (:func:`needed_samples` of its inlier ratio on ``scored``), kept
    between ``rule.min_iterations`` and ``rule.max_iterations``; every candidate drawn
    counts, rejected or not. Returns whether a hypothesis was found, its (4,) plane and its (3,)
    model normal.
    """
    batch, first, budget = rule.batch, rule.first, rule.budget
    check, cos_min = rule.check, rule.cos_min
    epsilon, epsilon_n = rule.epsilon, rule.epsilon_n
    min_iterations, max_iterations = rule.min_iterations, rule.max_iterations
    coords, start, centres, cos_reach = binned
    best_plane = np.zeros(4)
    best_normal = np.zeros(3)
    found = False
    if pool.shape[0] < 3:
        return found, best_plane, best_normal
    wanted = max(min(budget, batch), 0)
    samples = np.empty((wanted, 3), dtype=np.int64)
    planes = np.empty((wanted, 4))
    model = np.empty((wanted, 3))
    costs = np.empty(wanted)
    best_cost = np.inf
    needed = float(max_iterations)
    drawn = 0
    while drawn < min(max(needed, float(min_iterations)), float(max_iterations)):
        kept = _keep_triplets(rng, pool, first, normals, check, cos_min, samples, 0)
        if kept < wanted and budget > first:
            kept = _keep_triplets(rng, pool, budget - first, normals, check, cos_min, samples,
                                  kept)
        drawn += batch
        if kept == 0:
            break
        valid = _hypotheses_into(points, normals, samples[:kept], planes, model)
        if valid == 0:
            continue
        _binned_batch(coords, start, centres, cos_reach, planes[:valid], model[:valid],
                      epsilon, epsilon_n, True, best_cost, costs)
        i = np.argmin(costs[:valid])
        if costs[i] < best_cost:
            best_cost = costs[i]
            best_plane[:] = planes[i]
            best_normal[:] = model[i]
            found = True
            needed = needed_samples(_ratio_within(points, scored, planes[i], epsilon),
                                    rule.confidence, 3)
    return found, best_plane, best_normal
