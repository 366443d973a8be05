"""Connected regions of label images (scipy.ndimage.label as the reference), and the largest
part of a plane's inliers on a pixel lattice."""

import numpy as np
import pytest
from scipy import ndimage

from monoplane.errors import InvalidInput
from monoplane.geometry.components import (
    graph_components,
    label_regions,
    largest_component,
    lattice_largest_component,
    same_label_components,
)


def blocky(rng, h, w, labels):
    """A label image of 4 x 4 blocks (large regions) or single pixels (many small ones)."""
    small = rng.integers(0, labels, (h, w))
    return np.kron(small, np.ones((4, 4), dtype=np.int64)) if rng.random() < 0.5 else small


@pytest.mark.parametrize("connectivity", [4, 8])
def test_binary_masks_are_numbered_as_ndimage_does(connectivity):
    structure = ndimage.generate_binary_structure(2, 1 if connectivity == 4 else 2)
    rng = np.random.default_rng(connectivity)
    for _ in range(60):
        mask = blocky(rng, *rng.integers(1, 40, 2), 2) > 0
        expected, count = ndimage.label(mask, structure=structure)
        regions, origin = label_regions(mask, connectivity)
        np.testing.assert_array_equal(regions, expected)
        assert regions.dtype == np.int32 and origin.tolist() == [1] * count


@pytest.mark.parametrize("connectivity", [4, 8])
def test_regions_are_numbered_by_label_then_first_pixel(connectivity):
    structure = ndimage.generate_binary_structure(2, 1 if connectivity == 4 else 2)
    rng = np.random.default_rng(10 + connectivity)
    for _ in range(40):
        lab = blocky(rng, *rng.integers(1, 30, 2), 5)
        regions, origin = label_regions(lab, connectivity)
        offset = 0
        for value in range(1, 5):
            comp, count = ndimage.label(lab == value, structure=structure)
            np.testing.assert_array_equal(regions[lab == value], comp[lab == value] + offset)
            assert origin[offset:offset + count].tolist() == [value] * count
            offset += count
        assert regions.max(initial=0) == offset == origin.size
        assert (regions[lab == 0] == 0).all()


def test_diagonal_touch_joins_only_with_eight_connectivity():
    lab = np.array([[1, 0], [0, 1]])
    assert label_regions(lab, 8)[0].tolist() == [[1, 0], [0, 1]]
    assert label_regions(lab, 4)[0].tolist() == [[1, 0], [0, 2]]


@pytest.mark.parametrize("connectivity", [4, 8])
def test_runs_joined_across_rows_as_ndimage_joins_pixels(connectivity):
    # Regions are found on row runs: a comb whose teeth join only through its back row, a
    # U that joins at its bottom, teeth of another label between them touching at corners.
    structure = ndimage.generate_binary_structure(2, 1 if connectivity == 4 else 2)
    lab = np.zeros((9, 13), dtype=np.int64)
    lab[1:8:2, 0:12:2] = 1                # dotted teeth
    lab[8, :] = 1                         # the comb's back
    lab[0:6, 1:12:4] = 2                  # another label's teeth, touching 1 at corners
    lab[2:7, 9] = 3
    lab[6, 9:13] = 3                      # an L of label 3
    regions, origin = label_regions(lab, connectivity)
    offset = 0
    for value in (1, 2, 3):
        comp, count = ndimage.label(lab == value, structure=structure)
        np.testing.assert_array_equal(regions[lab == value], comp[lab == value] + offset)
        assert origin[offset:offset + count].tolist() == [value] * count
        offset += count
    assert origin.size == offset


@pytest.mark.parametrize("labels, connectivity, match", [
    (np.zeros(3), 8, r"\(H, W\)"),
    (np.zeros((2, 2)), 6, "4 or 8"),
    (-np.ones((2, 2)), 8, ">= 0"),
])
def test_bad_input_is_rejected(labels, connectivity, match):
    with pytest.raises(InvalidInput, match=match):
        label_regions(labels, connectivity)


@pytest.mark.parametrize("seed", range(8))
def test_graph_components_are_numbered_as_scipy_does(seed):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 80))
    edges = rng.integers(0, n, size=(int(rng.integers(0, n)), 2))
    _, expected = connected_components(
        coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n)),
        directed=False)
    comp = graph_components(n, edges)
    np.testing.assert_array_equal(comp, expected)
    assert comp.dtype == np.int64


def test_graph_components_reject_edges_outside_the_graph():
    assert graph_components(3, np.zeros((0, 2))).tolist() == [0, 1, 2]
    with pytest.raises(InvalidInput, match="0..2"):
        graph_components(3, [[0, 3]])


@pytest.mark.parametrize("seed", [0, 1])
def test_same_label_components_are_those_of_the_same_label_edges(seed):
    rng = np.random.default_rng(seed)
    labels = rng.integers(0, 4, 500)
    edges = rng.integers(0, 500, (1500, 2))
    same = (labels[edges[:, 0]] == labels[edges[:, 1]]) & (labels[edges[:, 0]] > 0)
    np.testing.assert_array_equal(same_label_components(labels, edges),
                                  graph_components(500, edges[same]))
    with pytest.raises(InvalidInput, match="edge ends"):
        same_label_components(labels[:10], edges)


def floor_behind_a_post(post_depth: float, gap_cols: int = 3):
    """A 6 x 12 lattice of a fronto-parallel plane at depth 2 (x spacing 0.02), whose columns
    4 .. 4 + gap_cols - 1 hold instead a post at ``post_depth``: (members, lattice, points)."""
    rows, cols = 6, 12
    v, u = np.mgrid[0:rows, 0:cols]
    points = np.stack([0.02 * u, 0.02 * v, np.full(u.shape, 2.0)], axis=-1).reshape(-1, 3)
    post = (u >= 4) & (u < 4 + gap_cols)
    points[post.ravel(), 2] = post_depth
    lattice = np.arange(rows * cols, dtype=np.int64).reshape(rows, cols)
    return ~post.ravel(), lattice, points


def test_lattice_parts_join_across_a_thin_occluder_in_front():
    members, lattice, points = floor_behind_a_post(post_depth=1.0)
    keep = lattice_largest_component(members, lattice, points, np.zeros(3), 0.05, 6)
    assert keep.all()  # both sides: 0.08 apart, within 5 % of the distance 2
    # A reach shorter than the post is wide: the left part (24 < 36 on the right) is dropped.
    keep = lattice_largest_component(members, lattice, points, np.zeros(3), 0.05, 3)
    assert keep.sum() == 6 * 5 and not keep[0] and keep[-1]
    # The jump limit still holds: 0.08 is more than 2 % of 2.
    keep = lattice_largest_component(members, lattice, points, np.zeros(3), 0.02, 6)
    assert keep.sum() == 30


def test_lattice_parts_stay_apart_across_samples_of_the_same_surface_or_behind():
    # Between the parts the surface goes on at the same depth (or farther away): no occluder,
    # so inliers scattered over one surface are not joined across the samples between them.
    for depth in (2.0, 3.0):
        members, lattice, points = floor_behind_a_post(post_depth=depth, gap_cols=1)
        keep = lattice_largest_component(members, lattice, points, np.zeros(3), 0.05, 6)
        assert keep.sum() == 6 * 7 and keep[-1] and not keep[0]


def test_lattice_nodes_without_depth_do_not_end_a_part():
    members, lattice, points = floor_behind_a_post(post_depth=1.0)
    lattice[:, 4:7] = -1  # the post's samples have no depth: no lattice node holds them
    keep = lattice_largest_component(members, lattice, points, np.zeros(3), 0.05, 6)
    assert keep.all()
    keep = lattice_largest_component(members, lattice, points, np.zeros(3), 0.05, 3)
    assert keep.sum() == 30


def test_lattice_reach_one_is_the_eight_neighbourhood():
    rng = np.random.default_rng(3)
    rows, cols = 9, 11
    v, u = np.mgrid[0:rows, 0:cols]
    points = np.stack([0.01 * u, 0.01 * v, np.ones(u.shape)], axis=-1).reshape(-1, 3)
    lattice = np.arange(rows * cols, dtype=np.int64).reshape(rows, cols)
    for _ in range(20):
        members = rng.random(rows * cols) < 0.45
        expected = largest_component(members, _eight_neighbour_edges(rows, cols))
        got = lattice_largest_component(members, lattice, points, np.zeros(3), 0.05, 1)
        np.testing.assert_array_equal(got, expected)
    with pytest.raises(InvalidInput, match="reach must be at least 1"):
        lattice_largest_component(members, lattice, points, np.zeros(3), 0.05, 0)


def _eight_neighbour_edges(rows: int, cols: int) -> np.ndarray:
    index = np.arange(rows * cols).reshape(rows, cols)
    pairs = [(index[:, :-1], index[:, 1:]), (index[:-1, :], index[1:, :]),
             (index[:-1, :-1], index[1:, 1:]), (index[:-1, 1:], index[1:, :-1])]
    return np.concatenate([np.stack([a.ravel(), b.ravel()], axis=1) for a, b in pairs])
