"""Ground truth of the synthetic generator: exact planes, labels, normals, two-view geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from monoplane.datamodel import pixel_rays, plane_to_camera, plane_to_world
from monoplane.errors import InvalidInput
from monoplane.synth import LEVELS, MIN_PLANE_FRACTION, SynthScene, generate
from monoplane.synth.generator import _STREAM_LAYOUT
from monoplane.synth.render import make_raycaster, render_view
from monoplane.synth.scene import build_layout

W, H = 128, 96
SEEDS = (0, 1, 2, 3)


@pytest.fixture(scope="module")
def pairs() -> list[SynthScene]:
    return [generate(s, "mild", W, H, n_views=2) for s in SEEDS]


def _arrays(scene: SynthScene) -> list[np.ndarray]:
    out = [scene.gt_planes_world]
    for v in scene.views:
        out += [v.frame.rgb, v.frame.depth, v.frame.normals, v.frame.K, v.gt_depth,
                v.gt_normals, v.gt_labels, v.gt_params, v.R, v.t]
    return out


def test_deterministic_byte_identical() -> None:
    a = generate(5, "strong", 64, 48, n_views=2)
    b = generate(5, "strong", 64, 48, n_views=2)
    for x, y in zip(_arrays(a), _arrays(b), strict=True):
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes()
    assert a.view_to_global == b.view_to_global
    c = generate(6, "strong", 64, 48, n_views=2)
    assert c.views[0].frame.rgb.tobytes() != a.views[0].frame.rgb.tobytes()


def test_gt_depth_is_ray_plane_intersection(pairs: list[SynthScene]) -> None:
    for scene in pairs:
        for v in scene.views:
            rays = pixel_rays(v.frame.K, H, W)
            m = v.gt_labels > 0
            p = v.gt_params[v.gt_labels[m] - 1]
            z = -p[:, 3] / np.einsum("ij,ij->i", rays[m], p[:, :3])
            rel = np.abs(z - v.gt_depth[m]) / z
            assert rel.max() < 1e-4
            # Planes are unit, facing the camera, and every id is used.
            assert np.allclose(np.linalg.norm(v.gt_params[:, :3], axis=1), 1.0)
            assert np.all(v.gt_params[:, 3] > 0)
            assert set(np.unique(v.gt_labels)) - {0} == set(range(1, len(v.gt_params) + 1))


def test_gt_matches_independent_raycast_and_labels_only_planar() -> None:
    """Re-cast the layout: the analytic GT depth equals Open3D's hit distance, labelled pixels
    lie on planar faces, curved objects are 0, and every big enough planar face is labelled."""
    seed = 2
    scene = generate(seed, "clean", W, H)
    v = scene.views[0]
    layout = build_layout(np.random.default_rng([seed, _STREAM_LAYOUT]))
    rc = make_raycaster(layout)
    r = render_view(rc, layout, v.frame.K, v.R, v.t, W, H, np.random.default_rng(0))
    rays = pixel_rays(v.frame.K, H, W).reshape(-1, 3) @ v.R
    center = -v.R.T @ v.t
    import open3d as o3d

    cast = rc.cast_rays(o3d.core.Tensor(
        np.concatenate([np.broadcast_to(center, rays.shape), rays], 1).astype(np.float32)))
    t_hit = cast["t_hit"].numpy().reshape(H, W)
    assert np.allclose(v.gt_depth, t_hit, rtol=1e-4)
    planar = np.array([s.planar for s in layout.surfaces])
    labelled = v.gt_labels > 0
    assert np.all(planar[r.surface[labelled]])
    assert np.all(v.gt_labels[~planar[r.surface]] == 0)
    assert (~planar[r.surface]).any(), "test scene should show curved objects"
    area = np.bincount(r.surface.ravel(), minlength=len(planar))
    big = np.flatnonzero(planar & (area >= math.ceil(MIN_PLANE_FRACTION * W * H)))
    assert len(big) == len(v.gt_params)
    for sid in big:
        ids = np.unique(v.gt_labels[r.surface == sid])
        assert len(ids) == 1 and ids[0] > 0


def test_normals_unit_facing_camera_and_exact_on_planes(pairs: list[SynthScene]) -> None:
    for scene in pairs:
        for v in scene.views:
            rays = pixel_rays(v.frame.K, H, W)
            for n in (v.gt_normals, v.frame.normals):
                assert n.dtype == np.float32
                assert np.allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-5)
                assert np.all(np.sum(n * rays, axis=-1) < 0)
            m = v.gt_labels > 0
            assert np.allclose(v.gt_normals[m], v.gt_params[v.gt_labels[m] - 1, :3], atol=1e-6)


def test_two_view_planes_consistent(pairs: list[SynthScene]) -> None:
    for scene in pairs:
        v0, v1 = scene.views
        back = {g: loc for loc, g in scene.view_to_global[1].items()}
        shared = 0
        for loc0, g in scene.view_to_global[0].items():
            world = plane_to_world(v0.gt_params[loc0 - 1], v0.R, v0.t)[0]
            assert np.allclose(world, scene.gt_planes_world[g], atol=1e-9)
            if g in back:
                in_v1 = plane_to_camera(world, v1.R, v1.t)[0]
                assert np.allclose(in_v1, v1.gt_params[back[g] - 1], atol=1e-9)
                shared += 1
        assert shared >= 4, "views should share most planes"
        # Baseline and rotation in the advertised range.
        c0, c1 = -v0.R.T @ v0.t, -v1.R.T @ v1.t
        angle = np.degrees(np.arccos(np.clip((np.trace(v1.R @ v0.R.T) - 1) / 2, -1, 1)))
        assert 0.3 <= np.linalg.norm(c1 - c0) <= 0.8 + 0.15
        assert 10.0 <= angle <= 30.0


def test_two_view_points_project_consistently(pairs: list[SynthScene]) -> None:
    """A labelled pixel of view 0 maps into view 1 onto the same global plane and depth."""
    for scene in pairs:
        v0, v1 = scene.views
        rays0 = pixel_rays(v0.frame.K, H, W)
        m = v0.gt_labels > 0
        X0 = rays0[m] * v0.gt_depth[m, None].astype(np.float64)
        Xw = (X0 - v0.t) @ v0.R
        X1 = Xw @ v1.R.T + v1.t
        uvw = X1 @ v1.frame.K.T
        u, v = uvw[:, 0] / uvw[:, 2], uvw[:, 1] / uvw[:, 2]
        ui, vi = np.rint(u).astype(int), np.rint(v).astype(int)
        inside = (X1[:, 2] > 0) & (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H)
        z1 = v1.gt_depth[vi[inside], ui[inside]]
        visible = np.abs(z1 - X1[inside, 2]) < 0.02 * X1[inside, 2]
        assert inside.mean() > 0.5 and visible.mean() > 0.5, "views should overlap widely"
        g0 = np.array([scene.view_to_global[0][int(k)] for k in v0.gt_labels[m][inside][visible]])
        l1 = v1.gt_labels[vi[inside][visible], ui[inside][visible]]
        g1 = np.array([scene.view_to_global[1].get(int(k), -1) for k in l1])
        # Disagreement only at rounding of pixel positions on plane boundaries.
        assert np.mean(g0 == g1) > 0.97


def test_view0_does_not_depend_on_n_views_or_level() -> None:
    one = generate(4, "mild", 64, 48, n_views=1).views[0]
    two = generate(4, "mild", 64, 48, n_views=2).views[0]
    strong = generate(4, "strong", 64, 48, n_views=1).views[0]
    for a, b in ((one, two), (one, strong)):
        assert np.array_equal(a.gt_labels, b.gt_labels)
        assert np.array_equal(a.gt_params, b.gt_params)
        assert np.array_equal(a.frame.rgb, b.frame.rgb)
    assert np.array_equal(one.frame.depth, two.frame.depth)


def test_frame_contract_and_levels() -> None:
    for level in LEVELS:
        scene = generate(0, level, 64, 48)
        assert scene.level == level and scene.seed == 0
        f = scene.views[0].frame
        assert f.rgb.shape == (48, 64, 3) and f.rgb.dtype == np.uint8
        assert f.depth.dtype == np.float32 and np.all(f.depth > 0)
        assert f.depth_kind == ("metric" if level == "clean" else "relative")
        assert scene.views[0].gt_labels.dtype == np.int32


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"level": "extreme"}, "level"),
    ({"seed": -1}, "seed"),
    ({"width": 8}, "size"),
    ({"n_views": 0}, "n_views"),
])
def test_invalid_arguments(kwargs: dict, match: str) -> None:
    args = {"seed": 0, "level": "mild", "width": 64, "height": 48, "n_views": 1} | kwargs
    with pytest.raises(InvalidInput, match=match):
        generate(**args)


def test_objects_sets_the_furnishing_of_the_same_room() -> None:
    usual = build_layout(np.random.default_rng([7, _STREAM_LAYOUT]))
    empty = build_layout(np.random.default_rng([7, _STREAM_LAYOUT]), objects=0)
    # The room and the camera are drawn first, so they do not depend on the furnishing.
    for a, b in ((usual.size, empty.size), (usual.camera_center, empty.camera_center),
                 (usual.camera_target, empty.camera_target)):
        assert np.array_equal(a, b)
    assert [s.kind for s in empty.surfaces] == ["floor", "ceiling", "wall", "wall", "wall",
                                                "wall"]
    planes = [len(generate(s, "clean", 64, 48, objects=n).views[0].gt_params)
              for n in (1, 10) for s in range(4)]
    assert np.mean(planes[4:]) > np.mean(planes[:4]) + 3
    a = generate(3, "mild", 32, 24, objects=5)
    b = generate(3, "mild", 32, 24, objects=5)
    assert a.views[0].frame.rgb.tobytes() == b.views[0].frame.rgb.tobytes()
    with pytest.raises(InvalidInput, match="objects"):
        generate(0, objects=-1)
