"""Test helpers for monoplane and for third-party stage plugins.

Installed as a pytest plugin (entry point ``pytest11``), so these fixtures are available in any
test suite once monoplane is installed:

* ``synthetic_view``: a small seeded synthetic view (mild monocular-style noise) with exact
  ground truth;
* ``plugin_manager``: a fresh plugin manager with built-ins only (no entry-point autoload),
  plus whatever the test registers on it.

:func:`box_frame`, a frame of exact planes with its true labels, and
:func:`check_stage_contract`, which a plugin's own tests call on each of its stage classes::

    from monoplane.testing import check_stage_contract

    def test_contract(synthetic_view):
        check_stage_contract(MyCueProvider, synthetic_view.frame)
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np
import pytest

if TYPE_CHECKING:
    import pluggy

    from monoplane.stages.base import Stage
    from monoplane.synth import SynthView
    from monoplane.types import Frame


#: Inside a box, camera frame (OpenCV axes), metres: back wall 4 m ahead, floor 1 m below,
#: left wall 1.5 m to the left; ``n · X + d = 0`` with n facing the camera.
BOX_PLANES = np.array([[0.0, 0.0, -1.0, 4.0], [0.0, -1.0, 0.0, 1.0], [1.0, 0.0, 0.0, 1.5]])


def box_frame(width: int = 128, height: int = 96, planes: np.ndarray = BOX_PLANES,
              focal: float = 80.0) -> tuple[Frame, np.ndarray]:
    """A depth-only frame of exact planes (the nearest plane along each ray), for tests.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    planes : numpy.ndarray
        (P, 4) camera-frame planes facing the camera.
    focal : float
        Focal length in pixels (principal point at the image centre).

    Returns
    -------
    frame : Frame
        Exact depth (metres) and normals, no RGB.
    labels : numpy.ndarray
        (H, W) int32 true labels, ``i`` = row ``i - 1`` of ``planes``.
    """
    from monoplane.types import Frame, intrinsics_matrix, pixel_rays

    K = intrinsics_matrix(focal, focal, (width - 1) / 2, (height - 1) / 2)
    rays = pixel_rays(K, height, width)
    with np.errstate(divide="ignore"):
        z = np.stack([-p[3] / (rays @ p[:3]) for p in planes])
    z[z <= 0] = np.inf
    labels = np.argmin(z, axis=0) + 1
    frame = Frame(rgb=None, K=K, depth=np.min(z, axis=0).astype(np.float32),
                  normals=planes[labels - 1, :3].astype(np.float32))
    return frame, labels.astype(np.int32)


@pytest.fixture
def synthetic_view() -> SynthView:
    """A 128x96 synthetic room, seed 0, level ``mild``."""
    from monoplane.synth import generate

    return generate(0, level="mild", width=128, height=96).views[0]


@pytest.fixture
def plugin_manager() -> pluggy.PluginManager:
    """A fresh plugin manager with the built-in stages only."""
    from monoplane.plugin_manager import get_plugin_manager

    return get_plugin_manager(autoload=False)


def _check_config(cls: type[Stage]) -> Any:
    from monoplane.stages.base import STAGE_KINDS, Stage  # noqa: F811 (runtime import)

    assert isinstance(cls, type) and issubclass(cls, Stage), f"{cls} is not a Stage"
    assert cls.kind in STAGE_KINDS, f"{cls.__name__}.kind {cls.kind!r} not in {STAGE_KINDS}"
    assert cls.name and cls.name == cls.name.strip(), f"{cls.__name__} needs a name"
    assert dataclasses.is_dataclass(cls.Config), f"{cls.__name__}.Config must be a dataclass"
    for f in dataclasses.fields(cls.Config):
        assert f.metadata.get("doc"), f"{cls.__name__}.Config.{f.name} has no doc (use param())"
    return cls(cls.Config())


def check_stage_contract(cls: type[Stage], frame: Frame | None = None, seed: int = 0) -> None:
    """Assert that a stage class honours its kind's contract.

    Static checks (all kinds): subclass of the right base, a name, a dataclass ``Config`` whose
    every field has a doc, and instantiation with defaults. With ``frame`` (a frame that has
    depth and normals), the stage is also run once and its output checked: shapes, dtypes and
    value ranges stated in :mod:`monoplane.stages.base`.
    """
    from monoplane.geometry.cloud import PlaneCloud
    from monoplane.geometry.graph import NeighbourGraph
    from monoplane.stages.base import Labeling, RansacParams
    from monoplane.types import Frame, Reconstruction

    stage = _check_config(cls)
    if frame is None:
        return
    rng = np.random.default_rng(seed)
    params = RansacParams()
    if cls.kind == "cues":
        # Every provider must at least complete given depth with normals (RGB-D input).
        out = stage.provide(frame.with_(normals=None))
        assert isinstance(out, Frame) and out.depth is not None and out.normals is not None
        assert out.shape == frame.shape
        return
    if cls.kind == "refiner":
        labels = np.zeros(frame.shape, dtype=np.int32)
        labels[: frame.height // 2] = 1
        pts = frame.points()[labels == 1]
        from monoplane.geometry.planes import fit_plane

        rec = Reconstruction(frame=frame, labels=labels, params=fit_plane(pts)[0][None])
        out = stage.refine(rec)
        assert isinstance(out, Reconstruction) and out.labels.shape == frame.shape
        return
    cloud = PlaneCloud.from_frame(frame, max_points=5000, rng=rng)
    pool = np.arange(len(cloud.points))
    if cls.kind == "sampler":
        samples = stage.sample(cloud, pool, 50, rng, params)
        assert samples.ndim == 2 and samples.shape[1] == 3 and len(samples) <= 50
        assert np.isin(samples, pool).all()
    elif cls.kind in ("scorer", "labeler"):
        idx = rng.choice(pool, size=3, replace=False)
        from monoplane.geometry.planes import planes_from_triplets

        planes, _ = planes_from_triplets(cloud.points[idx][None])
        normal = cloud.normals[idx].mean(0)
        normal /= np.linalg.norm(normal)
        if cls.kind == "scorer":
            costs = stage.score(cloud, pool, planes, normal[None], params)
            assert costs.shape == (1,) and np.isfinite(costs).all()
        else:
            graph = NeighbourGraph.build(cloud.points, k=8)
            lab = stage.label(cloud, graph, pool, planes[0], normal, params)
            assert isinstance(lab, Labeling) and lab.inliers.shape == pool.shape
            assert lab.inliers.dtype == bool and np.isfinite(lab.energy)
