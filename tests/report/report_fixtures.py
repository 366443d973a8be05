"""Scenes for report and export tests: a hand-made room (floor, ceiling, three walls and a box)
with exact planes, and a ground-truth multi-view scene (imported by the tests as
``report_fixtures``: a module name no other test folder uses, unlike ``conftest``).

The camera looks into the room, pitched 6° down; pixels are ray-cast analytically against
bounded rectangles, so labels, depth, normals and plane parameters are all exact.
"""

from __future__ import annotations

import numpy as np

from monoplane.datamodel import Camera, Reconstruction, Scene, default_intrinsics
from monoplane.testing import plane_scene

# (normal, d, lower bound, upper bound) in the room frame (x right, y down, z forward).
_RECTS = [
    ((0, -1, 0), 1.3, (-2.2, 1.3, 0.0), (2.0, 1.3, 5.0)),  # floor
    ((0, 1, 0), 1.4, (-2.2, -1.4, 0.0), (2.0, -1.4, 5.0)),  # ceiling
    ((0, 0, -1), 5.0, (-2.2, -1.4, 5.0), (2.0, 1.3, 5.0)),  # back wall
    ((1, 0, 0), 2.2, (-2.2, -1.4, 0.0), (-2.2, 1.3, 5.0)),  # left wall
    ((-1, 0, 0), 2.0, (2.0, -1.4, 0.0), (2.0, 1.3, 5.0)),  # right wall
    ((0, -1, 0), 0.6, (-0.3, 0.6, 2.8), (1.0, 0.6, 3.8)),  # box top
    ((0, 0, -1), 2.8, (-0.3, 0.6, 2.8), (1.0, 1.3, 2.8)),  # box front
]
_BASE = np.array([[150, 120, 90], [235, 235, 230], [200, 190, 170], [170, 185, 200],
                  [185, 200, 170], [120, 70, 50], [140, 85, 60]], dtype=np.float64)


def make_room(width: int = 160, height: int = 120, pitch_deg: float = 6.0) -> Reconstruction:
    """Ground-truth reconstruction of the room seen by a camera at the origin.

    Returns
    -------
    Reconstruction
        7 planes, labels with a small non-planar blob on the back wall, exact depth and normals.
    """
    a = np.deg2rad(pitch_deg)
    R = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    K = default_intrinsics(width, height, 70.0)
    planes = np.array([[*n, d] for n, d, _, _ in _RECTS], dtype=np.float64)
    bounds = np.array([[lo, hi] for _, _, lo, hi in _RECTS], dtype=np.float64)
    scene = plane_scene(planes, K, width, height, R=R, bounds=bounds)
    labels = scene.labels.copy()

    v, u = np.mgrid[0:height, 0:width]
    rng = np.random.default_rng(0)
    checker = ((u // 8 + v // 8) % 2)[..., None] * 18.0
    rgb = _BASE[labels - 1] + checker + rng.normal(0, 4, (height, width, 3))
    blob = (u - 0.42 * width) ** 2 + (v - 0.35 * height) ** 2 < (0.06 * width) ** 2
    rgb[blob] = (40, 140, 60)
    labels[blob] = 0
    rgb = np.clip(rgb, 0, 255).astype(np.uint8)
    frame = scene.frame.with_(rgb=rgb, name="room", notes=["synthetic test room"])
    return Reconstruction(frame=frame, labels=labels, planes=scene.planes,
                          rmse=np.full(len(planes), 0.004), timings={"total": 1.25})


def make_scene(n_views: int) -> Scene:
    """Ground-truth scene of synthetic room 3 seen by ``n_views`` cameras at 96x72 pixels, with
    view 2's first plane left unlinked (a plane only that view has)."""
    from monoplane.synth import generate

    sc = generate(3, "clean", 96, 72, n_views)
    cams, views = [], []
    for i, v in enumerate(sc.views):
        f = v.frame.with_(depth=v.gt_depth, normals=v.gt_normals, depth_kind="metric",
                          name=f"view{i}")
        views.append(Reconstruction(frame=f, labels=v.gt_labels, planes=v.gt_params))
        cams.append(Camera(K=f.K, R=v.R, t=v.t, width=f.width, height=f.height, name=f"v{i}"))
    links = [dict(d) for d in sc.view_to_global]
    del links[1][min(links[1])]  # one plane that only view 2 has
    return Scene(cameras=cams, views=views, planes=sc.gt_planes_world, links=links,
                 scales=[1.0] * n_views)
