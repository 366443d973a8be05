"""Mean-field inference of a Potts CRF on a sparse graph, over a short list of labels per node.

The energy is ``E(l) = Σ_i U_i(l_i) + β Σ_(i,j) w_ij [l_i ≠ l_j]`` on an undirected graph with
weights ``w_ij >= 0``. One mean-field update gives every node

    q_i(l) ∝ exp(-e_i(l) / T),    e_i(l) = U_i(l) - β Σ_j w_ij q_j(l)

(the Potts term's ``β Σ_j w_ij`` is the same for every label and cancels in the softmax).

**Which labels can matter at a node.** Since ``0 <= q_j(l) <= 1``, every label satisfies
``U_i(l) - β d_i <= e_i(l) <= U_i(l)`` with ``d_i = Σ_j w_ij``. So a label with
``U_i(l) > min_k U_i(k) + β d_i + m`` has ``e_i(l) > e_i(k*) + m`` and probability below
``exp(-m / T)`` after every update, whatever its neighbours hold. With ``m = 30 T`` that is
below 1e-13, under the rounding of a float32 probability near 1: such a label changes no sum
and no argmax. A node then carries only its other labels (and the one it starts with), which on
a range image of 40 planes is 2-4 of 41, so an iteration costs ``O(Σ_i deg_i (K_i + K_j))``
instead of ``O(E L)``.
"""

from __future__ import annotations

import functools

import numpy as np

from monoplane.jit import chunks, inline, kernel, run_threaded

#: Margin of the label bound, in units of the temperature: a dropped label has probability
#: below exp(-30) ≈ 1e-13 at every update (module docstring).
MARGIN_TEMPERATURES = 30.0

#: Nodes per thread below which an iteration runs on one thread.
_THREADED_NODES = 4096


def candidate_labels(unary: np.ndarray, start: np.ndarray, indptr: np.ndarray,
                     weights: np.ndarray, beta: float, temperature: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The labels each node can hold with non-negligible probability (module docstring).

    Parameters
    ----------
    unary : numpy.ndarray
        (N, L) float32 data costs U.
    start : numpy.ndarray
        (N,) int labels 0..L-1 the inference starts from; always kept.
    indptr, weights : numpy.ndarray
        Row starts (N + 1,) int64 and (2E,) float32 weights of the symmetric CSR adjacency.
    beta, temperature : float
        Pairwise weight β and temperature T (> 0).

    Returns
    -------
    ptr : numpy.ndarray
        (N + 1,) int64: node ``i``'s labels are ``labels[ptr[i]:ptr[i + 1]]``.
    labels : numpy.ndarray
        (M,) int32 label ids, ascending within each node.
    costs : numpy.ndarray
        (M,) float32 their data costs.
    """
    return _candidates(np.ascontiguousarray(unary, dtype=np.float32),
                       np.ascontiguousarray(start, dtype=np.int64),
                       np.ascontiguousarray(indptr, dtype=np.int64),
                       np.ascontiguousarray(weights, dtype=np.float32), float(beta),
                       MARGIN_TEMPERATURES * float(temperature))


def potts_mean_field(ptr: np.ndarray, labels: np.ndarray, costs: np.ndarray,
                     indptr: np.ndarray, indices: np.ndarray, weights: np.ndarray,
                     start: np.ndarray, beta: float, temperature: float, iterations: int,
                     settle: float = 0.0) -> np.ndarray:
    """Labels after ``iterations`` mean-field updates on the candidate lists.

    Parameters
    ----------
    ptr, labels, costs : numpy.ndarray
        The candidate lists of :func:`candidate_labels`.
    indptr, indices, weights : numpy.ndarray
        Symmetric CSR adjacency: (N + 1,) int64, (2E,) int64, (2E,) float32.
    start : numpy.ndarray
        (N,) int starting labels. A node starting at label 0 starts from its data term alone
        (softmax of ``-U / T``), any other from certainty in its label.
    beta, temperature : float
        Pairwise weight β and temperature T (> 0).
    iterations : int
        Number of updates; with 0 the labels are ``start``.
    settle : float
        A node whose probabilities all moved by at most this in an update counts as
        unchanged, so its neighbours skip their next update unless another neighbour moved
        (0: only a node whose probabilities repeat to the bit; exact).

    Returns
    -------
    numpy.ndarray
        (N,) int32 label of highest probability (the lowest id among ties).
    """
    start = np.ascontiguousarray(start, dtype=np.int64)
    q = _initial(ptr, labels, costs, start, np.float32(-1.0 / temperature))
    if iterations == 0:
        return _argmax(ptr, labels, q)
    weight, scale = np.float32(-beta), np.float32(-1.0 / temperature)
    # The first update changes every node: all of them, on the frame's threads.
    out = np.empty_like(q)
    moved = np.empty(start.size, dtype=np.bool_)
    run_threaded([functools.partial(_update, ptr, labels, costs, indptr, indices, weights,
                                    q, weight, scale, a, b, out, moved, np.float32(settle))
                  for a, b in chunks(start.size, _THREADED_NODES)])
    # A node's update reads only its neighbours' probabilities: when none of them changed in
    # the last iteration, its result would be the same to the bit, so only the neighbours of
    # the nodes that moved are updated: on the lattice of a 640x480 range frame with
    # ``settle`` 1e-4, 5-20 % of the nodes move in the first iteration and 1-3 % in the last.
    # With ``settle`` > 0, nodes still moving in their last float32 bits count as unchanged.
    moved_nodes = np.flatnonzero(moved)
    seen = np.full(start.size, -1, dtype=np.int64)
    for it in range(1, iterations):
        due, slots = _due_nodes(ptr, indptr, indices, moved_nodes, seen, it)
        new = np.empty(slots[-1], dtype=np.float32)
        run_threaded([functools.partial(_update_due, ptr, labels, costs, indptr, indices,
                                        weights, out, weight, scale, due, slots, a, b, new)
                      for a, b in chunks(due.size, _THREADED_NODES)])
        moved_nodes = _write_back(ptr, out, due, slots, new, np.float32(settle))
    return _argmax(ptr, labels, out)


@kernel
def _candidates(unary: np.ndarray, start: np.ndarray, indptr: np.ndarray, weights: np.ndarray,
                beta: float, margin: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`candidate_labels` after its conversions; ``margin`` is m (module docstring)."""
    n, num = unary.shape
    bound = np.empty(n, dtype=np.float64)
    ptr = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        low = np.inf
        for k in range(num):
            low = min(low, unary[i, k])
        degree = 0.0
        for jj in range(indptr[i], indptr[i + 1]):
            degree += weights[jj]
        bound[i] = low + beta * degree + margin
        kept = 0
        for k in range(num):
            if k == start[i] or unary[i, k] <= bound[i]:
                kept += 1
        ptr[i + 1] = ptr[i] + kept
    labels = np.empty(ptr[n], dtype=np.int32)
    costs = np.empty(ptr[n], dtype=np.float32)
    for i in range(n):
        s = ptr[i]
        for k in range(num):
            if k == start[i] or unary[i, k] <= bound[i]:
                labels[s] = k
                costs[s] = unary[i, k]
                s += 1
    return ptr, labels, costs


@kernel
def _initial(ptr: np.ndarray, labels: np.ndarray, costs: np.ndarray, start: np.ndarray,
             scale: np.float32) -> np.ndarray:
    """(M,) float32 starting probabilities (see :func:`potts_mean_field`)."""
    q = np.zeros(labels.size, dtype=np.float32)
    for i in range(start.size):
        a, b = ptr[i], ptr[i + 1]
        if start[i] != 0:
            for s in range(a, b):
                if labels[s] == start[i]:
                    q[s] = 1.0
            continue
        low = np.float32(np.inf)
        for s in range(a, b):
            low = min(low, costs[s])
        total = np.float32(0.0)
        for s in range(a, b):
            q[s] = np.exp((costs[s] - low) * scale)
            total += q[s]
        for s in range(a, b):
            q[s] /= total
    return q


@inline
def _node_update(ptr: np.ndarray, labels: np.ndarray, costs: np.ndarray, indptr: np.ndarray,
                 indices: np.ndarray, weights: np.ndarray, q: np.ndarray, weight: np.float32,
                 scale: np.float32, i: int, out: np.ndarray, o: int) -> None:
    """Node ``i``'s new probabilities from ``q`` (M,) float32 into ``out[o + s]`` (float32)
    for each of its slots ``s``: the Potts messages of its neighbours' shared labels, then a
    softmax of weight × messages + costs. The two nodes' label lists are ascending, so one
    merge pass finds the labels they share."""
    a, b = ptr[i], ptr[i + 1]
    for s in range(a, b):
        out[o + s] = 0.0
    for jj in range(indptr[i], indptr[i + 1]):
        j = indices[jj]
        w = weights[jj]
        s, t, t_end = a, ptr[j], ptr[j + 1]
        while s < b and t < t_end:
            if labels[s] < labels[t]:
                s += 1
            elif labels[s] > labels[t]:
                t += 1
            else:
                out[o + s] += w * q[t]
                s += 1
                t += 1
    low = np.float32(np.inf)
    for s in range(a, b):
        out[o + s] = out[o + s] * weight + costs[s]
        low = min(low, out[o + s])
    total = np.float32(0.0)
    for s in range(a, b):
        out[o + s] = np.exp((out[o + s] - low) * scale)
        total += out[o + s]
    for s in range(a, b):
        out[o + s] /= total


@kernel
def _update(ptr: np.ndarray, labels: np.ndarray, costs: np.ndarray, indptr: np.ndarray,
            indices: np.ndarray, weights: np.ndarray, q: np.ndarray, weight: np.float32,
            scale: np.float32, row0: int, row1: int, out: np.ndarray, changed_out: np.ndarray,
            settle: np.float32) -> None:
    """One update of nodes ``row0:row1`` (:func:`_node_update`): ``out`` (M,) float32 from
    ``q`` (M,) float32.

    ``changed_out`` (N,) bool receives whether each node's probabilities changed by more than
    ``settle`` (0: changed at all).
    """
    for i in range(row0, row1):
        _node_update(ptr, labels, costs, indptr, indices, weights, q, weight, scale, i, out, 0)
        moved = False
        for s in range(ptr[i], ptr[i + 1]):
            moved = moved or abs(out[s] - q[s]) > settle
        changed_out[i] = moved


@kernel
def _due_nodes(ptr: np.ndarray, indptr: np.ndarray, indices: np.ndarray, moved: np.ndarray,
               seen: np.ndarray, mark: int) -> tuple[np.ndarray, np.ndarray]:
    """The (K,) int64 nodes next to some of the ``moved`` nodes, each once, and (K + 1,)
    int64 ``slots``: node k's new probabilities go to ``slots[k]:slots[k + 1]`` of a buffer.
    ``seen`` (N,) int64 holds no ``mark`` before the call (it is left holding it at those
    nodes)."""
    reach = 0
    for c in moved:
        reach += indptr[c + 1] - indptr[c]
    due = np.empty(reach, dtype=np.int64)
    slots = np.empty(reach + 1, dtype=np.int64)
    slots[0] = 0
    count = 0
    for c in moved:
        for jj in range(indptr[c], indptr[c + 1]):
            i = indices[jj]
            if seen[i] != mark:
                seen[i] = mark
                due[count] = i
                slots[count + 1] = slots[count] + ptr[i + 1] - ptr[i]
                count += 1
    return due[:count], slots[:count + 1]


@kernel
def _update_due(ptr: np.ndarray, labels: np.ndarray, costs: np.ndarray, indptr: np.ndarray,
                indices: np.ndarray, weights: np.ndarray, q: np.ndarray, weight: np.float32,
                scale: np.float32, due: np.ndarray, slots: np.ndarray, k0: int, k1: int,
                new: np.ndarray) -> None:
    """The update (:func:`_node_update`) of the nodes ``due[k0:k1]`` (:func:`_due_nodes`),
    from ``q`` (M,) float32 into their ``slots`` of ``new`` (float32)."""
    for k in range(k0, k1):
        i = due[k]
        # Slot s of node i is new[slots[k] - ptr[i] + s].
        _node_update(ptr, labels, costs, indptr, indices, weights, q, weight, scale, i, new,
                     slots[k] - ptr[i])


@kernel
def _write_back(ptr: np.ndarray, q: np.ndarray, due: np.ndarray, slots: np.ndarray,
                new: np.ndarray, settle: np.float32) -> np.ndarray:
    """Write the ``due`` nodes' ``new`` probabilities (:func:`_update_due`) into ``q``; the
    int64 nodes among them whose probabilities moved by more than ``settle``."""
    changed = np.empty(due.shape[0], dtype=np.int64)
    count = 0
    for k in range(due.shape[0]):
        i = due[k]
        o = slots[k] - ptr[i]
        shifted = False
        for s in range(ptr[i], ptr[i + 1]):
            shifted = shifted or abs(new[o + s] - q[s]) > settle
            q[s] = new[o + s]
        if shifted:
            changed[count] = i
            count += 1
    return changed[:count]


@kernel
def _argmax(ptr: np.ndarray, labels: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(N,) int32 label of the largest probability of each node, lowest id among ties."""
    n = ptr.size - 1
    out = np.zeros(n, dtype=np.int32)
    for i in range(n):
        best = np.float32(-1.0)
        for s in range(ptr[i], ptr[i + 1]):
            if q[s] > best:
                best = q[s]
                out[i] = labels[s]
    return out
