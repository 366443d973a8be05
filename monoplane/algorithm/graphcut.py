"""Binary graph-cut energies of (proximity-guided) GC-RANSAC and their exact minimisation.

Label convention: ``True``/1 = inlier of the current plane, ``False``/0 = outlier.

The energy of a labelling L of M points with a neighbourhood graph (paper §III-B) is

    E(L) = (1 - λ) Σ_p [f(L_p, p) + g(L_p, p)] + λ Σ_(p,q)∈E e_pq(L_p, L_q)

* f: MSAC truncated-L2 data cost (GC-RANSAC eq. for f): with r = φ(p, θ)² / ε²,
  f(1, p) = 0 and f(0, p) = 1 - r inside the threshold, f(1, p) = r and f(0, p) = 0 outside;
* g: normal data cost E_n, g(1, p) = exp(ρ / ε_n - 1) when the angle ρ between the point's
  normal and the model normal θ_n is at least ε_n, else 0; g(0, p) = 0;
* e_pq: Potts-like pairwise term, e(1, 1) = 0, e(0, 0) = ½ (f(0, p) + f(0, q)) and
  e(0, 1) = e(1, 0) = w_pq, with w_pq = 1 (GC-RANSAC) or the proximity weight
  0.5 + k_p + k_c + k_n (paper eqs. kp, kc, kn).

Each edge table is reduced to unaries plus one directed edge (Kolmogorov & Zabih 2004) and the
energy is minimised exactly by max-flow (:mod:`monoplane.algorithm.mincut`). Nothing here
knows about stages or frames.

Two forms of the same minimisation live here. :class:`BinaryEnergy` (built by
:func:`gc_ransac_energy`, solved by :func:`minimize`) holds explicit (E, 2, 2) edge tables: the
general, readable form, for any submodular pairwise term a plugin labeler may want. The
built-in labelers call the specialised :func:`data_costs` and :func:`minimize_gc_ransac`,
compiled loops that exploit the structure of this energy and leave provable outliers out of
the max-flow graph; the tests hold them to the general form on random problems.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# The terms of these energies, re-exported: they were defined here before.
from monoplane.algorithm.graph_costs import (  # noqa: F401
    data_costs,
    msac_costs,
    normal_angles,
    normal_costs,
    proximity_weights,
)
from monoplane.algorithm.mincut import min_cut, min_cut_arcs
from monoplane.errors import InvalidInput
from monoplane.jit import kernel


@dataclass
class BinaryEnergy:
    """A pairwise binary energy, already weighted: ``E(L) = Σ_p U[p, L_p] + Σ_e T[e, L_i, L_j]``.

    Attributes
    ----------
    unary : numpy.ndarray
        (M, 2) float64 cost of label 0 and label 1 per node.
    edges : numpy.ndarray
        (E, 2) int64 node pairs ``(i, j)``.
    tables : numpy.ndarray
        (E, 2, 2) float64 ``tables[e, a, b]`` = cost when ``L_i = a`` and ``L_j = b``.
    """

    unary: np.ndarray
    edges: np.ndarray
    tables: np.ndarray

    def __post_init__(self) -> None:
        m = self.unary.shape[0]
        if self.unary.shape != (m, 2):
            raise InvalidInput(f"unary must have shape (M, 2), got {self.unary.shape}")
        e = self.edges.shape[0]
        if self.edges.shape != (e, 2) or self.tables.shape != (e, 2, 2):
            raise InvalidInput("edges must be (E, 2) and tables (E, 2, 2)")
        if e and (self.edges.min() < 0 or self.edges.max() >= m):
            raise InvalidInput("edge endpoints out of range")

    @property
    def num_nodes(self) -> int:
        """M."""
        return int(self.unary.shape[0])

    def energy(self, labels: np.ndarray) -> float:
        """Exact energy of a labelling (see :func:`energy`)."""
        return energy(labels, self.unary, self.edges, self.tables)

    def is_submodular(self, tol: float = 1e-12) -> bool:
        """True if every edge table is submodular (see :func:`check_submodular`)."""
        return bool(np.all(check_submodular(self.tables, tol)))

    def minimize(self) -> np.ndarray:
        """Globally optimal labelling by max-flow (see :func:`minimize`)."""
        return minimize(self.unary, self.edges, self.tables)


def gc_ransac_energy(f0: np.ndarray, f1: np.ndarray, edges: np.ndarray,
                     cut_cost: np.ndarray | float, lambda_: float,
                     g1: np.ndarray | None = None,
                     pairwise_scale: float = 1.0) -> BinaryEnergy:
    """Assemble E = (1-λ)E_d + (1-λ)E_n + λ·s·E_s of (proximity) GC-RANSAC.

    ``s`` (``pairwise_scale``) is 1 in the paper. Labelers pass ``s = 1 / k̄``, the inverse mean
    degree of the neighbourhood graph, to normalise E_s per point (see
    :func:`degree_normalisation`).

    Parameters
    ----------
    f0, f1 : numpy.ndarray
        (M,) data costs from :func:`msac_costs`.
    edges : numpy.ndarray
        (E, 2) int node pairs among the M points.
    cut_cost : numpy.ndarray or float
        (E,) cost of labelling an edge's ends differently: 1 for GC-RANSAC, or
        :func:`proximity_weights`.
    lambda_ : float
        Smoothness weight λ in [0, 1] (paper: 0.95).
    g1 : numpy.ndarray, optional
        (M,) normal cost of the inlier label, :func:`normal_costs`; ``None`` omits E_n.
    pairwise_scale : float
        Positive factor s on every pairwise table (the both-outlier cost included).

    Returns
    -------
    BinaryEnergy
    """
    if not 0.0 <= lambda_ <= 1.0:
        raise InvalidInput(f"lambda must lie in [0, 1], got {lambda_}")
    if not pairwise_scale > 0:
        raise InvalidInput(f"pairwise_scale must be positive, got {pairwise_scale}")
    data1 = f1 if g1 is None else f1 + g1
    unary = (1.0 - lambda_) * np.stack([f0, data1], axis=1)
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    cut = np.broadcast_to(np.asarray(cut_cost, dtype=np.float64), (edges.shape[0],))
    tables = np.zeros((edges.shape[0], 2, 2))
    tables[:, 0, 0] = 0.5 * (f0[edges[:, 0]] + f0[edges[:, 1]])
    tables[:, 0, 1] = cut
    tables[:, 1, 0] = cut
    tables *= lambda_ * pairwise_scale
    return BinaryEnergy(unary=unary, edges=edges, tables=tables)


def degree_normalisation(mean_degree: float) -> float:
    """Pairwise scale ``1 / k̄`` that makes E_s independent of the graph's density.

    Every edge charges its both-outlier cost ½(f(0,p) + f(0,q)) half to each end, so with k̄
    neighbours per point the unnormalised E_s raises the cost of the outlier label of a point
    within ε from ``(1-λ) f(0, p)`` to about ``(1-λ + λ k̄ / 2) f(0, p)``, and cutting a point off
    all its neighbours costs ``λ k̄``, while labelling a point beyond ε an inlier still costs
    only ``(1-λ) φ²/ε²``. On a dense cloud (k̄ ≈ 10) the smoothness term thus outweighs the data
    term k̄ times more than λ says, and a plane swallows strips of its neighbours. Dividing E_s
    by k̄ makes λ weigh one point's data cost against that point's share of the smoothness
    cost, as in GC-RANSAC's sparse sphere neighbourhoods (a few neighbours per point), and
    makes the labelling nearly independent of ``knn``.

    Parameters
    ----------
    mean_degree : float
        Mean number of neighbours per node of the full neighbourhood graph.

    Returns
    -------
    float
        ``1 / mean_degree``, or 1 when the graph has no edges.
    """
    return 1.0 / mean_degree if mean_degree > 0 else 1.0


def energy(labels: np.ndarray, unary: np.ndarray, edges: np.ndarray,
           tables: np.ndarray) -> float:
    """Evaluate a pairwise binary energy exactly.

    Parameters
    ----------
    labels : numpy.ndarray
        (M,) bool or {0, 1} labelling.
    unary : numpy.ndarray
        (M, 2) per-node costs of labels 0 and 1.
    edges : numpy.ndarray
        (E, 2) int node pairs.
    tables : numpy.ndarray
        (E, 2, 2) per-edge costs indexed ``[e, L_i, L_j]``.

    Returns
    -------
    float
    """
    lab = np.asarray(labels).astype(np.int64)
    total = unary[np.arange(lab.size), lab].sum()
    if edges.shape[0]:
        total += tables[np.arange(edges.shape[0]), lab[edges[:, 0]], lab[edges[:, 1]]].sum()
    return float(total)


def check_submodular(tables: np.ndarray, tol: float = 1e-12) -> np.ndarray:
    """Per-edge submodularity e(0,0) + e(1,1) <= e(0,1) + e(1,0), required by graph cuts.

    Parameters
    ----------
    tables : numpy.ndarray
        (E, 2, 2) edge tables.
    tol : float
        Slack for rounding.

    Returns
    -------
    numpy.ndarray
        (E,) bool.
    """
    t = np.asarray(tables)
    return t[:, 0, 0] + t[:, 1, 1] <= t[:, 0, 1] + t[:, 1, 0] + tol


def minimize(unary: np.ndarray, edges: np.ndarray, tables: np.ndarray) -> np.ndarray:
    """Globally minimise a submodular pairwise binary energy with max-flow.

    Each table is written as ``A + (C - A) x_i + (D - C) x_j + (B + C - A - D)(1 - x_i) x_j``
    with ``A, B, C, D = e(0,0), e(0,1), e(1,0), e(1,1)``: the linear parts join the unaries and
    the last term is one directed edge i → j of capacity ``B + C - A - D >= 0``. A node on the
    sink side of the cut takes label 1.

    Parameters
    ----------
    unary, edges, tables
        As in :func:`energy`.

    Returns
    -------
    numpy.ndarray
        (M,) bool optimal labelling (True = inlier).

    Raises
    ------
    InvalidInput
        If some edge table is not submodular.
    """
    m = unary.shape[0]
    if m == 0:
        return np.zeros(0, dtype=bool)
    slope = unary[:, 1] - unary[:, 0]
    cap = np.zeros(0)
    if edges.shape[0]:
        a, b = tables[:, 0, 0], tables[:, 0, 1]
        c, d = tables[:, 1, 0], tables[:, 1, 1]
        cap = b + c - a - d
        if np.any(cap < -1e-9 * np.maximum(1.0, np.abs(a) + np.abs(d))):
            raise InvalidInput(
                f"{int((cap < 0).sum())} edge tables are not submodular; graph cuts cannot "
                "minimise this energy"
            )
        cap = np.maximum(cap, 0.0)
        slope = slope + np.bincount(edges[:, 0], weights=c - a, minlength=m)
        slope = slope + np.bincount(edges[:, 1], weights=d - c, minlength=m)
    # A positive slope makes label 1 (sink side) dearer: capacity on the source edge.
    _, sink_side = min_cut(m, edges[:, 0], edges[:, 1], cap, np.zeros_like(cap), slope)
    return sink_side


def pool_payback(num_nodes: int, edges: np.ndarray, cut_cost: np.ndarray | float,
                 lambda_: float, pairwise_scale: float = 1.0) -> np.ndarray:
    """The most each point's edges can give back when it turns inlier: λ s Σ_q w_pq.

    It depends on the pool's graph only, not on the hypothesis: callers labelling one pool
    several times compute it once and pass it to :func:`minimize_gc_ransac`.

    Parameters
    ----------
    num_nodes : int
        M.
    edges : numpy.ndarray
        (E, 2) int node pairs among the M points.
    cut_cost : numpy.ndarray or float
        (E,) cut costs w_pq (or one for all edges).
    lambda_, pairwise_scale : float
        λ and s as for :func:`minimize_gc_ransac`.

    Returns
    -------
    numpy.ndarray
        (M,) float64.
    """
    edges = np.ascontiguousarray(np.asarray(edges, dtype=np.int64).reshape(-1, 2))
    cut = np.ascontiguousarray(np.broadcast_to(np.asarray(cut_cost, dtype=np.float64),
                                               edges.shape[:1]))
    return _payback(int(num_nodes), edges, cut, float(lambda_ * pairwise_scale))


def minimize_gc_ransac(f0: np.ndarray, data1: np.ndarray, edges: np.ndarray,
                       cut_cost: np.ndarray | float, lambda_: float,
                       pairwise_scale: float = 1.0, payback: np.ndarray | None = None,
                       with_energy: bool = True) -> tuple[np.ndarray, float | None]:
    """Exact minimiser and minimum of the (proximity) GC-RANSAC energy, without edge tables.

    The same energy as ``gc_ransac_energy(f0, f1, edges, cut_cost, lambda_, g1,
    pairwise_scale)`` with ``data1 = f1 + g1``, minimised as :func:`minimize` does, but built
    straight from its structure (e(1,1) = 0, e(0,1) = e(1,0)) instead of (E, 2, 2) tables, and
    on a smaller graph: a point whose extra data cost of the inlier label,
    ``(1-λ)(data1 - f0)``, exceeds everything its edges can ever pay back, ``λ s Σ_q w_pq``,
    is an outlier in *every* minimiser (turning it into an outlier always lowers the energy).
    Such points are fixed to 0 before the max-flow and their edges become unaries of their
    neighbours, which leaves the minimisers of the rest unchanged. With the normal term most
    points of other planes are fixed this way, which halves the max-flow graph.

    The max-flow starts from a flow rather than from none (:func:`_gc_ransac_network`, which
    builds the solver's network in the same pass): flow pushed straight from each
    outlier-preferring point to an inlier-preferring neighbour. Any starting flow gives the
    same cut (see :func:`monoplane.algorithm.mincut.min_cut_flows`); this one leaves less to
    search. (Starting the local optimisation's relabel from the flow of the
    labelling before it was measured too, and saved nothing: docs/evaluation.md.)

    Parameters
    ----------
    f0 : numpy.ndarray
        (M,) outlier costs f(0, p) in [0, 1] (:func:`msac_costs`).
    data1 : numpy.ndarray
        (M,) inlier costs f(1, p) + g(1, p) (:func:`msac_costs`, :func:`normal_costs`).
    edges : numpy.ndarray
        (E, 2) int node pairs among the M points.
    cut_cost : numpy.ndarray or float
        (E,) cost w_pq of labelling an edge's ends differently (or one for all edges).
    lambda_ : float
        Smoothness weight λ in [0, 1].
    pairwise_scale : float
        Positive factor s on the pairwise term.
    payback : numpy.ndarray, optional
        (M,) :func:`pool_payback` of these edges, cut costs, λ and s, when the caller keeps
        it; computed here when omitted.
    with_energy : bool
        False: the energy is not summed (a pass over every point and edge) and None is
        returned in its place; :func:`gc_ransac_cut_energy` gives it later.

    Returns
    -------
    labels : numpy.ndarray
        (M,) bool minimiser (True = inlier).
    energy : float or None
        Its energy (None without ``with_energy``).

    Raises
    ------
    InvalidInput
        If λ or s is out of range, or an edge's cut cost is below ¼(f(0,p) + f(0,q)), half
        its both-outlier cost (the energy is then not submodular).
    """
    if not 0.0 <= lambda_ <= 1.0:
        raise InvalidInput(f"lambda must lie in [0, 1], got {lambda_}")
    if not pairwise_scale > 0:
        raise InvalidInput(f"pairwise_scale must be positive, got {pairwise_scale}")
    f0, data1, edges, cut = _energy_arrays(f0, data1, edges, cut_cost)
    lam, ls = float(lambda_), float(lambda_ * pairwise_scale)
    # With f(0, p) <= 1 an edge whose cut costs at least 1/2 is submodular whatever the
    # hypothesis (2 λs w >= λs >= its both-outlier cost), so most calls check nothing.
    if edges.shape[0] and not (cut.min() >= 0.5 and f0.max() <= 1.0):
        bad = _non_submodular(f0, edges, cut, ls)
        if bad:
            raise InvalidInput(f"{bad} edge tables are not submodular; graph cuts cannot "
                               "minimise this energy")
    if payback is None:
        payback = _payback(f0.shape[0], edges, cut, ls)
    elif payback.shape != f0.shape:
        raise InvalidInput(f"payback must have one entry per point ({f0.shape[0]}), got "
                           f"{payback.shape}")
    # A positive slope makes label 1 (sink side) dearer: capacity on the source edge.
    nodes, first, head, sister, rcap, terminal = _gc_ransac_network(f0, data1, edges, cut, lam,
                                                                    ls, payback)
    labels = np.zeros(f0.shape[0], dtype=bool)
    if nodes.size:
        labels[nodes] = min_cut_arcs(first, head, sister, rcap, terminal)
    if not with_energy:
        return labels, None
    return labels, float(_gc_ransac_energy(f0, data1, edges, cut, lam, ls, labels))


def gc_ransac_cut_energy(f0: np.ndarray, data1: np.ndarray, edges: np.ndarray,
                         cut_cost: np.ndarray | float, lambda_: float, labels: np.ndarray,
                         pairwise_scale: float = 1.0) -> float:
    """The energy :func:`minimize_gc_ransac` returns with its minimiser, of any labelling.

    Parameters
    ----------
    f0, data1, edges, cut_cost, lambda_, pairwise_scale
        As for :func:`minimize_gc_ransac` (unvalidated).
    labels : numpy.ndarray
        (M,) bool labelling (True = inlier).

    Returns
    -------
    float
        Its energy, summed as :func:`minimize_gc_ransac` sums it (the same float).
    """
    f0, data1, edges, cut = _energy_arrays(f0, data1, edges, cut_cost)
    return float(_gc_ransac_energy(f0, data1, edges, cut, float(lambda_),
                                   float(lambda_ * pairwise_scale),
                                   np.ascontiguousarray(labels, dtype=np.bool_)))


def _energy_arrays(f0: np.ndarray, data1: np.ndarray, edges: np.ndarray,
                   cut_cost: np.ndarray | float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The arrays of :func:`minimize_gc_ransac`'s energy as its kernels take them: (M,) float64
    ``f0`` and ``data1``, (E, 2) int64 ``edges`` and (E,) float64 cut costs (a scalar
    broadcast), each contiguous."""
    edges = np.ascontiguousarray(np.asarray(edges, dtype=np.int64).reshape(-1, 2))
    cut = np.ascontiguousarray(np.broadcast_to(np.asarray(cut_cost, dtype=np.float64),
                                               edges.shape[:1]))
    return (np.ascontiguousarray(f0, dtype=np.float64),
            np.ascontiguousarray(data1, dtype=np.float64), edges, cut)


@kernel
def _payback(m: int, edges: np.ndarray, cut: np.ndarray, ls: float) -> np.ndarray:
    """(M,) λs Σ_q w_pq of each node over the (E, 2) int64 ``edges`` with (E,) cut costs, added
    in edge order (see :func:`pool_payback`)."""
    payback = np.zeros(m)
    for e in range(edges.shape[0]):
        b = ls * cut[e]
        payback[edges[e, 0]] += b
        payback[edges[e, 1]] += b
    return payback


def _non_submodular(f0: np.ndarray, edges: np.ndarray, cut: np.ndarray, ls: float) -> int:
    """How many edges cut cheaper than half their both-outlier cost (see
    :func:`minimize_gc_ransac`); rarely asked, so numpy."""
    a = 0.5 * ls * (f0[edges[:, 0]] + f0[edges[:, 1]])
    return int(np.count_nonzero(2.0 * (ls * cut) - a < -1e-9 * np.maximum(1.0, a)))


@kernel
def _gc_ransac_network(f0: np.ndarray, data1: np.ndarray, edges: np.ndarray, cut: np.ndarray,
                       lam: float, ls: float, payback: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                  np.ndarray]:
    """Max-flow network of :func:`minimize_gc_ransac` on its undecided points, warm-started.

    Inputs are float64 (M,) ``f0``, ``data1``, int64 (E, 2) ``edges``, float64 (E,) cut
    costs, λ, λs and the (M,) :func:`pool_payback`. Returns the (F,) pool positions of the
    undecided points and their network as :func:`monoplane.algorithm.mincut.min_cut_arcs`
    takes it: ``first`` (F + 1,), ``head``, ``sister``, ``rcap`` (2E',) of the E' edges among
    them, and the (F,) terminals, the cost slopes ``U(1) - U(0)`` less the starting flow.

    The starting flow: along each edge in order, as much flow as its capacity, its tail's
    source capacity and its head's sink capacity allow goes source -> tail -> head -> sink,
    the paths of length three the max-flow would otherwise find one search at a time. Any
    starting flow gives the same cut (see :func:`monoplane.algorithm.mincut.min_cut_flows`);
    this one leaves less to search. Slopes, arcs and pushes are taken in edge order, the
    arcs laid out as :func:`~monoplane.algorithm.mincut.min_cut` lays out an edge list's.
    """
    m, n_edges = f0.shape[0], edges.shape[0]
    ei, ej = edges[:, 0], edges[:, 1]
    keep = 1.0 - lam
    # int32 positions: the edge loop's random reads of them stay twice as dense in cache.
    local = np.full(m, -1, dtype=np.int32)
    count = 0
    for p in range(m):
        # Submodularity makes e(0,1) the most an edge gives back when its end turns inlier,
        # so u1 - u0 > Σ e(0,1) means outlier in every minimiser (kept with a margin).
        if keep * (data1[p] - f0[p]) <= payback[p] * (1.0 + 1e-9) + 1e-12:
            local[p] = count
            count += 1
    # Outputs are allocated at their size (counted first): untouched tails of oversized
    # buffers and the copies that trim them cost page faults on every call.
    nodes = np.empty(count, dtype=np.int64)
    terminal = np.empty(count)
    for p in range(m):
        q = local[p]
        if q >= 0:
            nodes[q] = p
            terminal[q] = keep * (data1[p] - f0[p])
    first = np.zeros(count + 1, dtype=np.int32)
    # The edges among undecided points, listed for the second pass (only the pages written
    # to are touched: a few percent of the buffer).
    inner = np.empty(n_edges, dtype=np.int32)
    n_inner = 0
    for e in range(n_edges):
        li, lj = local[ei[e]], local[ej[e]]
        if li < 0 and lj < 0:
            continue
        a = 0.5 * ls * (f0[ei[e]] + f0[ej[e]])
        b = ls * cut[e]
        if li >= 0 and lj >= 0:
            # e = A + (C - A) x_i + (D - C) x_j + (B + C - A - D)(1 - x_i) x_j, D = 0, B = C.
            inner[n_inner] = e
            n_inner += 1
            first[li + 1] += 1
            first[lj + 1] += 1
            terminal[li] += b - a
            terminal[lj] -= b
        else:
            # An edge to a fixed outlier costs e(0,0) = a or e(1,0) = b: a unary of its free end.
            terminal[max(li, lj)] += b - a
    for q in range(count):
        first[q + 1] += first[q]
    fill = first[1:].copy()
    arcs = first[count]
    head = np.empty(arcs, dtype=np.int32)
    sister = np.empty(arcs, dtype=np.int32)
    rcap = np.empty(arcs)
    for k in range(n_inner):
        e = inner[k]
        li, lj = local[ei[e]], local[ej[e]]
        a = 0.5 * ls * (f0[ei[e]] + f0[ej[e]])
        cap = max(2.0 * ls * cut[e] - a, 0.0)
        fill[li] -= 1
        x = fill[li]
        fill[lj] -= 1
        y = fill[lj]
        back = 0.0
        if terminal[li] > 0.0 and terminal[lj] < 0.0:
            push = min(terminal[li], -terminal[lj], cap)
            if push > 0.0:
                terminal[li] -= push
                terminal[lj] += push
                cap -= push
                back += push
        head[x], rcap[x], sister[x] = lj, cap, y
        head[y], rcap[y], sister[y] = li, back, x
    return nodes, first, head, sister, rcap, terminal


@kernel
def _gc_ransac_energy(f0: np.ndarray, data1: np.ndarray, edges: np.ndarray, cut: np.ndarray,
                      lam: float, ls: float, labels: np.ndarray) -> float:
    """Energy of a (M,) bool labelling for the inputs of :func:`_gc_ransac_network`."""
    ei, ej = edges[:, 0], edges[:, 1]
    total = 0.0
    for p in range(f0.shape[0]):
        total += (1.0 - lam) * (data1[p] if labels[p] else f0[p])
    for e in range(ei.shape[0]):
        li, lj = labels[ei[e]], labels[ej[e]]
        if not li and not lj:
            total += 0.5 * ls * (f0[ei[e]] + f0[ej[e]])
        elif li != lj:
            total += ls * cut[e]
    return total
