"""Compiled Boykov-Kolmogorov max-flow: closed forms, brute force and the C++ reference."""

import itertools

# PyMaxflow (the C++ reference, wrapped) is in the dev extra that setup.sh installs: the
# equivalence test runs in CI, never skipped.
import maxflow
import numpy as np
import pytest

from monoplane.algorithm.mincut import min_cut, min_cut_arcs, min_cut_flows
from monoplane.errors import InvalidInput


def cut_capacity(sink_side, tails, heads, caps, rev_caps, terminal):
    """Capacity of the cut whose sink side is ``sink_side`` (terminal differences only)."""
    s = np.asarray(sink_side, dtype=bool)
    total = np.where(s, np.maximum(terminal, 0.0), np.maximum(-terminal, 0.0)).sum()
    forward = ~s[tails] & s[heads]
    backward = s[tails] & ~s[heads]
    return total + caps[forward].sum() + rev_caps[backward].sum()


def random_graph(rng, n, m, integer=False):
    tails, heads = rng.integers(0, n, m), rng.integers(0, n, m)
    caps = rng.random(m) * (rng.random(m) < 0.8)
    rev = rng.random(m) * (rng.random(m) < 0.5)
    terminal = rng.normal(size=n) * (rng.random(n) < 0.7)
    if integer:
        caps, rev, terminal = np.round(caps * 4), np.round(rev * 4), np.round(terminal * 3)
    return tails, heads, caps, rev, terminal


def test_four_node_chain_closed_form():
    # s -> 0 (3), 0 -> 1 (2), 1 -> 2 (5), 2 -> 3 (1), 3 -> t (4) and 1 -> t (1). Two paths,
    # s-0-1-t and s-0-1-2-3-t, carry one unit each and saturate 0 -> 1: flow 2.
    tails = np.array([0, 1, 2])
    heads = np.array([1, 2, 3])
    caps = np.array([2.0, 5.0, 1.0])
    terminal = np.array([3.0, -1.0, 0.0, -4.0])
    flow, sink = min_cut(4, tails, heads, caps, np.zeros(3), terminal)
    assert flow == 2.0
    # The sink side is what still reaches t in the residual graph: 3 (3 -> t keeps 3 units).
    # 2 -> 3 and 1 -> t are saturated, so 2 and 1 do not.
    assert sink.tolist() == [False, False, False, True]
    assert cut_capacity(sink, tails, heads, caps, np.zeros(3), terminal) == flow


def test_energy_minimum_of_a_two_node_potts_problem():
    # E = 3 x0 - 2 x1 (unaries) + 4 [x0 != x1], split as a directed edge each way.
    flow, sink = min_cut(2, np.array([0]), np.array([1]), np.array([4.0]), np.array([4.0]),
                         np.array([3.0, -2.0]))
    # Labellings: 00 -> 0, 11 -> 1, 01 -> -2 + 4 = 2, 10 -> 3 + 4 = 7; the minimum 00 has
    # energy 0 = flow - 2 (the constant taken out by the terminal form is -2).
    assert sink.tolist() == [False, False]
    assert flow == 2.0


@pytest.mark.parametrize("seed", range(40))
def test_flow_equals_brute_force_min_cut_and_the_cut_is_the_smallest_sink_side(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 9))
    graph = random_graph(rng, n, int(rng.integers(0, 3 * n + 1)), integer=seed % 2 == 0)
    flow, sink = min_cut(n, *graph)
    values = {}
    for bits in itertools.product([False, True], repeat=n):
        values[bits] = cut_capacity(np.array(bits), *graph)
    best = min(values.values())
    assert flow == pytest.approx(best, abs=1e-9)
    assert cut_capacity(sink, *graph) == pytest.approx(best, abs=1e-9)
    # The returned sink side lies inside every minimum cut's sink side (integer capacities
    # make the minima exact).
    if seed % 2 == 0:
        for bits, value in values.items():
            if value == best:
                assert not (sink & ~np.array(bits)).any()


def test_bit_identical_to_pymaxflow_on_random_graphs():
    rng = np.random.default_rng(7)
    for trial in range(300):
        n = int(rng.integers(1, 80))
        tails, heads, caps, rev, terminal = random_graph(rng, n, int(rng.integers(0, 5 * n)),
                                                         integer=trial % 3 == 0)
        g = maxflow.Graph[float](n, max(tails.size, 1))
        ids = g.add_nodes(n)
        if tails.size:
            g.add_edges(tails, heads, caps, rev)
        g.add_grid_tedges(ids, np.maximum(terminal, 0.0), np.maximum(-terminal, 0.0))
        expected_flow = g.maxflow()
        expected = np.asarray(g.get_grid_segments(ids), dtype=bool)
        flow, sink = min_cut(n, tails, heads, caps, rev, terminal)
        assert flow == expected_flow
        np.testing.assert_array_equal(sink, expected)


def test_empty_graph_and_isolated_nodes():
    flow, sink = min_cut(0, np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0))
    assert flow == 0.0 and sink.shape == (0,)
    flow, sink = min_cut(3, np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0),
                         np.array([1.0, 0.0, -2.0]))
    assert flow == 0.0 and sink.tolist() == [False, False, True]


@pytest.mark.parametrize("kwargs, match", [
    ({"tails": np.array([0, 5])}, r"edge ends must lie in \[0, 3\)"),
    ({"caps": np.array([1.0, -1.0])}, "non-negative"),
    ({"terminal": np.array([np.nan, 0.0, 0.0])}, "finite"),
    ({"terminal": np.zeros(2)}, "2 entries for 3 nodes"),
    ({"heads": np.array([1])}, "one length"),
])
def test_bad_graphs_are_rejected(kwargs, match):
    args = {"tails": np.array([0, 1]), "heads": np.array([1, 2]), "caps": np.ones(2),
            "rev_caps": np.zeros(2), "terminal": np.array([1.0, 0.0, -1.0])}
    args.update(kwargs)
    with pytest.raises(InvalidInput, match=match):
        min_cut(3, args["tails"], args["heads"], args["caps"], args["rev_caps"],
                args["terminal"])


@pytest.mark.parametrize("seed", range(30))
def test_a_warm_start_from_any_flow_gives_the_same_cut(seed):
    # The residual graph of a flow (flow moved into its ends' terminals) has the same minimum
    # cuts, and the smallest sink side comes back whatever flow the search starts from.
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 60))
    integer = seed % 2 == 0
    tails, heads, caps, _, terminal = random_graph(rng, n, int(rng.integers(0, 5 * n)),
                                                   integer=integer)
    if not integer:
        # Generic real capacities: no zero capacity or terminal, so that no two minimum cuts
        # tie (ties would be broken by rounding, differently for different flows).
        caps = 0.1 + rng.random(caps.size)
        terminal = np.where(rng.random(n) < 0.5, -1.0, 1.0) * (0.1 + rng.random(n))
    rev = np.zeros_like(caps)
    cold_flow, cold = min_cut(n, tails, heads, caps, rev, terminal)
    phi = caps * rng.random(caps.size)
    if integer:  # exact arithmetic: the property holds with ties too
        phi = np.floor(phi)
    warm_terminal = terminal.copy()
    np.subtract.at(warm_terminal, tails, phi)
    np.add.at(warm_terminal, heads, phi)
    sink, reverse = min_cut_flows(n, tails.astype(np.int64), heads.astype(np.int64),
                                  caps - phi, phi, warm_terminal)
    np.testing.assert_array_equal(sink, cold)
    # The reverse residuals are the total flow along each edge: feasible, and conserved with
    # the terminals' flows.
    assert np.all(reverse >= -1e-12) and np.all(reverse <= caps + 1e-12)
    assert cut_capacity(sink, tails, heads, caps, rev, terminal) == pytest.approx(
        cold_flow, abs=1e-9)


def arc_network(n, tails, heads, caps, rev):
    """The arc layout :func:`min_cut_arcs` documents, built the slow way: edges in order,
    each edge's two arcs at the last free slot of their node's range."""
    first = np.zeros(n + 1, dtype=np.int32)
    np.add.at(first, tails + 1, 1)
    np.add.at(first, heads + 1, 1)
    first = np.cumsum(first).astype(np.int32)
    fill = first[1:].copy()
    head = np.empty(2 * tails.size, dtype=np.int32)
    sister = np.empty(2 * tails.size, dtype=np.int32)
    rcap = np.empty(2 * tails.size)
    for u, v, c, r in zip(tails, heads, caps, rev, strict=True):
        fill[u] -= 1
        a = fill[u]
        fill[v] -= 1  # after the tail's: a self-loop's two arcs take two slots
        b = fill[v]
        head[a], rcap[a], sister[a] = v, c, b
        head[b], rcap[b], sister[b] = u, r, a
    return first, head, sister, rcap


@pytest.mark.parametrize("seed", range(20))
def test_a_network_given_as_arcs_gives_the_cut_of_its_edge_list(seed):
    # Bit for bit: the same arcs in the same order, so the same search and the same cut, ties
    # and rounding included (real capacities with zeros, unlike the warm-start test).
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 80))
    tails, heads, caps, rev, terminal = random_graph(rng, n, int(rng.integers(0, 5 * n)),
                                                     integer=seed % 2 == 0)
    _, expected = min_cut(n, tails, heads, caps, rev, terminal)
    first, head, sister, rcap = arc_network(n, tails, heads, caps, rev)
    np.testing.assert_array_equal(min_cut_arcs(first, head, sister, rcap, terminal.copy()),
                                  expected)


def test_graphs_beyond_int32_indices_are_refused():
    empty = np.zeros(0)
    with pytest.raises(InvalidInput, match="2\\^31"):
        min_cut(2**31, empty, empty, empty, empty, empty)
    with pytest.raises(InvalidInput, match="2\\^31"):
        min_cut_flows(2**31, empty, empty, empty, empty, empty)
