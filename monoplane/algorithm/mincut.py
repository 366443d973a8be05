"""Exact s-t minimum cut of a sparse graph: the Boykov-Kolmogorov max-flow, compiled.

The graph-cut labelers solve one binary energy per plane hypothesis, on graphs of a few hundred
to about ten thousand nodes. Through PyMaxflow, even with its vectorised ``add_edges``,
building those graphs takes longer than its C++ solve saves over this one (figures and the
command in docs/design.md); here the graph arrives as arrays, possibly as the residual of a
starting flow, and is solved in one compiled call.

Algorithm: Boykov and Kolmogorov, "An Experimental Comparison of Min-Cut/Max-Flow Algorithms
for Energy Minimization in Vision" (PAMI 2004), in the form of Kolmogorov's reference
implementation (maxflow 3.0x, which PyMaxflow wraps): two search trees grown from the
terminals in first-in first-out order, augmentation along the path where they meet, adoption
of orphans with the distance and timestamp heuristics. Arcs are visited in the order that
implementation stores them (each node's arcs newest first) and every step is taken in the same
order, so the flow, the residual capacities and hence the returned cut are bit for bit those
of PyMaxflow's ``Graph[float]`` for the same edges added in the same order; the tests check
this on random graphs.

Which minimum cut: a node is on the sink side iff it belongs to the sink search tree when the
search ends, i.e. iff the sink is reachable from it in the residual graph. Among all minimum
cuts this puts the fewest nodes on the sink side.
"""

from __future__ import annotations

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.jit import inline, kernel

#: Values of ``parent`` for nodes without a parent arc.
_FREE, _TERMINAL, _ORPHAN = -1, -2, -3
#: Distance of a node whose origin is not a terminal.
_INFINITE_D = 2**31 - 1


def min_cut(num_nodes: int, tails: np.ndarray, heads: np.ndarray, caps: np.ndarray,
            rev_caps: np.ndarray, terminal: np.ndarray, validate: bool = True
            ) -> tuple[float, np.ndarray]:
    """Maximum flow and a minimum cut of a graph with terminal edges.

    Parameters
    ----------
    num_nodes : int
        Number N of non-terminal nodes.
    tails, heads : numpy.ndarray
        (E,) int node indices in [0, N) of each edge's ends.
    caps, rev_caps : numpy.ndarray
        (E,) non-negative float capacities of each edge from tail to head and back.
    terminal : numpy.ndarray
        (N,) float terminal capacity of each node: ``c(source → i) - c(i → sink)``; a
        positive value links the node to the source, a negative one to the sink. (A node with
        both terminal edges contributes ``min`` of the two to the flow and only their
        difference to the cut; add that constant yourself.)
    validate : bool
        Check ranges and capacities (callers that build the graph themselves, such as the
        graph-cut labelers on every hypothesis, skip the checks).

    Returns
    -------
    flow : float
        Value of the maximum flow (equal to the capacity of the minimum cut).
    sink_side : numpy.ndarray
        (N,) bool, True for the nodes on the sink side of the cut.

    Raises
    ------
    InvalidInput
        If shapes disagree, an index is out of range or a capacity is negative or not finite.
    """
    tails = np.ascontiguousarray(tails, dtype=np.int64).ravel()
    heads = np.ascontiguousarray(heads, dtype=np.int64).ravel()
    caps = np.ascontiguousarray(caps, dtype=np.float64).ravel()
    rev_caps = np.ascontiguousarray(rev_caps, dtype=np.float64).ravel()
    terminal = np.ascontiguousarray(terminal, dtype=np.float64).ravel()
    n_edges = tails.shape[0]
    _check_size(num_nodes, n_edges)
    if not validate:
        flow, sink_side, _ = _bk_min_cut(int(num_nodes), tails, heads, caps, rev_caps,
                                         terminal)
        return float(flow), sink_side
    if heads.shape[0] != n_edges or caps.shape[0] != n_edges or rev_caps.shape[0] != n_edges:
        raise InvalidInput(f"min_cut: tails, heads, caps and rev_caps must have one length, got "
                           f"{tails.shape[0]}, {heads.shape[0]}, {caps.shape[0]}, "
                           f"{rev_caps.shape[0]}")
    if terminal.shape[0] != num_nodes:
        raise InvalidInput(f"min_cut: terminal has {terminal.shape[0]} entries for "
                           f"{num_nodes} nodes")
    if n_edges and (min(tails.min(), heads.min()) < 0
                    or max(tails.max(), heads.max()) >= num_nodes):
        raise InvalidInput(f"min_cut: edge ends must lie in [0, {num_nodes})")
    if not (np.isfinite(terminal).all() and np.isfinite(caps).all()
            and np.isfinite(rev_caps).all()):
        raise InvalidInput("min_cut: capacities must be finite")
    if n_edges and min(caps.min(), rev_caps.min()) < 0:
        raise InvalidInput("min_cut: edge capacities must be non-negative")
    flow, sink_side, _ = _bk_min_cut(int(num_nodes), tails, heads, caps, rev_caps, terminal)
    return float(flow), sink_side


def min_cut_flows(num_nodes: int, tails: np.ndarray, heads: np.ndarray, caps: np.ndarray,
                  rev_caps: np.ndarray, terminal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`min_cut` (unvalidated input) that also returns each edge's final flow.

    For warm starts: a graph whose edges carry a flow ``phi`` may be given as its residual,
    ``caps - phi`` forward, ``rev_caps + phi`` backward, with ``phi`` moved into the
    terminals of its ends (``terminal[tail] -= phi``, ``terminal[head] += phi``). That graph
    has the same minimum cuts, and the same cut comes back (the sink side is what reaches the
    sink in the final residual graph, the smallest sink side of any minimum cut), with less
    flow left to find. That is exact in exact arithmetic; in floating point two minimum cuts
    that tie (or differ by rounding) may be told apart differently after different flows.

    Parameters
    ----------
    num_nodes, tails, heads, caps, rev_caps, terminal
        As for :func:`min_cut`, already int64 / float64 and checked by the caller.

    Returns
    -------
    sink_side : numpy.ndarray
        (N,) bool, True for the nodes on the sink side of the cut.
    reverse : numpy.ndarray
        (E,) float64 residual capacity of each edge from head to tail at the end:
        ``rev_caps`` plus the flow the solve sent from tail to head.
    """
    _check_size(num_nodes, tails.shape[0])
    _, sink_side, reverse = _bk_min_cut(int(num_nodes), tails, heads, caps, rev_caps,
                                        terminal)
    return sink_side, reverse


def min_cut_arcs(first: np.ndarray, head: np.ndarray, sister: np.ndarray, rcap: np.ndarray,
                 terminal: np.ndarray) -> np.ndarray:
    """:func:`min_cut` (unvalidated input) of a graph already laid out as the solver's arcs.

    For callers that build the network themselves in one pass (the graph-cut labelers):
    the arrays :func:`min_cut` would build from edge lists, and the same cut.

    Parameters
    ----------
    first : numpy.ndarray
        (N + 1,) int32: node i's arcs are the slots ``first[i]:first[i + 1]``. For the cut of
        :func:`min_cut` bit for bit, they must be in the order it stores them: edges taken in
        order, each edge's tail -> head arc and head -> tail arc put at the last free slot of
        their tail's and head's range (so each node's arcs run newest first).
    head : numpy.ndarray
        (2E,) int32 node an arc points to.
    sister : numpy.ndarray
        (2E,) int32 slot of the opposite arc.
    rcap : numpy.ndarray
        (2E,) float64 residual capacity of each arc (overwritten by the final residual).
    terminal : numpy.ndarray
        (N,) float64 terminal capacities as for :func:`min_cut` (overwritten).

    Returns
    -------
    numpy.ndarray
        (N,) bool, True for the nodes on the sink side of the cut.
    """
    _check_size(terminal.shape[0], head.shape[0] // 2)
    return _bk_arcs_min_cut(first, head, sister, rcap, terminal)


def _check_size(num_nodes: int, num_edges: int) -> None:
    """The solver numbers nodes and arcs (two per edge) in int32."""
    if num_nodes >= 2**31 or 2 * num_edges >= 2**31:
        raise InvalidInput(f"min_cut: {num_nodes} nodes and {num_edges} edges; at most 2^31 "
                           "nodes and 2^30 edges")


@kernel
def _bk_min_cut(n: int, tails: np.ndarray, heads: np.ndarray, caps: np.ndarray,
                rev_caps: np.ndarray, terminal: np.ndarray
                ) -> tuple[float, np.ndarray, np.ndarray]:
    """:func:`min_cut` on validated int64 / float64 arrays, and the (E,) final residual
    capacities from head to tail (:func:`min_cut_flows`): :func:`_arcs` then
    :func:`_bk_search`."""
    first, head, sister, rcap, forward = _arcs(n, tails, heads, caps, rev_caps)
    flow, sink_side = _bk_search(n, first, head, sister, rcap, terminal.copy())
    reverse = np.empty(tails.shape[0])
    for e in range(tails.shape[0]):
        reverse[e] = rcap[sister[forward[e]]]
    return flow, sink_side, reverse


@kernel
def _bk_arcs_min_cut(first: np.ndarray, head: np.ndarray, sister: np.ndarray,
                     rcap: np.ndarray, terminal: np.ndarray) -> np.ndarray:
    """:func:`min_cut_arcs`: the (N,) bool sink side; ``rcap`` and ``terminal`` are
    consumed (left as the final residual)."""
    return _bk_search(terminal.shape[0], first, head, sister, rcap, terminal)[1]


@inline
def _arcs(n: int, tails: np.ndarray, heads: np.ndarray, caps: np.ndarray,
          rev_caps: np.ndarray
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The arc arrays of :func:`min_cut_arcs` for (E,) edges given as ends and capacities,
    and the (E,) int64 slot of each edge's tail -> head arc.

    Each node's arcs, newest first (the order the reference implementation visits them).
    Node and arc indices are int32: the arrays the search walks stay half as large, which
    makes it about 10 % faster (:func:`_check_size` holds the graph to that).
    """
    m = tails.shape[0]
    first = np.zeros(n + 1, dtype=np.int32)
    for e in range(m):
        first[tails[e] + 1] += 1
        first[heads[e] + 1] += 1
    for i in range(n):
        first[i + 1] += first[i]
    fill = first[1:].copy()
    forward = np.empty(m, dtype=np.int64)  # each edge's tail -> head arc
    sister = np.empty(2 * m, dtype=np.int32)
    head = np.empty(2 * m, dtype=np.int32)
    rcap = np.empty(2 * m)
    for e in range(m):
        u, v = tails[e], heads[e]
        fill[u] -= 1
        a = fill[u]
        fill[v] -= 1
        b = fill[v]
        head[a], rcap[a], sister[a] = v, caps[e], b
        forward[e] = a
        head[b], rcap[b], sister[b] = u, rev_caps[e], a
    return first, head, sister, rcap, forward


@inline
def _bk_search(n: int, first: np.ndarray, head: np.ndarray, sister: np.ndarray,
               rcap: np.ndarray, tr: np.ndarray) -> tuple[float, np.ndarray]:
    """The Boykov-Kolmogorov search on an arc network (layout of :func:`min_cut_arcs`):
    the flow and the (N,) bool sink side; ``rcap`` and the terminals ``tr`` end as the
    final residual.

    ``parent[i]`` is the arc from i towards its parent in its search tree, or ``_FREE``,
    ``_TERMINAL`` or ``_ORPHAN``.
    """
    parent = np.full(n, _FREE, dtype=np.int32)
    is_sink = np.zeros(n, dtype=np.bool_)
    ts = np.zeros(n, dtype=np.int64)
    dist = np.zeros(n, dtype=np.int32)
    # Active nodes: one FIFO ring (the reference's two queues pop in the same order);
    # ``flagged`` marks queued nodes and the current node.
    size = n + 1  # ring buffers: at most n entries at a time, empty when head == tail
    queue = np.empty(size, dtype=np.int32)
    q_head = 0
    q_tail = 0
    flagged = np.zeros(n, dtype=np.bool_)
    # Orphans: those an augmentation creates (taken newest first), each followed by the
    # orphans its adoption creates (first in, first out).
    found = np.empty(n, dtype=np.int32)
    orphans = np.empty(size, dtype=np.int32)
    clock = 0
    flow = 0.0
    for i in range(n):
        if tr[i] != 0.0:
            is_sink[i] = tr[i] < 0.0
            parent[i] = _TERMINAL
            dist[i] = 1
            queue[q_tail] = i
            q_tail += 1
            flagged[i] = True
    # A node whose growth found a path is grown again next, until it finds none.
    current = -1
    while True:
        i = current
        if i >= 0:
            flagged[i] = False
            if parent[i] == _FREE:
                i = -1
        while i < 0 and q_head != q_tail:
            j = queue[q_head]
            q_head += 1
            if q_head == size:
                q_head = 0
            flagged[j] = False
            if parent[j] != _FREE:
                i = j
        if i < 0:
            break
        # Growth along the residual arcs leaving i's tree (out of i in the source tree, into
        # i in the sink tree): the first arc to the other tree is the middle of a path.
        middle = -1
        sink = is_sink[i]
        for a in range(first[i], first[i + 1]):
            if rcap[sister[a] if sink else a] == 0.0:
                continue
            j = head[a]
            if parent[j] == _FREE:
                is_sink[j] = sink
                parent[j] = sister[a]
                ts[j] = ts[i]
                dist[j] = dist[i] + 1
                if not flagged[j]:
                    queue[q_tail] = j
                    q_tail += 1
                    if q_tail == size:
                        q_tail = 0
                    flagged[j] = True
            elif is_sink[j] != sink:
                middle = sister[a] if sink else a  # oriented source tree -> sink tree
                break
            elif ts[j] <= ts[i] and dist[j] > dist[i]:
                parent[j] = sister[a]
                ts[j] = ts[i]
                dist[j] = dist[i] + 1
        clock += 1
        if middle < 0:
            current = -1
            continue
        flagged[i] = True
        current = i
        # Augmentation: the bottleneck along source root -> middle arc -> sink root.
        bottleneck = rcap[middle]
        j = head[sister[middle]]
        while parent[j] != _TERMINAL:
            a = parent[j]
            if bottleneck > rcap[sister[a]]:
                bottleneck = rcap[sister[a]]
            j = head[a]
        if bottleneck > tr[j]:
            bottleneck = tr[j]
        j = head[middle]
        while parent[j] != _TERMINAL:
            a = parent[j]
            if bottleneck > rcap[a]:
                bottleneck = rcap[a]
            j = head[a]
        if bottleneck > -tr[j]:
            bottleneck = -tr[j]
        rcap[sister[middle]] += bottleneck
        rcap[middle] -= bottleneck
        n_found = 0
        j = head[sister[middle]]
        while parent[j] != _TERMINAL:
            a = parent[j]
            rcap[a] += bottleneck
            rcap[sister[a]] -= bottleneck
            nxt = head[a]
            if rcap[sister[a]] == 0.0:
                parent[j] = _ORPHAN
                found[n_found] = j
                n_found += 1
            j = nxt
        tr[j] -= bottleneck
        if tr[j] == 0.0:
            parent[j] = _ORPHAN
            found[n_found] = j
            n_found += 1
        j = head[middle]
        while parent[j] != _TERMINAL:
            a = parent[j]
            rcap[sister[a]] += bottleneck
            rcap[a] -= bottleneck
            nxt = head[a]
            if rcap[a] == 0.0:
                parent[j] = _ORPHAN
                found[n_found] = j
                n_found += 1
            j = nxt
        tr[j] += bottleneck
        if tr[j] == 0.0:
            parent[j] = _ORPHAN
            found[n_found] = j
            n_found += 1
        flow += bottleneck
        # Adoption.
        for f in range(n_found - 1, -1, -1):
            orphans[0] = found[f]
            o_head = 0
            o_tail = 1
            while o_head != o_tail:
                o = orphans[o_head]
                o_head += 1
                if o_head == size:
                    o_head = 0
                sink = is_sink[o]
                best = -1
                d_min = _INFINITE_D
                for a0 in range(first[o], first[o + 1]):
                    # The residual arc that would carry flow from the candidate parent to o
                    # (source tree) or from o to it (sink tree).
                    if rcap[a0 if sink else sister[a0]] == 0.0:
                        continue
                    j = head[a0]
                    if is_sink[j] != sink or parent[j] == _FREE:
                        continue
                    d = 0
                    while True:
                        if ts[j] == clock:
                            d += dist[j]
                            break
                        a = parent[j]
                        d += 1
                        if a == _TERMINAL:
                            ts[j] = clock
                            dist[j] = 1
                            break
                        if a == _ORPHAN:
                            d = _INFINITE_D
                            break
                        j = head[a]
                    if d < _INFINITE_D:
                        if d < d_min:
                            best = a0
                            d_min = d
                        j = head[a0]
                        while ts[j] != clock:
                            ts[j] = clock
                            dist[j] = d
                            d -= 1
                            j = head[parent[j]]
                if best >= 0:
                    parent[o] = best
                    ts[o] = clock
                    dist[o] = d_min + 1
                    continue
                parent[o] = _FREE
                for a0 in range(first[o], first[o + 1]):
                    j = head[a0]
                    a = parent[j]
                    if is_sink[j] != sink or a == _FREE:
                        continue
                    if rcap[a0 if sink else sister[a0]] != 0.0 and not flagged[j]:
                        queue[q_tail] = j
                        q_tail += 1
                        if q_tail == size:
                            q_tail = 0
                        flagged[j] = True
                    if a >= 0 and head[a] == o:
                        parent[j] = _ORPHAN
                        orphans[o_tail] = j
                        o_tail += 1
                        if o_tail == size:
                            o_tail = 0
    sink_side = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        sink_side[i] = is_sink[i] and parent[i] != _FREE
    return flow, sink_side
