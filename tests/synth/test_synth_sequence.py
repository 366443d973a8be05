"""Walk-through and star sequences: camera paths as documented, same room as generate()."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.synth import generate
from monoplane.synth.sequence import (
    STAR_TURN_DEG,
    WALK_STEP_M,
    WALK_TURN_DEG,
    generate_sequence,
    rotation_angle_deg,
)


def _center(view) -> np.ndarray:
    return -view.R.T @ view.t


@pytest.mark.parametrize("seed", [0, 4])
def test_walk_steps_and_turns(seed: int) -> None:
    s = generate_sequence(seed, 4, "walk", width=64, height=48)
    assert len(s.views) == 4
    for a, b in zip(s.views, s.views[1:], strict=False):
        step = np.linalg.norm(_center(b) - _center(a))
        assert WALK_STEP_M[0] - 0.06 <= step <= WALK_STEP_M[1] + 0.06
        assert WALK_TURN_DEG[0] <= rotation_angle_deg(a.R, b.R) <= WALK_TURN_DEG[1]


def test_star_views_overlap_view_zero_and_room_is_shared() -> None:
    s = generate_sequence(2, 4, "star", width=64, height=48)
    for v in s.views[1:]:
        assert STAR_TURN_DEG[0] <= rotation_angle_deg(s.views[0].R, v.R) <= STAR_TURN_DEG[1]
    single = generate(2, width=64, height=48)
    np.testing.assert_array_equal(s.views[0].frame.rgb, single.views[0].frame.rgb)
    # Ground-truth links cover every labelled plane, and global planes are shared.
    for v, view in enumerate(s.views):
        assert set(s.view_to_global[v]) == set(range(1, int(view.gt_labels.max()) + 1))
    assert len(s.gt_planes_world) < sum(len(m) for m in s.view_to_global)


def test_bad_arguments() -> None:
    with pytest.raises(InvalidInput, match="unknown camera path 'loop'"):
        generate_sequence(0, 3, "loop")
    with pytest.raises(InvalidInput, match="at least 2 views"):
        generate_sequence(0, 1, "walk")
