"""NeighbourGraph: symmetric deduplicated kNN edges, CSR adjacency and pool subgraphs."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from monoplane.errors import InvalidInput
from monoplane.geometry.components import largest_component
from monoplane.geometry.graph import NeighbourGraph, _adjacency, _knn_edges, _pool_edges


def grid_points(n=6):
    u, v = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    return np.stack([u.ravel(), v.ravel(), np.zeros(n * n)], axis=1)


def test_grid_with_four_neighbours_gives_the_lattice_edges():
    pts = grid_points(6)
    # Tiny jitter breaks distance ties at the diagonal so the 4 nearest are the axis neighbours.
    pts[:, :2] += np.random.default_rng(0).uniform(-1e-3, 1e-3, size=(36, 2))
    g = NeighbourGraph.build(pts, k=4)
    # The 4-neighbour lattice on 6x6 has 2 * 6 * 5 = 60 edges; border nodes pick extra
    # (diagonal or second-ring) neighbours, so the graph contains the lattice.
    lattice = set()
    for r in range(6):
        for c in range(6):
            i = r * 6 + c
            if c < 5:
                lattice.add((i, i + 1))
            if r < 5:
                lattice.add((i, i + 6))
    edges = {tuple(e) for e in g.edges.tolist()}
    assert lattice <= edges
    assert g.spacing == np.float64(g.spacing) and 0.99 < g.spacing < 1.01


def test_edges_are_unique_ordered_and_contain_every_knn_pair():
    rng = np.random.default_rng(1)
    pts = rng.uniform(size=(300, 3))
    g = NeighbourGraph.build(pts, k=5)
    e = g.edges
    assert np.all(e[:, 0] < e[:, 1])
    assert len({tuple(x) for x in e.tolist()}) == len(e)
    _, nbr = cKDTree(pts).query(pts, k=6)
    edges = {tuple(x) for x in e.tolist()}
    for i in range(300):
        for j in nbr[i, 1:]:
            assert (min(i, j), max(i, j)) in edges
    # Every edge comes from some point's kNN list.
    assert len(edges) <= 300 * 5


def test_csr_adjacency_is_symmetric_and_matches_edges():
    rng = np.random.default_rng(2)
    g = NeighbourGraph.build(rng.uniform(size=(100, 3)), k=4)
    assert g.indptr[-1] == 2 * g.num_edges
    for i, j in g.edges[:50]:
        assert j in g.neighbours(i) and i in g.neighbours(j)
    degree = np.diff(g.indptr)
    assert degree.min() >= 4


def test_subgraph_keeps_edges_among_pool_in_local_indices():
    rng = np.random.default_rng(3)
    g = NeighbourGraph.build(rng.uniform(size=(200, 3)), k=6)
    pool = np.sort(rng.choice(200, size=120, replace=False))
    local, ids = g.subgraph(pool)
    np.testing.assert_array_equal(pool[local], g.edges[ids])
    inside = np.isin(g.edges, pool).all(axis=1)
    assert inside.sum() == len(ids)


def test_subgraph_of_every_node_is_the_graph_itself():
    rng = np.random.default_rng(4)
    g = NeighbourGraph.build(rng.uniform(size=(150, 3)), k=5)
    every = np.arange(150)
    local, ids = g.subgraph(every)
    ref_local, ref_ids = _pool_edges(150, g.edges, every)
    np.testing.assert_array_equal(local, ref_local)
    np.testing.assert_array_equal(ids, ref_ids)
    assert not local.flags.writeable and not ids.flags.writeable
    # All nodes in another order are not the identity: renumbered like any pool.
    shuffled = rng.permutation(150)
    local, ids = g.subgraph(shuffled)
    np.testing.assert_array_equal(shuffled[local], g.edges[ids])


def test_duplicate_points_do_not_create_self_loops_and_tiny_clouds_work():
    pts = np.zeros((5, 3))
    g = NeighbourGraph.build(pts, k=3)
    assert np.all(g.edges[:, 0] != g.edges[:, 1])
    single = NeighbourGraph.build(np.zeros((1, 3)), k=3)
    assert single.num_edges == 0


def test_mean_degree_is_twice_edges_over_nodes():
    # On a line at 0, 1, 3, 7 each point's nearest neighbour gives the edges 0-1, 1-2, 2-3.
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [3, 0, 0], [7, 0, 0]])
    g = NeighbourGraph.build(pts, k=1)
    assert {tuple(e) for e in g.edges.tolist()} == {(0, 1), (1, 2), (2, 3)}
    assert g.mean_degree == 1.5
    assert NeighbourGraph.build(np.zeros((1, 3)), k=3).mean_degree == 0.0


def test_largest_component_of_a_node_subset():
    # Chain 0-1-2 and pair 3-4 far away.
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [10, 0, 0], [11, 0, 0]])
    g = NeighbourGraph.build(pts, k=1)

    def largest(nodes: np.ndarray) -> np.ndarray:
        return g.largest_component_within(nodes, np.ones(nodes.size, dtype=bool))

    np.testing.assert_array_equal(largest(np.arange(5)), [True, True, True, False, False])
    # Without node 1 the chain falls apart: {0}, {2}, {3, 4}.
    np.testing.assert_array_equal(largest(np.array([0, 2, 3, 4])), [False, False, True, True])
    assert largest(np.zeros(0, dtype=np.int64)).shape == (0,)


def test_subgraph_of_the_same_pool_is_reused_and_read_only():
    rng = np.random.default_rng(4)
    g = NeighbourGraph.build(rng.uniform(size=(200, 3)), k=6)
    pool = np.sort(rng.choice(200, size=120, replace=False))
    a, ids = g.subgraph(pool)
    b, _ = g.subgraph(pool.copy())
    assert a is b and not a.flags.writeable and not ids.flags.writeable
    other = pool[::2]
    c, _ = g.subgraph(other)
    np.testing.assert_array_equal(other[c], g.edges[np.isin(g.edges, other).all(axis=1)])


def test_subgraphs_of_shrinking_pools_are_those_of_the_whole_graph():
    # Each pool within the last one is cut from the last one's subgraph (and the pool of
    # another run starts from the whole graph again): row for row the whole graph's.
    rng = np.random.default_rng(5)
    g = NeighbourGraph.build(rng.uniform(size=(300, 3)), k=6)
    for _ in range(2):
        pool = np.arange(300)
        while pool.size > 10:
            pool = np.sort(rng.choice(pool, size=pool.size * 2 // 3, replace=False))
            local, ids = g.subgraph(pool)
            ref_local, ref_ids = _pool_edges(300, g.edges, pool)
            np.testing.assert_array_equal(local, ref_local)
            np.testing.assert_array_equal(ids, ref_ids)


def test_largest_component_within_a_pool_matches_the_subset_one():
    # Two clusters along x, far apart; the larger one wins, computed from the pool's subgraph.
    rng = np.random.default_rng(5)
    pts = np.concatenate([rng.uniform(0, 1, (80, 3)), rng.uniform(0, 1, (50, 3)) + [10, 0, 0]])
    g = NeighbourGraph.build(pts, k=5)
    pool = np.sort(rng.choice(130, size=100, replace=False))
    members = rng.random(100) < 0.7
    within = g.largest_component_within(pool, members)
    subset = pool[members]  # the same nodes as a pool of their own: a fresh subgraph
    np.testing.assert_array_equal(
        within, g.largest_component_within(subset, np.ones(subset.size, dtype=bool)))
    assert np.all(pool[members][within] < 80)
    assert g.largest_component_within(pool, np.zeros(100, bool)).shape == (0,)


def reference_knn_edges(nbr):
    """The straightforward construction: all (min, max) pairs, one global sort, unique."""
    n = nbr.shape[0]
    src = np.repeat(np.arange(n), nbr.shape[1])
    dst = nbr.ravel()
    keep = src != dst
    lo, hi = np.minimum(src, dst)[keep], np.maximum(src, dst)[keep]
    key = np.unique(lo * n + hi)
    edges = np.stack([key // n, key % n], axis=1)
    neighbours = [[] for _ in range(n)]
    for i, j in edges:
        neighbours[i].append(j)
        neighbours[j].append(i)
    return edges, [sorted(x) for x in neighbours]


@pytest.mark.parametrize("seed", range(8))
def test_knn_edge_kernel_matches_the_sorting_reference(seed):
    # Random neighbour tables, with self-references anywhere and repeated pairs (as among
    # duplicate points), and real kNN tables of random clouds with exact duplicates.
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 300))
    if seed % 2:
        pts = rng.uniform(size=(n, 3))
        pts[rng.random(n) < 0.2] = pts[0]
        _, nbr = cKDTree(pts).query(pts, k=min(n, 6))
        nbr = nbr.reshape(n, -1)
    else:
        nbr = rng.integers(0, n, size=(n, int(rng.integers(1, 12))))
    nbr = np.ascontiguousarray(nbr, dtype=np.int64)
    edges = _knn_edges(nbr, 0, n)
    indptr, indices = _adjacency(n, edges)
    ref_edges, ref_rows = reference_knn_edges(nbr)
    np.testing.assert_array_equal(edges.reshape(-1, 2), ref_edges.reshape(-1, 2))
    assert [indices[indptr[i]:indptr[i + 1]].tolist() for i in range(n)] == ref_rows
    # Ranges of smaller ends, listed apart (on threads) and joined: the same list.
    cut = int(rng.integers(0, n + 1))
    np.testing.assert_array_equal(
        np.concatenate([_knn_edges(nbr, 0, cut), _knn_edges(nbr, cut, n)]).reshape(-1, 2),
        ref_edges.reshape(-1, 2))


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_graph_edges_and_lazy_adjacency_do_not_depend_on_threads(threads, monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", str(threads))
    monkeypatch.setattr("monoplane.geometry.graph.THREADED_NODES", 50)
    pts = np.random.default_rng(5).uniform(size=(400, 3))
    g = NeighbourGraph.build(pts, 6)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    ref = NeighbourGraph.build(pts, 6)
    np.testing.assert_array_equal(g.edges, ref.edges)
    assert g._indptr is None  # built when first asked for
    np.testing.assert_array_equal(g.indptr, ref.indptr)
    np.testing.assert_array_equal(g.indices, ref.indices)
    assert g._indptr is not None


def reference_largest_component(members, edges):
    """scipy's connected components of the members' induced subgraph, largest (first) one."""
    idx = np.flatnonzero(members)
    rank = np.cumsum(members) - 1
    inside = members[edges[:, 0]] & members[edges[:, 1]]
    ends = rank[edges[inside]]
    adj = coo_matrix((np.ones(len(ends)), (ends[:, 0], ends[:, 1])), shape=(idx.size,) * 2)
    _, comp = connected_components(adj, directed=False)
    return comp == np.argmax(np.bincount(comp))


@pytest.mark.parametrize("seed", range(12))
def test_largest_component_kernel_matches_scipy(seed):
    # Sparse random graphs have many components of equal size: the tie rule is exercised.
    rng = np.random.default_rng(seed)
    m = int(rng.integers(1, 200))
    edges = rng.integers(0, m, size=(int(rng.integers(0, m)), 2)).astype(np.int64)
    members = rng.random(m) < rng.uniform(0.2, 1.0)
    if not members.any():
        members[0] = True
    np.testing.assert_array_equal(largest_component(members, edges),
                                  reference_largest_component(members, edges))


def test_weighted_adjacency_is_scipys_sorted_csr():
    rng = np.random.default_rng(5)
    graph = NeighbourGraph.build(rng.normal(size=(300, 3)), 6)
    weights = rng.uniform(0.1, 2.0, graph.num_edges)
    indptr, indices, data = graph.weighted_adjacency(weights)
    i, j = graph.edges[:, 0], graph.edges[:, 1]
    want = coo_matrix((np.r_[weights, weights], (np.r_[i, j], np.r_[j, i])),
                      shape=(300, 300)).tocsr()
    want.sort_indices()
    np.testing.assert_array_equal(indptr, want.indptr)
    np.testing.assert_array_equal(indices, want.indices)
    np.testing.assert_array_equal(data, want.data.astype(np.float32))
    with pytest.raises(InvalidInput, match="weights must be"):
        graph.weighted_adjacency(weights[:-1])


def _lattice_frame(h=24, w=32, stride=4, step_at=None):
    """Points of a fronto-parallel plane at depth 2 (a step to depth 3 from column
    ``step_at`` on), sampled on the lattice of ``stride``: (points, lattice, shift)."""
    offset = stride // 2
    v, u = np.mgrid[offset:h:stride, offset:w:stride]
    z = np.full(v.shape, 2.0)
    if step_at is not None:
        z[:, (u[0] >= step_at)] = 3.0
    f = 50.0
    pts = np.stack([(u - w / 2) / f * z, (v - h / 2) / f * z, z], axis=-1).reshape(-1, 3)
    lattice = np.arange(v.size, dtype=np.int64).reshape(v.shape)
    return pts, lattice, np.zeros(3)


def test_lattice_graph_links_the_eight_lattice_neighbours():
    pts, lattice, shift = _lattice_frame()
    g = NeighbourGraph.from_lattice(pts, lattice, shift, 0.5)
    rows, cols = 6, 8
    # 8-neighbourhood on a rows x cols lattice: horizontal, vertical and two diagonals.
    expected = rows * (cols - 1) + (rows - 1) * cols + 2 * (rows - 1) * (cols - 1)
    assert g.num_edges == expected
    assert np.all(g.edges[:, 0] < g.edges[:, 1])
    order = np.lexsort((g.edges[:, 1], g.edges[:, 0]))
    np.testing.assert_array_equal(order, np.arange(g.num_edges))
    # An interior lattice point has all 8 neighbours; the adjacency agrees with the edges.
    interior = 2 * cols + 3
    assert sorted(g.neighbours(interior).tolist()) == sorted(
        interior + d for d in (-cols - 1, -cols, -cols + 1, -1, 1, cols - 1, cols, cols + 1))
    assert g.tree is None
    # Spacing: the median lattice pair, axial 4 px at depth 2 and f = 50 is 0.16.
    assert 0.16 <= g.spacing <= 0.16 * np.sqrt(2)


def test_lattice_graph_cuts_at_depth_jumps():
    pts, lattice, shift = _lattice_frame(step_at=16)
    # Lattice steps are 4 px / f = 0.08 of the depth, the step 1 / 2: a jump of 0.2 parts them.
    g = NeighbourGraph.from_lattice(pts, lattice, shift, 0.2)
    z = pts[:, 2]
    assert g.num_edges > 0
    assert np.all(z[g.edges[:, 0]] == z[g.edges[:, 1]])  # no edge crosses the step


def test_lattice_graph_rejects_points_off_the_lattice():
    pts, lattice, shift = _lattice_frame()
    with pytest.raises(InvalidInput, match="each of the 48 points once"):
        NeighbourGraph.from_lattice(pts, lattice[::-1], shift, 0.05)
    holes = np.where(lattice % 5 == 0, -1, lattice)
    with pytest.raises(InvalidInput, match="each of the 48 points once"):
        NeighbourGraph.from_lattice(pts, holes, shift, 0.05)


def test_lattice_graph_cuts_where_the_normals_turn():
    pts, lattice, shift = _lattice_frame()
    u = (pts[:, 0] * 50 / 2 + 16).round()
    # Flat depth, but the normals of the right half are turned 30 degrees about the y axis.
    turn = np.radians(30.0)
    normals = np.where((u >= 16)[:, None], [np.sin(turn), 0.0, -np.cos(turn)], [0.0, 0.0, -1.0])
    full = NeighbourGraph.from_lattice(pts, lattice, shift, 0.5)
    kept = NeighbourGraph.from_lattice(pts, lattice, shift, 0.5, normals, 31.0)
    np.testing.assert_array_equal(kept.edges, full.edges)  # 30 degrees is within 31
    cut = NeighbourGraph.from_lattice(pts, lattice, shift, 0.5, normals, 29.0)
    side = u >= 16
    assert np.all(side[cut.edges[:, 0]] == side[cut.edges[:, 1]])  # no edge crosses the fold
    # Only the pairs across the fold went: 6 horizontal ones and 2 diagonal ones in each of
    # the 5 gaps between lattice rows.
    assert full.num_edges - cut.num_edges == 6 + 2 * 5
    with pytest.raises(InvalidInput, match="max_turn_deg and turn_scale_deg need"):
        NeighbourGraph.from_lattice(pts, lattice, shift, 0.5, None, 29.0)


def test_lattice_graph_weakens_pairs_whose_normals_turn():
    pts, lattice, shift = _lattice_frame()
    u = (pts[:, 0] * 50 / 2 + 16).round()
    turn = np.radians(30.0)
    normals = np.where((u >= 16)[:, None], [np.sin(turn), 0.0, -np.cos(turn)], [0.0, 0.0, -1.0])
    plain = NeighbourGraph.from_lattice(pts, lattice, shift, 0.5, normals)
    assert plain.affinity_scale is None and plain.normal_angle is None
    soft = NeighbourGraph.from_lattice(pts, lattice, shift, 0.5, normals, None, 10.0)
    np.testing.assert_array_equal(soft.edges, plain.edges)  # no pair is cut
    side = u >= 16
    across = side[soft.edges[:, 0]] != side[soft.edges[:, 1]]
    # exp(-t^2 / 2 sigma^2): 1 where the normals agree, exp(-4.5) across the 30 degree fold.
    np.testing.assert_allclose(soft.affinity_scale[~across], 1.0)
    np.testing.assert_allclose(soft.affinity_scale[across], np.exp(-4.5))
    with pytest.raises(InvalidInput, match="turn_scale_deg need"):
        NeighbourGraph.from_lattice(pts, lattice, shift, 0.5, None, None, 10.0)


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_lattice_graph_turn_weights_angles_spacing_do_not_depend_on_threads(threads, monkeypatch):
    # Random normals: the turn weights of the chunks, computed on parallel threads and joined,
    # are each edge's exp(-t^2 / 2 sigma^2), as on one thread; the spacing is the median gap.
    pts, lattice, shift = _lattice_frame()
    normals = np.random.default_rng(3).normal(size=pts.shape) + [0.0, 0.0, -3.0]
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    monkeypatch.setattr("monoplane.geometry.graph.THREADED_EDGES", 7)
    monkeypatch.setenv("OMP_NUM_THREADS", str(threads))
    g = NeighbourGraph.from_lattice(pts, lattice, shift, 0.5, normals, None, 10.0)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    ref = NeighbourGraph.from_lattice(pts, lattice, shift, 0.5, normals, None, 10.0)
    np.testing.assert_array_equal(g.edges, ref.edges)
    np.testing.assert_array_equal(g.affinity_scale, ref.affinity_scale)
    assert g.spacing == ref.spacing
    i, j = g.edges.T
    t = np.degrees(np.arccos(np.clip(np.sum(normals[i] * normals[j], axis=1), -1.0, 1.0)))
    np.testing.assert_allclose(g.affinity_scale, np.exp(-t**2 / 200.0), rtol=1e-12)
    np.testing.assert_array_equal(g.normal_angle, ref.normal_angle)
    np.testing.assert_allclose(np.degrees(g.normal_angle), t, rtol=1e-12)
    gaps = np.linalg.norm(pts[i] - pts[j], axis=1)  # every pair is kept at max_jump 0.5
    assert g.spacing == pytest.approx(np.median(gaps), rel=1e-12)
