"""The terms of the graph-cut energies (paper §III-B): data costs and pairwise cut costs.

* f: MSAC truncated-L2 data cost, :func:`msac_costs`; g: the normal data cost of E_n,
  :func:`normal_costs` of :func:`normal_angles`; :func:`data_costs` gives f and f + g of a
  whole pool for one hypothesis in one compiled pass;
* w_pq: the proximity-guided cut cost of an edge, 0.5 + k_p + k_c + k_n
  (:func:`proximity_weights`), computed on the frame's threads.

:mod:`monoplane.algorithm.graphcut` assembles them into binary energies and minimises those.
Positions are in the caller's (normalised) frame, angles in radians.
"""

from __future__ import annotations

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.jit import chunks, inline, kernel, run_threaded

#: Edges per thread below which proximity weights are computed on one thread.
THREADED_EDGES = 20_000


def msac_costs(dist: np.ndarray, epsilon: float) -> tuple[np.ndarray, np.ndarray]:
    """Truncated-L2 data costs f(0, p) and f(1, p) of the paper's GC-RANSAC data term.

    Parameters
    ----------
    dist : numpy.ndarray
        (M,) point-to-plane distances φ(p, θ) (any unit, same as ``epsilon``).
    epsilon : float
        Inlier threshold ε.

    Returns
    -------
    f0, f1 : numpy.ndarray
        (M,) float64 costs of labelling each point outlier / inlier.
    """
    r = (np.asarray(dist, dtype=np.float64) / epsilon) ** 2
    inside = r < 1.0
    f0 = np.where(inside, 1.0 - r, 0.0)
    f1 = np.where(inside, 0.0, r)
    return f0, f1


def normal_angles(normals: np.ndarray, model_normal: np.ndarray) -> np.ndarray:
    """Angle ρ(p, θ_n) between each point normal and the model normal.

    Parameters
    ----------
    normals : numpy.ndarray
        (M, 3) unit normals.
    model_normal : numpy.ndarray
        (3,) unit model normal θ_n (same orientation convention as ``normals``).

    Returns
    -------
    numpy.ndarray
        (M,) float64 angles in radians, in [0, π].
    """
    cos = np.clip(np.asarray(normals, dtype=np.float64) @ np.asarray(model_normal), -1.0, 1.0)
    return np.arccos(cos)


def normal_costs(angles: np.ndarray, epsilon_n: float) -> np.ndarray:
    """Normal data cost g(1, p) of E_n (g(0, p) is 0).

    Parameters
    ----------
    angles : numpy.ndarray
        (M,) normal errors ρ in radians.
    epsilon_n : float
        Normal threshold ε_n in radians.

    Returns
    -------
    numpy.ndarray
        (M,) float64 ``exp(ρ / ε_n - 1)`` where ``ρ >= ε_n``, else 0.
    """
    a = np.asarray(angles, dtype=np.float64)
    return np.where(a >= epsilon_n, np.exp(a / epsilon_n - 1.0), 0.0)


def data_costs(points: np.ndarray, normals: np.ndarray, pool: np.ndarray, plane: np.ndarray,
               model_normal: np.ndarray | None, epsilon: float, epsilon_n: float = np.pi,
               payback: np.ndarray | None = None, keep: float = 1.0,
               gate: float = np.pi, edges: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray]:
    """Data costs f(0, p) and f(1, p) + g(1, p) of a pool for one hypothesis, in one pass.

    :func:`msac_costs` of the point-to-plane distances, plus :func:`normal_costs` of the
    angles to the model normal when one is given.

    With a model normal and ``gate`` below π, a point whose normal lies more than ``gate``
    from the model normal (*turned*) cannot be an inlier: its f(1, p) + g(1, p) is +inf, and
    the cut fixes it as an outlier whatever its neighbours. g alone cannot do that: at 3 ε_n
    it is e², which the (1 - λ) weight makes far smaller than what a point within ε pays on
    its edges as an outlier (the both-outlier cost ½ λ (f(0, p) + f(0, q)) per edge). With
    ``edges`` (the pool's graph) only a turned point whose neighbours are all turned too is
    gated: a surface that turns away from the plane (a globe beside a cabinet front), not a
    plane's own noisy normal or the band along a crease, whose normals blur into the next
    face's; those keep g and the smoothness decides.

    With ``payback`` (a graph cut's :func:`~monoplane.algorithm.graphcut.pool_payback`) and
    ``keep`` (its 1 - λ), a point whose distance cost alone already makes it an outlier in
    every minimiser (``keep f(1, p) > payback[p]``, with the margin
    :func:`~monoplane.algorithm.graphcut.minimize_gc_ransac` tests) gets f(1, p) without g:
    the cut fixes it as an outlier all the same and never reads its inlier cost, and the
    arccos and exp of its normal term are saved.

    Parameters
    ----------
    points, normals : numpy.ndarray
        (N, 3) float64 cloud points and unit normals.
    pool : numpy.ndarray
        (M,) int64 indices of the points to label.
    plane : numpy.ndarray
        (4,) unit-normal plane in the points' frame.
    model_normal : numpy.ndarray or None
        (3,) unit model normal θ_n; ``None`` leaves out E_n.
    epsilon, epsilon_n : float
        Distance threshold ε (points' unit) and normal threshold ε_n (radians).
    payback : numpy.ndarray, optional
        (M,) float64 bound of each point's edges (see above); ``None``: every cost exact.
    keep : float
        Weight 1 - λ of the data term in the cut's energy, with ``payback``.
    gate : float
        Largest angle in radians between a point's normal and the model normal at which
        the point may be an inlier (π: no gate).
    edges : numpy.ndarray, optional
        (E, 2) int64 pool positions of the pool's graph edges: a turned point with a
        neighbour that is not turned is not gated. ``None``: every turned point is.

    Returns
    -------
    f0, data1 : numpy.ndarray
        (M,) float64 costs of the outlier and the inlier label (data1 +inf where gated).
    """
    use_normal = model_normal is not None
    mn = np.zeros(3) if model_normal is None else np.asarray(model_normal, dtype=np.float64)
    bound = np.zeros(0) if payback is None else np.ascontiguousarray(payback, dtype=np.float64)
    # Turned below this cosine; -2 turns nothing (the cosine of unit normals is at least -1).
    cos_gate = float(np.cos(gate)) if gate < np.pi and use_normal else -2.0
    idx = np.ascontiguousarray(pool, dtype=np.int64)
    f0, data1, turned = _data_costs(points, normals, idx, np.asarray(plane, dtype=np.float64), mn,
                                    float(epsilon), float(epsilon_n), use_normal, bound,
                                    float(keep), cos_gate)
    if cos_gate > -2.0:
        pairs = (np.zeros((0, 2), dtype=np.int64) if edges is None else
                 np.ascontiguousarray(np.asarray(edges, dtype=np.int64).reshape(-1, 2)))
        _gate_turned(data1, turned, pairs, edges is not None, normals, idx, mn,
                     float(epsilon_n), bound, float(keep))
    return f0, data1


@inline
def _add_normal_term(data1: np.ndarray, i: int, cos: float, epsilon_n: float,
                     cos_skip: float) -> None:
    """Add g(1, p) of a point whose normal has cosine ``cos`` to the model normal to
    ``data1[i]``. arccos only where the angle can reach ε_n: above ``cos_skip`` it is surely
    smaller (the margin is far wider than arccos's rounding), so the result is that of
    testing every point."""
    if cos < cos_skip:
        rho = np.arccos(min(max(cos, -1.0), 1.0))
        if rho >= epsilon_n:
            data1[i] += np.exp(rho / epsilon_n - 1.0)


@inline
def _cos_to(model_normal: np.ndarray, normals: np.ndarray, p: int) -> float:
    """Cosine of the (N, 3) ``normals[p]`` to the unit ``model_normal`` (3,): one expression
    for :func:`_data_costs` and :func:`_gate_turned`, whose bits must agree."""
    return (model_normal[0] * normals[p, 0] + model_normal[1] * normals[p, 1]
            + model_normal[2] * normals[p, 2])


@inline
def _fixed_by_distance(r: float, payback: np.ndarray, i: int, keep: float) -> bool:
    """The test of graphcut._gc_ransac_network on a lower bound of its data1 - f0, the
    distance cost ``r`` >= 1 alone (always False with an empty ``payback``)."""
    return payback.shape[0] > 0 and keep * r > payback[i] * (1.0 + 1e-9) + 1e-12


@kernel
def _data_costs(points: np.ndarray, normals: np.ndarray, pool: np.ndarray, plane: np.ndarray,
                model_normal: np.ndarray, epsilon: float, epsilon_n: float, use_normal: bool,
                payback: np.ndarray, keep: float, cos_gate: float
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`data_costs` before the gate (``use_normal`` False ignores ``model_normal``; an
    empty ``payback`` skips no normal term), and the (M,) bool points whose normal's cosine
    to the model normal is below ``cos_gate``. Their normal terms are left to
    :func:`_gate_turned`: most of them are gated, and a gated point's term is never read."""
    m = pool.shape[0]
    f0 = np.zeros(m)
    data1 = np.empty(m)
    turned = np.zeros(m, dtype=np.bool_)
    cos_skip = np.cos(epsilon_n) + 1e-9
    for i in range(m):
        p = pool[i]
        cos = 1.0
        if use_normal:
            cos = _cos_to(model_normal, normals, p)
            turned[i] = cos < cos_gate
        phi = (plane[0] * points[p, 0] + plane[1] * points[p, 1] + plane[2] * points[p, 2]
               + plane[3])
        r = (phi / epsilon) ** 2
        if r < 1.0:
            f0[i] = 1.0 - r
            data1[i] = 0.0
        else:
            data1[i] = r
            if _fixed_by_distance(r, payback, i, keep):
                continue
        if use_normal and not turned[i]:
            _add_normal_term(data1, i, cos, epsilon_n, cos_skip)
    return f0, data1, turned


@kernel
def _gate_turned(data1: np.ndarray, turned: np.ndarray, edges: np.ndarray,
                 by_neighbours: bool, normals: np.ndarray, pool: np.ndarray,
                 model_normal: np.ndarray, epsilon_n: float, payback: np.ndarray,
                 keep: float) -> None:
    """Set ``data1`` (M,) to +inf, in place, at the ``turned`` (M,) points; with
    ``by_neighbours`` only at those whose every neighbour along the (E, 2) ``edges`` is
    turned too (see :func:`data_costs`). The turned points left ungated get the normal term
    :func:`_data_costs` left out, as it would have added it (same cosine, same bound test)."""
    gated = turned.copy()
    if by_neighbours:
        for e in range(edges.shape[0]):
            i, j = edges[e, 0], edges[e, 1]
            if not turned[j]:
                gated[i] = False
            if not turned[i]:
                gated[j] = False
    cos_skip = np.cos(epsilon_n) + 1e-9
    for i in range(data1.shape[0]):
        if gated[i]:
            data1[i] = np.inf
        elif turned[i]:
            # data1 holds the distance cost alone: 0 within ε, else r >= 1.
            if data1[i] > 0.0 and _fixed_by_distance(data1[i], payback, i, keep):
                continue
            cos = _cos_to(model_normal, normals, pool[i])
            _add_normal_term(data1, i, cos, epsilon_n, cos_skip)


def proximity_weights(points: np.ndarray, edges: np.ndarray, normals: np.ndarray | None = None,
                      colors: np.ndarray | None = None, alpha_p2: float = 0.005,
                      alpha_c2: float = 0.1, alpha_n2: float = 5.0, w_p: float = 1.0,
                      w_c: float = 1.0, w_n: float = 1.0, scale: np.ndarray | None = None,
                      angles: np.ndarray | None = None) -> np.ndarray:
    """Cost of cutting each edge in the proximity-guided pairwise term, 0.5 + k_p + k_c + k_n.

    k_p = w_p exp(-|p_i - p_j|² / 2α_p²)  (eq. kp),
    k_c = w_c exp(-|p_i - p_j|² / 2α_p² - |I_i - I_j|² / 2α_c²)  (eq. kc),
    k_n = w_n exp(-|p_i - p_j|² / 2α_p² - arccos(n_i · n_j) / 2α_n²)  (eq. kn; the angle is
    not squared, as written in the paper).

    Parameters
    ----------
    points : numpy.ndarray
        (N, 3) normalised positions.
    edges : numpy.ndarray
        (E, 2) int node pairs.
    normals : numpy.ndarray, optional
        (N, 3) unit normals; ``None`` drops k_n.
    colors : numpy.ndarray, optional
        (N, 3) RGB in [0, 1]; ``None`` (depth-only or grey input) drops k_c.
    alpha_p2, alpha_c2, alpha_n2 : float
        Squared bandwidths α_p², α_c², α_n² (paper: 0.005, 0.1, 5.0).
    w_p, w_c, w_n : float
        Term weights (paper: 1).
    scale : numpy.ndarray, optional
        (E,) factors in [0, 1] on each edge's affinity ``k_p + k_c + k_n``: the cost becomes
        ``0.5 + scale (cost - 0.5)`` (the lattice graph's down-weighting of pairs whose
        normals turn, :meth:`~monoplane.geometry.graph.NeighbourGraph.from_lattice`). The 0.5
        floor keeps every edge's table submodular.
    angles : numpy.ndarray, optional
        (E,) ``arccos(n_i · n_j)`` of each edge (clipped to [-1, 1]), when the caller has them
        (:attr:`~monoplane.geometry.graph.NeighbourGraph.normal_angle`): k_n reads them
        instead of computing them. Ignored without ``normals``.

    Returns
    -------
    numpy.ndarray
        (E,) float64 cut costs, all >= 0.5.
    """
    none = np.zeros((0, 3))
    pts = np.ascontiguousarray(points, dtype=np.float64)
    pairs = np.ascontiguousarray(np.asarray(edges, dtype=np.int64).reshape(-1, 2))
    nor = none if normals is None else np.ascontiguousarray(normals, dtype=np.float64)
    col = none if colors is None else np.ascontiguousarray(colors, dtype=np.float64)
    if scale is None:
        factor = np.zeros(0)
    else:
        factor = np.ascontiguousarray(scale, dtype=np.float64)
        if factor.shape != (pairs.shape[0],):
            raise InvalidInput(f"scale must be ({pairs.shape[0]},), got {factor.shape}")
    turn = (np.zeros(0) if angles is None or normals is None
            else np.ascontiguousarray(angles, dtype=np.float64))
    if turn.size and turn.shape != (pairs.shape[0],):
        raise InvalidInput(f"angles must be ({pairs.shape[0]},), got {turn.shape}")
    # Each edge's weight is computed alone: chunks of edges on parallel threads change nothing.
    parts = run_threaded([
        lambda a=a, b=b: _proximity_weights(pts, pairs[a:b], nor, col, float(alpha_p2),
                                            float(alpha_c2), float(alpha_n2), float(w_p),
                                            float(w_c), float(w_n),
                                            factor[a:b] if factor.size else factor,
                                            turn[a:b] if turn.size else turn)
        for a, b in chunks(pairs.shape[0], THREADED_EDGES)])
    return np.concatenate(parts) if len(parts) > 1 else parts[0]


@kernel
def _proximity_weights(points: np.ndarray, edges: np.ndarray, normals: np.ndarray,
                       colors: np.ndarray, alpha_p2: float, alpha_c2: float, alpha_n2: float,
                       w_p: float, w_c: float, w_n: float, scale: np.ndarray, angles: np.ndarray
                       ) -> np.ndarray:
    """:func:`proximity_weights` in one pass; empty (0, 3) ``normals``/``colors`` drop a term,
    an empty ``scale`` scales nothing, empty ``angles`` are computed from the normals."""
    use_n, use_c, use_s = normals.shape[0] > 0, colors.shape[0] > 0, scale.shape[0] > 0
    given = angles.shape[0] > 0
    out = np.empty(edges.shape[0])
    for e in range(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        d2 = 0.0
        for c in range(3):
            d2 += (points[i, c] - points[j, c]) ** 2
        pos = -d2 / (2.0 * alpha_p2)
        w = 0.5 + w_p * np.exp(pos)
        if use_c:
            c2 = 0.0
            for c in range(3):
                c2 += (colors[i, c] - colors[j, c]) ** 2
            w += w_c * np.exp(pos - c2 / (2.0 * alpha_c2))
        if use_n:
            if given:
                angle = angles[e]
            else:
                dot = 0.0
                for c in range(3):
                    dot += normals[i, c] * normals[j, c]
                angle = np.arccos(min(max(dot, -1.0), 1.0))
            w += w_n * np.exp(pos - angle / (2.0 * alpha_n2))
        out[e] = 0.5 + scale[e] * (w - 0.5) if use_s else w
    return out
