"""numba kernels of the permutohedral lattice (:mod:`monoplane.algorithm.mean_field`).

Construction follows Adams, Baek & Davis (Eurographics 2010, §3): elevate each feature vector
onto the hyperplane ``Σ x = 0`` of R^(d+1), find the nearest remainder-0 lattice point, sort the
residuals to get the enclosing simplex and read the barycentric weights off them. Vertices are
found in an open-addressing hash table of their packed integer keys, so construction is linear
in the number of points. Filtering (splat, [½, 1, ½] blur along the d+1 lattice directions,
slice) works on float32 values in place of the sparse-matrix products it replaces.

Every kernel is compiled with ``cache=True`` (no run pays the compile twice) and ``nogil``.
"""

from __future__ import annotations

import numba
import numpy as np

_FIB = np.uint64(11400714819323198485)  # 2^64 / golden ratio: multiplicative hashing


@numba.njit(cache=True, nogil=True)
def enclosing_simplices(f: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Remainder-0 vertex, residual ranks and barycentric weights of each point's simplex.

    Parameters
    ----------
    f : numpy.ndarray
        (N, d) float64 features with unit Gaussian deviation.

    Returns
    -------
    key0 : numpy.ndarray
        (N, d) int64 first d elevated coordinates of the simplex's remainder-0 vertex.
    rank : numpy.ndarray
        (N, d+1) int64 rank of each coordinate's residual (0 = largest), a permutation of
        0..d; vertex r of the simplex is ``key0 + r`` minus ``d+1`` where ``rank > d - r``.
    weights : numpy.ndarray
        (N, d+1) float32 barycentric weight of vertex r (non-negative, summing to 1).
    """
    n, d = f.shape
    d1 = d + 1
    scale = _elevation_scale(d)
    key0 = np.empty((n, d), np.int64)
    ranks = np.empty((n, d1), np.int64)
    weights = np.empty((n, d1), np.float32)
    elevated = np.empty(d1)
    rem0 = np.empty(d1)
    diff = np.empty(d1)
    rank = np.empty(d1, np.int64)
    bary = np.empty(d1 + 1)
    for i in range(n):
        _enclose(f[i], scale, elevated, rem0, diff, rank, bary)
        for k in range(d1):
            ranks[i, k] = rank[k]
            weights[i, k] = bary[k]
        for k in range(d):
            key0[i, k] = np.int64(rem0[k])
    return key0, ranks, weights


@numba.njit(cache=True, nogil=True)
def _elevation_scale(d: int) -> np.ndarray:
    """(d,) scale of each feature coordinate before elevation, so that the lattice's
    [1,2,1]^(d+1) blur approximates a unit-deviation Gaussian."""
    scale = np.empty(d)
    for k in range(d):
        scale[k] = np.sqrt(2.0 / 3.0) * (d + 1) / np.sqrt((k + 1.0) * (k + 2.0))
    return scale


@numba.njit(cache=True, nogil=True, inline="always")
def _enclose(f: np.ndarray, scale: np.ndarray, elevated: np.ndarray, rem0: np.ndarray,
             diff: np.ndarray, rank: np.ndarray, bary: np.ndarray) -> None:
    """The enclosing simplex of one (d,) float64 feature vector ``f``: fills ``rem0`` (d+1,)
    with its remainder-0 vertex (elevated coordinates, float64), ``rank`` (d+1,) with the
    residual ranks and ``bary`` (d+2,) with the barycentric weights (first d+1 used);
    ``elevated`` and ``diff`` are (d+1,) scratch. See :func:`enclosing_simplices`."""
    d = f.shape[0]
    d1 = d + 1
    # x_0 = Σ_k cf_k, x_j = Σ_{k>=j} cf_k - j cf_{j-1}.
    tail = 0.0
    for j in range(d, 0, -1):
        cf = f[j - 1] * scale[j - 1]
        elevated[j] = tail - j * cf
        tail += cf
    elevated[0] = tail
    total = 0.0
    inv = 1.0 / d1
    for j in range(d1):
        # floor(e / d1) from e * (1 / d1), within a few ulps of the quotient: the same floor
        # unless the quotient lies that close to an integer, where it is divided after all.
        t = elevated[j] * inv
        down = np.floor(t)
        near = 1e-12 * (abs(t) + 1.0)
        if t - down < near or down + 1.0 - t < near:
            down = np.floor(elevated[j] / d1)
        down *= d1
        up = down + d1
        rem0[j] = up if up - elevated[j] < elevated[j] - down else down
        total += rem0[j]
    s = np.int64(np.rint(total / d1))
    for j in range(d1):
        diff[j] = elevated[j] - rem0[j]
    # Rank: how many residuals are larger, ties going to the lower index (counted as sums of
    # comparisons, which compile without branches).
    for k in range(d1):
        r = s
        dk = diff[k]
        for j in range(k):
            r += diff[j] >= dk
        for j in range(k + 1, d1):
            r += diff[j] > dk
        rank[k] = r
    for k in range(d1):
        if rank[k] < 0:
            rank[k] += d1
            rem0[k] += d1
        elif rank[k] > d:
            rank[k] -= d1
            rem0[k] -= d1
    bary[:] = 0.0
    for k in range(d1):
        v = (elevated[k] - rem0[k]) / d1
        bary[d - rank[k]] += v
        bary[d - rank[k] + 1] -= v
    bary[0] += 1.0 + bary[d1]


@numba.njit(cache=True, nogil=True)
def _slot(table: np.ndarray, code: np.int64, shift: np.uint64) -> np.int64:
    """Hash-table slot holding ``code``, or the empty slot where it would go (linear probing)."""
    mask = table.size - 1
    h = np.int64((np.uint64(code) * _FIB) >> shift)
    while table[h] != -1 and table[h] != code:
        h = (h + 1) & mask
    return h


@numba.njit(cache=True, nogil=True)
def insert_vertices(key0: np.ndarray, rank: np.ndarray, place: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Index the simplex vertices of every point in a hash table.

    Parameters
    ----------
    key0 : numpy.ndarray
        (N, d) int64 remainder-0 keys, shifted to be non-negative with room for offsets.
    rank : numpy.ndarray
        (N, d+1) int64 ranks from :func:`enclosing_simplices`.
    place : numpy.ndarray
        (d,) int64 place value of each key coordinate in the packed code.

    Returns
    -------
    vertex_of : numpy.ndarray
        (N, d+1) int32 index of each point's simplex vertex r.
    codes : numpy.ndarray
        (M,) int64 packed key of each vertex, in order of first use.
    table, index : numpy.ndarray
        The hash table: slot -> code (-1 = empty) and slot -> vertex index, for
        :func:`lattice_neighbours` and :func:`add_messages_at`.
    """
    n, d = key0.shape
    d1 = d + 1
    bits = 1
    while (1 << bits) < 2 * n * d1 + 16:
        bits += 1
    table = np.full(1 << bits, -1, np.int64)
    index = np.empty(1 << bits, np.int32)
    shift = np.uint64(64 - bits)
    codes = np.empty(n * d1, np.int64)
    vertex_of = np.empty((n, d1), np.int32)
    place_sum = 0
    for k in range(d):
        place_sum += place[k]
    m = 0
    for i in range(n):
        base = 0
        for k in range(d):
            base += key0[i, k] * place[k]
        for r in range(d1):
            code = base + r * place_sum
            for k in range(d):
                if rank[i, k] > d - r:
                    code -= d1 * place[k]
            h = _slot(table, code, shift)
            if table[h] == -1:
                table[h] = code
                index[h] = m
                codes[m] = code
                m += 1
            vertex_of[i, r] = index[h]
    return vertex_of, codes[:m].copy(), table, index


@numba.njit(cache=True, nogil=True)
def lattice_neighbours(codes: np.ndarray, place: np.ndarray, table: np.ndarray,
                       index: np.ndarray) -> np.ndarray:
    """(d+1, M, 2) int32 index of each vertex's neighbour one step back/forward along each
    lattice direction, -1 where that neighbour is not in use (it holds zero and drops out).

    In key coordinates the step along direction ``a`` adds ``d+1`` to coordinate ``a`` (when
    ``a < d``) and subtracts 1 from every coordinate. The neighbours are looked up in the
    hash table of :func:`insert_vertices` (``table``, ``index``), which holds every code.
    """
    m = codes.size
    d = place.size
    d1 = d + 1
    bits = 0
    while (1 << bits) < table.size:
        bits += 1
    shift = np.uint64(64 - bits)
    place_sum = 0
    for k in range(d):
        place_sum += place[k]
    out = np.empty((d1, m, 2), np.int32)
    for a in range(d1):
        delta = -place_sum + (d1 * place[a] if a < d else 0)
        for v in range(m):
            for side in range(2):
                target = codes[v] + (delta if side == 0 else -delta)
                h = _slot(table, target, shift)
                out[a, v, side] = index[h] if table[h] == target else -1
    return out


@numba.njit(cache=True, nogil=True)
def _barycentric(vertex_of: np.ndarray, weights: np.ndarray, values: np.ndarray, rows: int,
                 splat: bool) -> np.ndarray:
    """Product with the (N, M) matrix ``B`` of the points' barycentric weights (row i: point
    i's weights at its simplex's vertices), or with its transpose.

    Splatting and slicing are the two directions of one sparse product, walked over the same
    (point, vertex, weight) entries in the same order.

    Parameters
    ----------
    vertex_of, weights : numpy.ndarray
        (N, d+1) int32 vertex indices and float32 weights (:func:`insert_vertices`,
        :func:`enclosing_simplices`).
    values : numpy.ndarray
        (N, C) float32 point values when ``splat``, else (M, C) lattice values.
    rows : int
        M when ``splat``, else N.
    splat : bool
        True for ``Bᵀ values`` (points onto the lattice), False for ``B values`` (lattice at
        the points).

    Returns
    -------
    numpy.ndarray
        (rows, C) float32 product.
    """
    n, d1 = vertex_of.shape
    c = values.shape[1]
    out = np.zeros((rows, c), np.float32)
    for i in range(n):
        for r in range(d1):
            v = vertex_of[i, r]
            w = weights[i, r]
            src, dst = (i, v) if splat else (v, i)
            for j in range(c):
                out[dst, j] += w * values[src, j]
    return out


@numba.njit(cache=True, nogil=True)
def splat_blur(vertex_of: np.ndarray, weights: np.ndarray, neighbours: np.ndarray,
               values: np.ndarray, m: int) -> np.ndarray:
    """(M, C) float32 lattice values: ``values`` (N, C) splatted and blurred."""
    d1 = vertex_of.shape[1]
    c = values.shape[1]
    lat = _barycentric(vertex_of, weights, values, m, True)
    tmp = np.empty_like(lat)
    for a in range(d1):
        for v in range(m):
            p = neighbours[a, v, 0]
            q = neighbours[a, v, 1]
            for j in range(c):
                s = lat[v, j]
                if p >= 0:
                    s += np.float32(0.5) * lat[p, j]
                if q >= 0:
                    s += np.float32(0.5) * lat[q, j]
                tmp[v, j] = s
        lat, tmp = tmp, lat
    return lat


@numba.njit(cache=True, nogil=True)
def slice_values(vertex_of: np.ndarray, weights: np.ndarray, lat: np.ndarray) -> np.ndarray:
    """(N, C) float32 barycentric interpolation of lattice values ``lat`` (M, C)."""
    return _barycentric(vertex_of, weights, lat, vertex_of.shape[0], False)


@numba.njit(cache=True, nogil=True)
def add_messages_at(head: np.ndarray, tail: np.ndarray, div: float, div2: float,
                    lo: np.ndarray, span: np.ndarray, place: np.ndarray, table: np.ndarray,
                    index: np.ndarray, values: np.ndarray, ones: np.ndarray, weight: np.float32,
                    start: int, stop: int, out: np.ndarray) -> None:
    """Rows ``start:stop`` of ``out`` += a normalised lattice message at points not in the
    lattice, which are located, sliced and normalised one at a time.

    Point k's features are ``[head[k], tail[k] / div / div2]`` (the CRF's positions, shared by
    its kernels, then a cue). The message is ``weight · (B values) / sqrt(max(B ones,
    1e-20))`` with ``B`` the point's barycentric weights on the lattice (0 at vertices that
    are not in it): :func:`enclosing_simplices`, a look-up of the simplex's vertices in the
    lattice's hash table, :func:`slice_values` and that float32 arithmetic, fused, so that no
    (K, d+1) arrays are built.

    Parameters
    ----------
    head, tail : numpy.ndarray
        (K, a) and (K, b) float64, ``a + b = d`` the lattice's dimension (``b`` may be 0).
    div, div2 : float
        Divisors of ``tail``, applied one after the other (1.0: none).
    lo, span, place, table, index : numpy.ndarray
        The lattice's key offset (d,), key radix (d,), place values (d,) and hash table
        (:func:`insert_vertices`).
    values : numpy.ndarray
        (M, L) float32 blurred lattice values.
    ones : numpy.ndarray
        (M, 1) float32 blurred lattice values of ones (the normaliser).
    weight : numpy.float32
        Kernel weight.
    start, stop : int
        Rows to do.
    out : numpy.ndarray
        (K, L) float32 sums, added to in place.
    """
    a = head.shape[1]
    d = a + tail.shape[1]
    d1 = d + 1
    num = values.shape[1]
    scale = _elevation_scale(d)
    bits = 0
    while (1 << bits) < table.size:
        bits += 1
    shift = np.uint64(64 - bits)
    f = np.empty(d)
    elevated = np.empty(d1)
    rem0 = np.empty(d1)
    diff = np.empty(d1)
    rank = np.empty(d1, np.int64)
    bary = np.empty(d1 + 1)
    acc = np.empty(num + 1, np.float32)
    of_rank = np.empty(d1, np.int64)
    place_sum = 0
    for k in range(d):
        place_sum += place[k]
    floor = np.float32(1e-20)
    for i in range(start, stop):
        for k in range(a):
            f[k] = head[i, k]
        for k in range(d - a):
            f[a + k] = tail[i, k] / div
            if div2 != 1.0:  # x / 1 is x: one division less for the normals
                f[a + k] /= div2
        _enclose(f, scale, elevated, rem0, diff, rank, bary)
        acc[:] = 0.0
        # Vertex r's key is key0 + r, less d+1 where rank > d - r: every key of the simplex
        # lies in key0 - d .. key0 + d. When they all lie inside the key range, each code
        # follows from the previous one (the coordinate of rank d - r + 1 drops by d+1).
        code = 0
        whole = True
        for k in range(d):
            key = np.int64(rem0[k]) - lo[k]
            whole = whole and key - d >= 0 and key + d < span[k]
            code += key * place[k]
            of_rank[rank[k]] = k
        of_rank[rank[d]] = d
        for r in range(d1):
            if whole:
                if r > 0:
                    code += place_sum
                    k = of_rank[d - r + 1]
                    if k < d:
                        code -= d1 * place[k]
            else:
                code = 0
                inside = True
                for k in range(d):
                    key = np.int64(rem0[k]) - lo[k] + r
                    if rank[k] > d - r:
                        key -= d1
                    if key < 0 or key >= span[k]:
                        inside = False
                    code += key * place[k]
                if not inside:
                    continue
            h = _slot(table, code, shift)
            if table[h] != code:
                continue  # a vertex outside the lattice holds nothing
            v = index[h]
            w = np.float32(bary[r])
            for j in range(num):
                acc[j] += w * values[v, j]
            acc[num] += w * ones[v, 0]
        den = np.float32(np.sqrt(max(acc[num], floor)))
        for j in range(num):
            out[i, j] += np.float32(weight * acc[j]) / den
