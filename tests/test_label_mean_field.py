"""Mean field on candidate label lists against the dense update over every label."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse import coo_matrix

from monoplane.algorithm import label_mean_field
from monoplane.algorithm.label_mean_field import (
    MARGIN_TEMPERATURES,
    _argmax,
    _initial,
    _update,
    candidate_labels,
    potts_mean_field,
)


def dense_mean_field(unary, adj, start, beta, temperature, iterations):
    """The textbook update over all labels: q_i ∝ exp(-(U_i - β (W Q)_i) / T)."""
    q = np.zeros(unary.shape)
    q[np.arange(start.size), start] = 1.0
    free = start == 0
    e = unary[free] - unary[free].min(axis=1, keepdims=True)
    q[free] = np.exp(-e / temperature)
    q[free] /= q[free].sum(axis=1, keepdims=True)
    for _ in range(iterations):
        e = unary - beta * (adj @ q)
        q = np.exp(-(e - e.min(axis=1, keepdims=True)) / temperature)
        q /= q.sum(axis=1, keepdims=True)
    return np.argmax(q, axis=1), q


def random_problem(seed, n=400, labels=12, degree=6):
    """A random weighted graph and data costs where each node is near a few labels only."""
    rng = np.random.default_rng(seed)
    i = rng.integers(0, n, n * degree // 2)
    j = rng.integers(0, n, n * degree // 2)
    keep = i != j
    w = rng.uniform(0.5, 3.0, keep.sum())
    adj = coo_matrix((np.r_[w, w], (np.r_[i[keep], j[keep]], np.r_[j[keep], i[keep]])),
                     shape=(n, n)).tocsr()
    adj.sum_duplicates()
    unary = rng.uniform(0.0, 40.0, (n, labels)).astype(np.float32)
    unary[:, 0] = 1.0
    near = rng.integers(1, labels, (n, 2))
    unary[np.arange(n)[:, None], near] = rng.uniform(0.0, 2.0, (n, 2))
    start = np.where(rng.random(n) < 0.3, 0, near[:, 0])
    return unary, adj, start


BETA, TEMPERATURE = 0.3, 0.2


def candidate_problem(seed):
    """:func:`random_problem` ``seed``, its candidate lists ``(ptr, cand, costs)`` at
    :data:`BETA` and :data:`TEMPERATURE`, and the graph as the kernels take it."""
    unary, adj, start = random_problem(seed)
    ptr, cand, costs = candidate_labels(unary, start, adj.indptr, adj.data, BETA, TEMPERATURE)
    graph = (adj.indptr.astype(np.int64), adj.indices.astype(np.int64),
             adj.data.astype(np.float32))
    return unary, adj, start, (ptr, cand, costs), graph


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_candidate_mean_field_matches_the_dense_one(seed):
    unary, adj, start, (ptr, cand, costs), graph = candidate_problem(seed)
    got = potts_mean_field(ptr, cand, costs, *graph, start, BETA, TEMPERATURE, 6)
    want, q = dense_mean_field(unary.astype(np.float64), adj, start, BETA, TEMPERATURE, 6)
    # Only the clear winners are compared: float32 against float64 may swap near-ties.
    top2 = np.sort(q, axis=1)[:, -2:]
    clear = top2[:, 1] - top2[:, 0] > 1e-3
    assert clear.mean() > 0.9
    np.testing.assert_array_equal(got[clear], want[clear])
    # The lists are short: most labels of most nodes were dropped.
    assert ptr[-1] < 0.5 * unary.size


def test_dropped_labels_are_beyond_the_bound_and_start_labels_kept():
    unary, adj, start, (ptr, cand, costs), _ = candidate_problem(3)
    degree = np.asarray(adj.sum(axis=1)).ravel()
    bound = unary.min(axis=1) + BETA * degree + MARGIN_TEMPERATURES * TEMPERATURE
    for i in range(start.size):
        kept = cand[ptr[i]:ptr[i + 1]]
        assert np.all(np.diff(kept) > 0)
        assert start[i] in kept
        np.testing.assert_array_equal(costs[ptr[i]:ptr[i + 1]], unary[i, kept])
        dropped = np.setdiff1d(np.arange(unary.shape[1]), kept)
        assert np.all(unary[i, dropped] > bound[i] - 1e-4)


def test_zero_iterations_return_the_start():
    _, _, start, lists, graph = candidate_problem(4)
    got = potts_mean_field(*lists, *graph, start, BETA, TEMPERATURE, 0)
    moved = start != 0
    np.testing.assert_array_equal(got[moved], start[moved])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_settled_nodes_skip_updates_and_keep_the_clear_winners(seed):
    unary, adj, start, lists, graph = candidate_problem(seed)

    def run(iterations, *settle):
        return potts_mean_field(*lists, *graph, start, BETA, TEMPERATURE, iterations, *settle)

    exact = run(8)
    # settle = 0 is the exact skip; a tolerance can only change near-ties.
    np.testing.assert_array_equal(run(8, 0.0), exact)
    settled = run(8, 1e-4)
    _, q = dense_mean_field(unary.astype(np.float64), adj, start, BETA, TEMPERATURE, 8)
    top2 = np.sort(q, axis=1)[:, -2:]
    clear = top2[:, 1] - top2[:, 0] > 1e-2
    np.testing.assert_array_equal(settled[clear], exact[clear])
    # A tolerance of 1 counts every node as settled after the first update: the labels are
    # those of one update.
    np.testing.assert_array_equal(run(8, 1.0), run(1))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_updating_only_the_neighbours_of_moved_nodes_is_updating_every_node(seed, monkeypatch):
    # After the first update only the nodes next to one that moved are updated: with
    # settle = 0 (moved at all) that is, bit for bit, the update of every node every time.
    # Two threads of at least 64 nodes: both passes run on both.
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    monkeypatch.setattr(label_mean_field, "_THREADED_NODES", 64)
    finals = []  # the probabilities potts_mean_field takes the labels of
    monkeypatch.setattr(label_mean_field, "_argmax",
                        lambda ptr, labels, q: finals.append(q.copy()) or _argmax(ptr, labels, q))
    _, _, start, (ptr, cand, costs), graph = candidate_problem(seed)
    q = _initial(ptr, cand, costs, start.astype(np.int64), np.float32(-1.0 / TEMPERATURE))
    moved = np.empty(start.size, dtype=np.bool_)
    for _ in range(8):
        out = np.empty_like(q)
        _update(ptr, cand, costs, *graph, q, np.float32(-BETA), np.float32(-1.0 / TEMPERATURE),
                0, start.size, out, moved, np.float32(0.0))
        q = out
    got = potts_mean_field(ptr, cand, costs, *graph, start, BETA, TEMPERATURE, 8, 0.0)
    np.testing.assert_array_equal(finals[0], q)
    np.testing.assert_array_equal(got, _argmax(ptr, cand, q))
    assert moved.sum() < start.size  # some nodes had settled: the skip was exercised
