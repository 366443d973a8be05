"""Global planes as consistent components of the plane-match graph."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.geometry.plane_matching import consistent_groups


def test_transitive_matches_over_three_views_form_one_group() -> None:
    views = np.array([0, 0, 1, 1, 2])
    groups = consistent_groups(views, np.array([[0, 2], [2, 4], [1, 3]]), np.ones(3))
    assert groups == [[0, 2, 4], [1, 3]]


def test_weak_edge_that_would_join_two_planes_of_one_view_is_dropped() -> None:
    # View 0 has planes 0 and 1; view 1 has plane 2. Both match plane 2, the first strongly.
    views = np.array([0, 0, 1])
    groups = consistent_groups(views, np.array([[1, 2], [0, 2]]), np.array([0.6, 1.8]))
    assert groups == [[0, 2], [1]]
    for g in groups:
        assert len({int(views[k]) for k in g}) == len(g)


def test_chain_through_other_views_cannot_merge_a_view_with_itself() -> None:
    # 0(v0) - 2(v1) - 3(v2) - 1(v0): the weakest link of the chain is cut.
    views = np.array([0, 0, 1, 2])
    edges = np.array([[0, 2], [2, 3], [3, 1]])
    groups = consistent_groups(views, edges, np.array([1.0, 0.9, 0.5]))
    assert groups == [[0, 2, 3], [1]]


def test_no_edges_gives_singletons_and_bad_lengths_are_rejected() -> None:
    assert consistent_groups(np.array([0, 1]), np.zeros((0, 2)), np.zeros(0)) == [[0], [1]]
    with pytest.raises(InvalidInput):
        consistent_groups(np.array([0, 1]), np.array([[0, 1]]), np.zeros(2))


def test_two_planes_of_one_view_join_when_the_check_accepts_their_union() -> None:
    # Planes 0 and 1 of view 0 (a wall cut by an occluder) both match plane 2 of view 1.
    views = np.array([0, 0, 1])
    edges, strengths = np.array([[1, 2], [0, 2]]), np.array([0.6, 1.8])
    asked = []

    def coplanar(a: list[int], b: list[int]) -> bool:
        asked.append((a, b))
        return True

    assert consistent_groups(views, edges, strengths, coplanar) == [[0, 1, 2]]
    assert asked == [([1], [0, 2])]            # only the union that shares a view is checked
    assert consistent_groups(views, edges, strengths, lambda a, b: False) == [[0, 2], [1]]
