"""The fuser's rules against over-splitting, on hand-built two-view scenes with known answers.

A tiny ray caster renders exact depth and normals of rectangles and spheres for two cameras;
each test labels the views as a single-view stage might have (a wall cut in two by a pillar, a
sphere painted as a plane, a plane one view missed) and checks the global planes. World frame =
camera 0's (OpenCV axes: x right, y down, z forward); poses are world-to-camera.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from monoplane.datamodel import (
    Camera,
    Frame,
    Reconstruction,
    Scene,
    SfmResult,
    orient_towards_camera,
    pixel_rays,
    plane_to_camera,
)
from monoplane.stages.fusers import AverageFuser

H, W = 120, 160
K = np.array([[120.0, 0.0, 79.5], [0.0, 120.0, 59.5], [0.0, 0.0, 1.0]])


@dataclass
class Rect:
    """The part of world plane ``n · x + d = 0`` inside the axis-aligned box [lo, hi]."""

    plane: tuple[float, float, float, float]
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]


@dataclass
class Ball:
    centre: tuple[float, float, float]
    radius: float


WALL = Rect((0, 0, -1, 3.0), (-4, -2, 2.9), (4, 1, 3.1))          # z = 3
FLOOR = Rect((0, -1, 0, 1.0), (-4, 0.9, 0.1), (4, 1.1, 3.0))       # y = 1 (below the cameras)
PILLAR = Rect((0, 0, -1, 2.0), (-0.25, -2, 1.9), (0.25, 1, 2.1))   # in front of the wall


def _yaw(deg: float) -> np.ndarray:
    a = np.radians(deg)
    return np.array([[np.cos(a), 0, -np.sin(a)], [0, 1, 0], [np.sin(a), 0, np.cos(a)]])


def _camera(center: tuple[float, float, float], yaw_deg: float, name: str) -> Camera:
    R = _yaw(yaw_deg)
    return Camera(K=K, R=R, t=-R @ np.asarray(center, dtype=float), width=W, height=H, name=name)


CAMERAS = [_camera((0, 0, 0), 0.0, "a"), _camera((0.45, 0, 0.1), 6.0, "b")]


def _render(cam: Camera, prims: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact z-depth (H, W), camera-frame normals (H, W, 3) and the primitive index hit (H, W)
    (-1 for none) of a camera."""
    rays = pixel_rays(cam.K, H, W).reshape(-1, 3)
    dirs = rays @ cam.R            # world directions; their camera z is 1, so t is z-depth
    c = -cam.R.T @ cam.t
    best = np.full(len(rays), np.inf)
    hit = np.full(len(rays), -1)
    normals = np.zeros((len(rays), 3))
    for k, prim in enumerate(prims):
        if isinstance(prim, Rect):
            n, d = np.asarray(prim.plane[:3], float), prim.plane[3]
            with np.errstate(divide="ignore", invalid="ignore"):
                t = -(n @ c + d) / (dirs @ n)
            p = c + t[:, None] * dirs
            ok = (t > 0) & np.all((p >= np.asarray(prim.lo)) & (p <= np.asarray(prim.hi)), 1)
            nrm = np.broadcast_to(n, p.shape)
        else:
            s = np.asarray(prim.centre, float)
            b = dirs @ (c - s)
            a = np.einsum("ij,ij->i", dirs, dirs)
            disc = b * b - a * ((c - s) @ (c - s) - prim.radius ** 2)
            t = (-b - np.sqrt(np.maximum(disc, 0))) / a
            ok = (disc > 0) & (t > 0)
            nrm = (c + t[:, None] * dirs - s) / prim.radius
        closer = ok & (t < best)
        best[closer], hit[closer] = t[closer], k
        normals[closer] = nrm[closer]
    normals = normals @ cam.R.T
    normals *= np.where(np.einsum("ij,ij->i", normals, rays) > 0, -1.0, 1.0)[:, None]
    depth = np.where(np.isfinite(best), best, 0.0)
    return depth.reshape(H, W), normals.reshape(H, W, 3), hit.reshape(H, W)


def _view(cam: Camera, prims: list, labelling: list[tuple[int, np.ndarray | None]],
          depth: np.ndarray | None = None) -> Reconstruction:
    """A view whose planes are given as ``(primitive index, pixel mask or None = all its
    pixels)`` in label order; each plane is the least-squares fit of its pixels' points, so a
    sphere gets the plane a single-view stage would paint on it."""
    true_depth, normals, hit = _render(cam, prims)
    depth = true_depth if depth is None else depth
    frame = Frame(rgb=None, K=K, depth=depth.astype(np.float32),
                  normals=normals.astype(np.float32), name=cam.name)
    labels = np.zeros((H, W), np.int32)
    params = []
    rays = pixel_rays(K, H, W)
    for local, (k, mask) in enumerate(labelling, start=1):
        m = (hit == k) if mask is None else mask
        labels[m] = local
        x = rays[m] * depth[m, None]
        centre = x.mean(0)
        normal = np.linalg.svd(x - centre, full_matrices=False)[2][-1]
        params.append([*normal, -normal @ centre])
    return Reconstruction(frame=frame, labels=labels, planes=orient_towards_camera(
        np.array(params)))


def _sfm(cameras: list[Camera] = CAMERAS) -> SfmResult:
    """Exact cameras without keypoints: planes match by reprojection only."""
    n = len(cameras)
    return SfmResult(cameras=list(cameras), points=np.zeros((0, 3)),
                     keypoints=[np.zeros((0, 2))] * n, point_ids=[np.zeros(0, np.int64)] * n)


def _members(scene: Scene) -> dict[int, set[tuple[int, int]]]:
    out: dict[int, set[tuple[int, int]]] = {}
    for v, table in enumerate(scene.links):
        for local, glob in table.items():
            out.setdefault(glob, set()).add((v, local))
    return out


def _halves(cam: Camera, prims: list, k: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of primitive ``k`` left and right of the pillar's image (by pixel column)."""
    _, _, hit = _render(cam, prims)
    cols = np.nonzero((hit == prims.index(PILLAR)).any(0))[0]
    left = (hit == k) & (np.arange(W)[None, :] < cols.min())
    return left, (hit == k) & ~left


def test_a_wall_cut_by_a_pillar_in_one_view_is_one_global_plane() -> None:
    prims = [WALL, FLOOR, PILLAR]
    a_left, a_right = _halves(CAMERAS[0], prims, 0)
    # View a splits the wall at the pillar; view b keeps it whole.
    a = _view(CAMERAS[0], prims, [(0, a_left), (0, a_right), (1, None), (2, None)])
    b = _view(CAMERAS[1], prims, [(0, None), (1, None), (2, None)])
    scene = AverageFuser().fuse([a, b], _sfm())
    walls = [g for g, m in _members(scene).items() if (0, 1) in m]
    assert _members(scene)[walls[0]] == {(0, 1), (0, 2), (1, 1)}
    assert scene.planes.shape[0] == 3                  # wall, floor, pillar
    # The old rule (at most one plane per view in a global plane) kept the halves apart.
    old = AverageFuser(AverageFuser.Config(merge_coplanar=False, check_single_view=False))
    assert old.fuse([a, b], _sfm()).planes.shape[0] == 4


@pytest.mark.parametrize("n_views", [1, 2])
def test_a_wall_cut_by_a_pillar_in_every_view_is_one_global_plane(n_views: int) -> None:
    # The halves are 0.75 m apart on the wall; the pixels between them see the pillar, in
    # front of the wall, so the gap is an occlusion.
    prims = [WALL, FLOOR, PILLAR]
    views = []
    for cam in CAMERAS[:n_views]:
        left, right = _halves(cam, prims, 0)
        views.append(_view(cam, prims, [(0, left), (0, right), (1, None), (2, None)]))
    scene = AverageFuser().fuse(views, _sfm(CAMERAS[:n_views]))
    assert _members(scene)[scene.links[0][1]] == {(v, k) for v in range(n_views) for k in (1, 2)}
    assert scene.planes.shape[0] == 3


@pytest.mark.parametrize("n_views", [1, 2])
def test_coplanar_table_tops_with_the_floor_between_stay_apart(n_views: int) -> None:
    # Two tops at one height (y = 0.5), 0.6 m apart; the floor shows between them, behind
    # their common plane.
    left = Rect((0, -1, 0, 0.5), (-1.2, 0.4, 1.6), (-0.3, 0.6, 2.6))
    right = Rect((0, -1, 0, 0.5), (0.3, 0.4, 1.6), (1.2, 0.6, 2.6))
    prims = [WALL, FLOOR, left, right]
    views = [_view(cam, prims, [(0, None), (1, None), (2, None), (3, None)])
             for cam in CAMERAS[:n_views]]
    scene = AverageFuser().fuse(views, _sfm(CAMERAS[:n_views]))
    assert scene.links[0][3] != scene.links[0][4]
    assert _members(scene)[scene.links[0][3]] == {(v, 3) for v in range(n_views)}
    assert scene.planes.shape[0] == 4


def test_a_plane_painted_on_a_sphere_becomes_no_global_plane() -> None:
    prims = [WALL, FLOOR, Ball((0.9, 0.55, 2.2), 0.4)]
    views = [_view(cam, prims, [(0, None), (1, None), (2, None)]) for cam in CAMERAS]
    scene = AverageFuser().fuse(views, _sfm())
    assert scene.planes.shape[0] == 2
    for v, rec in enumerate(scene.views):
        assert 3 not in scene.links[v]
        # Its local label stays (the view's own segmentation) but it is non-planar globally.
        np.testing.assert_array_equal(rec.labels, views[v].labels)
    kept = AverageFuser(AverageFuser.Config(reject_curved=False)).fuse(views, _sfm())
    assert kept.planes.shape[0] == 3


def test_a_plane_segmented_in_one_of_the_two_views_that_see_it_is_recovered() -> None:
    prims = [WALL, FLOOR]
    a = _view(CAMERAS[0], prims, [(0, None), (1, None)])
    b = _view(CAMERAS[1], prims, [(0, None)])              # view b left the floor unlabelled
    scene = AverageFuser().fuse([a, b], _sfm())
    floor = scene.links[0][2]
    assert _members(scene)[floor] == {(0, 2), (1, 2)}
    # Recovered where view a's floor projects: all of it floor, most of view b's floor.
    _, _, hit = _render(CAMERAS[1], prims)
    recovered = scene.views[1].labels == 2
    assert (recovered & (hit == 1)).sum() / recovered.sum() > 0.99
    assert (recovered & (hit == 1)).sum() / (hit == 1).sum() > 0.7
    # Without the single-view test it stays a plane of view a alone.
    alone = AverageFuser(AverageFuser.Config(check_single_view=False)).fuse([a, b], _sfm())
    assert _members(alone)[alone.links[0][2]] == {(0, 2)}


def test_a_plane_another_view_sees_through_is_dropped() -> None:
    prims = [WALL, FLOOR]
    depth, _, hit = _render(CAMERAS[0], prims)
    # View a's depth hallucinates a slanted surface 1 m in front of part of the wall.
    ghost = (hit == 0) & (np.arange(W)[None, :] > 100) & (np.arange(H)[:, None] < 60)
    rays = pixel_rays(K, H, W)
    slanted = np.array([0.6, 0.0, -0.8, 1.6])     # x-z plane through (0, 0, 2) and beyond
    z = -slanted[3] / (rays @ slanted[:3])
    depth = np.where(ghost, z, depth)
    a = _view(CAMERAS[0], prims, [(0, (hit == 0) & ~ghost), (1, None), (-1, ghost)], depth)
    b = _view(CAMERAS[1], prims, [(0, None), (1, None)])
    scene = AverageFuser().fuse([a, b], _sfm())
    assert 3 not in scene.links[0]
    assert scene.planes.shape[0] == 2
    kept = AverageFuser(AverageFuser.Config(check_single_view=False)).fuse([a, b], _sfm())
    assert 3 in kept.links[0]


def test_a_fragment_with_a_bad_fit_is_absorbed_by_the_plane_it_lies_on() -> None:
    prims = [WALL, FLOOR]
    _, _, hit = _render(CAMERAS[0], prims)
    piece = (hit == 0) & (np.abs(np.arange(W) - 40)[None, :] < 8) & (
        np.abs(np.arange(H) - 30)[:, None] < 8)
    a = _view(CAMERAS[0], prims, [(0, (hit == 0) & ~piece), (1, None), (0, piece)])
    # The fragment's own fit is tilted by 25 degrees about its centre.
    centre = (pixel_rays(K, H, W)[piece] * 3.0).mean(0)
    normal = _yaw(25.0) @ np.array([0.0, 0.0, -1.0])
    params = a.planes.copy()
    params[2] = [*normal, -normal @ centre]
    a = Reconstruction(frame=a.frame, labels=a.labels, planes=orient_towards_camera(params))
    b = _view(CAMERAS[1], prims, [(0, None), (1, None)])
    scene = AverageFuser().fuse([a, b], _sfm())
    wall = scene.links[1][1]
    assert scene.links[0][3] == wall
    # Absorbed: it now is the wall in its camera, and the wall keeps its parameters.
    expected = orient_towards_camera(plane_to_camera(scene.planes[wall], CAMERAS[0].R,
                                                     CAMERAS[0].t))[0]
    np.testing.assert_allclose(scene.views[0].planes[2], expected, atol=1e-9)
    np.testing.assert_allclose(np.abs(scene.planes[wall]), [0, 0, 1, 3], atol=1e-6)


@pytest.mark.parametrize(("kind", "method"), [("metric", "box"), ("relative", "gated")])
def test_the_curvature_test_estimates_missing_normals_as_the_cue_stage_does(
        kind: str, method: str, monkeypatch: pytest.MonkeyPatch) -> None:
    # A view without normals gets the default cue stage's fit ("auto": box on a sensor's
    # metric depth, gated otherwise), so the test sees the normals it was segmented with.
    from monoplane.geometry.normals import normals_from_depth
    from monoplane.stages import fusers

    seen: list[np.ndarray] = []

    def spread(normals: np.ndarray, *args, **kwargs):
        seen.append(normals)
        return real(normals, *args, **kwargs)

    real = fusers.normal_spread_deg
    monkeypatch.setattr(fusers, "normal_spread_deg", spread)
    rec = _view(CAMERAS[0], [WALL, FLOOR, Ball((0.9, 0.55, 2.2), 0.4)],
                [(0, None), (1, None), (2, None)])
    noise = np.random.default_rng(1).normal(1.0, 0.01, rec.frame.depth.shape)
    frame = rec.frame.with_(normals=None, depth_kind=kind,
                            depth=(rec.frame.depth * noise).astype(np.float32))
    AverageFuser().flat_planes([Reconstruction(frame=frame, labels=rec.labels,
                                               planes=rec.planes)])
    other = "gated" if method == "box" else "box"
    want = normals_from_depth(frame.depth, frame.K, method=method)
    np.testing.assert_array_equal(seen[0], want)
    assert not np.array_equal(want, normals_from_depth(frame.depth, frame.K, method=other))
