"""The CGAL baseline finds the planes of an exact box and is discoverable by the host."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("CGAL.CGAL_Shape_detection", reason="the GPL 'cgal' package is optional")

from monoplane_cgal_baseline import CgalRansacConfig, cgal_efficient_ransac  # noqa: E402

from monoplane.evaluation.segmentation import segmentation_scores  # noqa: E402
from monoplane.types import Frame, intrinsics_matrix, pixel_rays  # noqa: E402

# Back wall 4 m ahead, floor 1 m below, left wall 1.5 m to the left (camera frame, metres).
BOX_PLANES = np.array([[0.0, 0.0, -1.0, 4.0], [0.0, -1.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.5]])


def box_frame(width: int = 128, height: int = 96) -> tuple[Frame, np.ndarray]:
    K = intrinsics_matrix(80.0, 80.0, (width - 1) / 2, (height - 1) / 2)
    rays = pixel_rays(K, height, width)
    with np.errstate(divide="ignore"):
        z = np.stack([-p[3] / (rays @ p[:3]) for p in BOX_PLANES])
    z[z <= 0] = np.inf
    labels = np.argmin(z, axis=0) + 1
    frame = Frame(rgb=None, K=K, depth=np.min(z, axis=0).astype(np.float32),
                  normals=BOX_PLANES[labels - 1, :3].astype(np.float32))
    return frame, labels.astype(np.int32)


def test_finds_the_three_planes_of_an_exact_box() -> None:
    frame, gt = box_frame()
    rec = cgal_efficient_ransac(frame)
    # CGAL's unseeded sampling may occasionally cut a sparse far strip of the floor off as a
    # second shape of the same plane; it never misses or invents a plane.
    assert 3 <= rec.num_planes <= 4
    assert segmentation_scores(rec.labels, gt).sc > 0.9
    for plane in BOX_PLANES:
        assert np.abs(rec.params - plane).max(axis=1).min() < 5e-3


def test_minimum_support_drops_small_planes() -> None:
    frame, _ = box_frame(64, 48)
    rec = cgal_efficient_ransac(frame, config=CgalRansacConfig(min_support=0.4))
    assert rec.num_planes == 1
    np.testing.assert_allclose(rec.params[0], BOX_PLANES[0], atol=1e-3)


def test_registered_in_the_baselines_entry_point_group(monkeypatch: pytest.MonkeyPatch) -> None:
    from monoplane.evaluation.baselines import get_baseline
    from monoplane.plugin_manager import AUTOLOAD_ENV

    monkeypatch.delenv(AUTOLOAD_ENV, raising=False)
    assert get_baseline("cgal") is cgal_efficient_ransac
