"""Coplanarity and footprint contact of view-plane samples, relative to depth."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane.geometry.coplanar import coplanarity_residual, footprint_gap

PLANE = np.array([0.0, 0.0, -1.0, 2.0])        # z = 2


def _square(x0: float, x1: float, z: float, n: int = 11) -> np.ndarray:
    xs, ys = np.meshgrid(np.linspace(x0, x1, n), np.linspace(-0.5, 0.5, n))
    return np.stack([xs.ravel(), ys.ravel(), np.full(xs.size, z)], 1)


def test_residual_is_the_worst_members_median_distance_over_depth() -> None:
    on, off = _square(-1, 0, 2.0), _square(0, 1, 2.1)
    depth_on, depth_off = on[:, 2], off[:, 2]
    assert coplanarity_residual([on], [depth_on], PLANE) == pytest.approx(0.0)
    assert coplanarity_residual([on, off], [depth_on, depth_off], PLANE) == pytest.approx(0.1 / 2.1)
    assert coplanarity_residual([], [], PLANE) == 0.0


def test_gap_is_the_closest_distance_on_the_plane_over_depth() -> None:
    a, b = _square(-1.0, 0.0, 2.0), _square(0.4, 1.0, 2.05)   # b 5 cm off the plane
    assert footprint_gap(a, a[:, 2], b, b[:, 2], PLANE) == pytest.approx(0.4 / 2.05)
    c = _square(-0.5, 0.5, 2.0)
    assert footprint_gap(a, a[:, 2], c, c[:, 2], PLANE) == pytest.approx(0.0, abs=1e-12)
    assert footprint_gap(a, a[:, 2], np.zeros((0, 3)), np.zeros(0), PLANE) == np.inf
