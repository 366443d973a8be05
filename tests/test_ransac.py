"""Sequential RANSAC driver on exact synthetic rooms (ray-plane intersection)."""

import numpy as np
import pytest

from monoplane.algorithm.ransac import RansacConfig, SequentialRansac
from monoplane.contracts import Sampler
from monoplane.datamodel import Frame, default_intrinsics, orient_towards_camera, pixel_rays
from monoplane.errors import ConfigError, InvalidInput, PluginError, StageError
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.graph import NeighbourGraph
from monoplane.geometry.hypotheses import draw_triplets, needed_samples
from monoplane.stages.labelers import GraphCutLabeler, ProximityGraphCutLabeler, ThresholdLabeler
from monoplane.stages.samplers import NormalConsistentSampler, UniformSampler
from monoplane.stages.scorers import InlierCountScorer, MsacNormalScorer, MsacScorer


def room(h=96, w=128, rgb=True):
    """Floor, back wall, left wall, right wall and a box face seen from a tilted camera.

    Returns the frame, the ground-truth labels (H, W) and the planes (P, 4) in the camera
    frame (metres, facing the camera).
    """
    K = default_intrinsics(w, h, 70.0)
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])  # camera looks slightly down
    world = [  # (normal, offset): n . X_w + d = 0, y down, camera 1.4 m above the floor
        ([0, -1, 0], 1.4), ([0, 0, -1], 5.0), ([1, 0, 0], 2.0), ([-1, 0, 0], 2.5)]
    planes = np.array([np.r_[R @ n, d] for n, d in world], dtype=float)
    rays = pixel_rays(K, h, w).reshape(-1, 3)
    with np.errstate(divide="ignore"):
        t = -planes[:, 3][None] / (rays @ planes[:, :3].T)
    t[t <= 0] = np.inf
    # The box front: plane z_w = 3 limited to x_w in [0.2, 1.2], y_w in [0.5, 1.4].
    box = np.r_[R @ [0, 0, -1.0], 3.0]
    tb = -box[3] / (rays @ box[:3])
    xw = (rays * tb[:, None]) @ R  # camera -> world (R orthonormal)
    inside = (tb > 0) & (xw[:, 0] > 0.2) & (xw[:, 0] < 1.2) & (xw[:, 1] > 0.5)
    t = np.concatenate([t, np.where(inside, tb, np.inf)[:, None]], axis=1)
    planes = orient_towards_camera(np.vstack([planes, box]))
    labels = np.argmin(t, axis=1) + 1
    depth = t[np.arange(len(t)), labels - 1]
    normals = planes[labels - 1, :3]
    image = None
    if rgb:
        palette = np.array([[0, 0, 0], [180, 60, 40], [40, 160, 60], [50, 70, 200],
                            [200, 200, 40], [120, 40, 160]], dtype=np.uint8)
        image = palette[labels].reshape(h, w, 3)
    frame = Frame(rgb=image, K=K, depth=depth.reshape(h, w).astype(np.float32),
                  normals=normals.reshape(h, w, 3).astype(np.float32))
    return frame, labels.reshape(h, w), planes


STACKS = {
    "seq-ransac": (UniformSampler, InlierCountScorer, ThresholdLabeler),
    "gc-ransac": (UniformSampler, MsacScorer, GraphCutLabeler),
    "monoplane-nocrf": (NormalConsistentSampler, MsacNormalScorer, ProximityGraphCutLabeler),
}


def make(stack, **cfg):
    sampler, scorer, labeler = STACKS[stack]
    return SequentialRansac(sampler(), scorer(), labeler(), RansacConfig(**cfg))


def match(rec, labels, planes):
    """For each ground-truth plane: the predicted plane covering most of its pixels."""
    out = []
    for k in range(1, len(planes) + 1):
        pred = rec.labels[labels == k]
        pred = pred[pred > 0]
        assert pred.size, f"plane {k} not detected"
        out.append(np.bincount(pred).argmax())
    return np.array(out)


@pytest.mark.parametrize("stack,angle_tol,offset_tol", [
    ("monoplane-nocrf", 1e-3, 1e-5), ("gc-ransac", 1.0, 0.02), ("seq-ransac", 1.0, 0.02)])
def test_recovers_the_room_planes(stack, angle_tol, offset_tol):
    frame, labels, planes = room()
    rec = make(stack).run(frame)
    assert rec.num_planes == len(planes)
    ids = match(rec, labels, planes)
    assert len(set(ids.tolist())) == len(planes)
    est = rec.planes[ids - 1]
    angle = np.degrees(np.arccos(np.clip((est[:, :3] * planes[:, :3]).sum(1), -1, 1)))
    assert angle.max() < angle_tol
    np.testing.assert_allclose(est[:, 3], planes[:, 3], atol=offset_tol * planes[:, 3].max())
    assert np.all(rec.planes[:, 3] > 0)  # normals face the camera
    np.testing.assert_array_equal(rec.support, rec.area_px)
    # Pixel accuracy of the segmentation.
    agree = np.mean(ids[labels - 1] == rec.labels)
    assert agree > (0.98 if stack == "monoplane-nocrf" else 0.9)


def test_exact_planes_have_near_zero_rmse_and_labels_are_int32():
    frame, labels, planes = room()
    rec = make("monoplane-nocrf").run(frame)
    assert rec.labels.dtype == np.int32 and rec.labels.shape == frame.shape
    assert rec.rmse.max() < 1e-4
    assert set(rec.timings) >= {"ransac.search", "ransac.label", "ransac.graph"}


def test_same_seed_same_result():
    frame, _, _ = room()
    a = make("monoplane-nocrf", max_points=3000).run(frame)
    b = make("monoplane-nocrf", max_points=3000).run(frame)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.planes, b.planes)


def test_meanwhile_runs_once_with_the_graph_under_way():
    frame, _, _ = room()
    calls = []
    a = make("monoplane-nocrf", max_points=3000).run(frame, meanwhile=lambda: calls.append(1))
    b = make("monoplane-nocrf", max_points=3000).run(frame)
    assert calls == [1]
    np.testing.assert_array_equal(a.labels, b.labels)


def test_labeler_pool_preparation_runs_for_every_pool(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "2")
    frame, _, _ = room()
    driver = make("monoplane-nocrf", max_points=3000)
    pools = []
    prepare = driver.labeler.prepare_pool
    monkeypatch.setattr(driver.labeler, "prepare_pool",
                        lambda cloud, graph, pool, context: (
                            pools.append(pool.size), prepare(cloud, graph, pool, context)))
    rec = driver.run(frame)
    # For the whole cloud, then once after each accepted plane, on the shrinking pool; the
    # labels do not change.
    assert len(pools) == rec.num_planes + 1 and pools == sorted(pools, reverse=True)
    assert pools[0] == driver.config.max_points
    np.testing.assert_array_equal(rec.labels,
                                  make("monoplane-nocrf", max_points=3000).run(frame).labels)


def test_pool_subgraphs_taken_from_the_last_pool_change_no_label(monkeypatch):
    import monoplane.geometry.graph as graph

    frame, _, _ = room()
    shrunk = make("monoplane-nocrf", max_points=3000).run(frame)
    monkeypatch.setattr(graph, "shrink_subgraph", lambda *args: None)  # the whole graph
    whole = make("monoplane-nocrf", max_points=3000).run(frame)
    np.testing.assert_array_equal(shrunk.labels, whole.labels)
    np.testing.assert_array_equal(shrunk.planes, whole.planes)


def test_depth_only_input_without_colour():
    frame, labels, planes = room(rgb=False)
    rec = make("monoplane-nocrf").run(frame)
    assert rec.num_planes == len(planes)
    ids = match(rec, labels, planes)
    np.testing.assert_allclose(rec.planes[ids - 1], planes, atol=1e-4)


def test_planes_come_back_in_the_depth_units():
    frame, _, _ = room()
    mm = frame.with_(depth=frame.depth * 1000.0, depth_units="mm")
    a = make("monoplane-nocrf").run(frame)
    b = make("monoplane-nocrf").run(mm)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_allclose(b.planes[:, :3], a.planes[:, :3], atol=1e-6)
    np.testing.assert_allclose(b.planes[:, 3], 1000.0 * a.planes[:, 3], rtol=1e-5)
    np.testing.assert_allclose(b.rmse, 1000.0 * a.rmse, atol=1e-3)


def test_subsampled_run_labels_every_valid_pixel_of_the_planes():
    frame, labels, planes = room(h=120, w=160)
    depth = frame.depth.copy()
    depth[:10, :10] = 0.0  # invalid corner
    frame = frame.with_(depth=depth)
    rec = make("monoplane-nocrf", max_points=4000).run(frame)
    assert np.all(rec.labels[:10, :10] == 0)
    ids = match(rec, labels, planes)
    valid = frame.valid
    assert np.mean(ids[labels[valid] - 1] == rec.labels[valid]) > 0.97
    np.testing.assert_allclose(rec.planes[ids - 1], planes, atol=5e-3)


def test_grid_sampling_recovers_the_room_with_the_lattice_graph():
    frame, labels, planes = room(h=120, w=160)
    driver = make("monoplane-nocrf", max_points=4000, sampling="grid")
    rec = driver.run(frame)
    ids = match(rec, labels, planes)
    assert len(set(ids.tolist())) == len(planes)
    assert np.mean(ids[labels - 1] == rec.labels) > 0.97
    np.testing.assert_allclose(rec.planes[ids - 1], planes, atol=1e-2)


def test_lattice_normal_cut_keeps_flat_walls_whole():
    # Each wall's normals are one vector: a 12 degree cut parts the walls, not a wall.
    frame, labels, planes = room(h=120, w=160)
    driver = make("monoplane-nocrf", max_points=4000, sampling="grid", lattice_max_turn_deg=12.0)
    rec = driver.run(frame)
    ids = match(rec, labels, planes)
    assert len(set(ids.tolist())) == len(planes)
    assert np.mean(ids[labels - 1] == rec.labels) > 0.97
    np.testing.assert_allclose(rec.planes[ids - 1, :3], planes[:, :3], atol=1e-2)


@pytest.mark.parametrize("reach,whole", [(6, True), (1, False)])
def test_lattice_split_joins_a_plane_behind_a_thin_post(reach, whole):
    # A post 4 px wide, 1 m from the camera, parts floor and back wall in the image from top
    # to bottom: in 3D each wall's two sides lie 0.035 of their distance apart (4 px at
    # f = 114 px), within the jump limit, so they join across the post with reach 6 (the
    # post is 2 lattice steps wide); with the lattice graph's links only, each wall's
    # inliers fall into two parts and the smaller one becomes a plane of its own.
    frame, labels, _ = room(h=120, w=160)
    depth = frame.depth.copy()
    post = np.zeros(labels.shape, dtype=bool)
    post[:, 78:82] = True
    depth[post] = 1.0
    normals = frame.normals.copy()
    normals[post] = (0.0, 0.0, -1.0)
    frame = frame.with_(depth=depth, normals=normals)
    driver = make("monoplane-nocrf", max_points=4000, sampling="grid", split_components=True,
                  lattice_split_reach=reach)
    rec = driver.run(frame)
    for wall in (1, 2):  # floor, back wall
        counts = np.sort(np.bincount(rec.labels[(labels == wall) & ~post])[1:])
        # Split: a second plane holds 40-50 % of the wall; whole: none more than 10 %.
        assert (counts[-2] < 0.1 * counts.sum()) == whole
        assert counts[-1] > 0.4 * counts.sum()


def test_sampling_must_be_named():
    with pytest.raises(ConfigError, match="sampling must be one of auto, random, grid"):
        RansacConfig(sampling="lattice")
    with pytest.raises(ConfigError, match="lattice_max_turn_deg must lie in"):
        RansacConfig(lattice_max_turn_deg=0.0)
    with pytest.raises(ConfigError, match="lattice_turn_deg must be non-negative"):
        RansacConfig(lattice_turn_deg=-1.0)
    with pytest.raises(ConfigError, match="lattice_split_reach must be at least 1"):
        RansacConfig(lattice_split_reach=0)
    with pytest.raises(ConfigError, match="lattice_fragments must be non-negative"):
        RansacConfig(lattice_fragments=-1)


def test_max_planes_and_min_support_stop_the_search():
    frame, _, _ = room()
    assert make("gc-ransac", max_planes=2).run(frame).num_planes == 2
    # With a 30 % minimum only the largest surfaces qualify.
    big = make("monoplane-nocrf", min_support=0.3).run(frame)
    assert 1 <= big.num_planes < 5
    assert np.all(big.area_px >= 0.25 * frame.valid.sum())


def test_a_failing_stage_is_reported_with_kind_and_name():
    class Broken(UniformSampler):
        name = "broken"

        def sample(self, *args):
            raise RuntimeError("boom")

    frame, _, _ = room(h=24, w=32)
    ransac = SequentialRansac(Broken(), MsacScorer(), ThresholdLabeler())
    with pytest.raises(StageError, match="sampler stage 'broken' failed: boom"):
        ransac.run(frame)


def test_needed_samples():
    assert needed_samples(0.5, 0.99) == pytest.approx(np.log(0.01) / np.log(1 - 0.125))
    assert needed_samples(0.0, 0.99) == np.inf
    assert needed_samples(1.0, 0.99) == 1.0


@pytest.mark.parametrize("split", [False, True])
def test_split_components_separates_two_coplanar_patches(split):
    # One fronto-parallel plane z = 3 seen through a 40-column gap of invalid pixels: the two
    # halves are one plane geometrically, two surfaces spatially.
    h, w = 48, 96
    K = default_intrinsics(w, h, 60.0)
    depth = np.full((h, w), 3.0, dtype=np.float32)
    depth[:, 28:68] = 0.0
    normals = np.tile(np.array([0, 0, -1], dtype=np.float32), (h, w, 1))
    frame = Frame(rgb=None, K=K, depth=depth, normals=normals)
    rec = make("monoplane-nocrf", split_components=split).run(frame)
    left, right = rec.labels[:, :28], rec.labels[:, 68:]
    assert np.all(left > 0) and np.all(right > 0)
    assert len(np.unique(left)) == 1 and len(np.unique(right)) == 1
    assert rec.num_planes == (2 if split else 1)
    assert (left[0, 0] != right[0, 0]) == split
    np.testing.assert_allclose(rec.planes[:, 3], 3.0, rtol=1e-6)


def test_run_cloud_is_the_core_of_run():
    # The cloud-level core needs no pixels: on the frame's own cloud and graph it gives the
    # labels that run() carries to the pixels and planes that are the normalised-frame ones.
    frame, labels, planes = room()
    ransac = make("monoplane-nocrf")
    cloud = PlaneCloud.from_frame(frame)
    graph = NeighbourGraph.build(cloud.points, ransac.config.knn)
    point_labels, found, timings = ransac.run_cloud(cloud, graph)
    assert point_labels.dtype == np.int32 and point_labels.shape == (cloud.size,)
    assert found.shape == (len(planes), 4)
    assert set(timings) == {"ransac.search", "ransac.label"}
    rec = ransac.run(frame)
    np.testing.assert_array_equal(rec.labels.ravel()[cloud.pixels], point_labels)
    cam = orient_towards_camera(cloud.plane_to_camera(found))
    np.testing.assert_allclose(cam, rec.planes, atol=1e-6)


def test_run_cloud_rejects_a_graph_of_another_cloud():
    frame, _, _ = room(h=24, w=32)
    cloud = PlaneCloud.from_frame(frame)
    graph = NeighbourGraph.build(cloud.points[:-1], 8)
    with pytest.raises(InvalidInput, match="graph has"):
        make("gc-ransac").run_cloud(cloud, graph)


class _BatchByBatch:
    """A sampler or scorer seen through a wrapper that states nothing, so that the driver
    calls it batch by batch."""

    draws = scores = None

    def __init__(self, stage):
        self._stage = stage
        self.kind, self.name = stage.kind, stage.name

    def __getattr__(self, attr):
        return getattr(self._stage, attr)


@pytest.mark.parametrize("sampler", [NormalConsistentSampler, UniformSampler])
def test_the_compiled_search_equals_the_batch_by_batch_loop(sampler):
    # search_batches runs the whole adaptive search in one call when the sampler and scorer
    # allow it; it must give the loop's hypothesis and leave the generator where it does
    # (it gives up hypotheses that cannot beat the best so far; the scorer's costs are all
    # exact).
    from monoplane.synth import generate

    frame = generate(3, "mild", width=128, height=96, n_views=1, objects=6).views[0].frame
    cloud = PlaneCloud.from_frame(frame)
    fused = SequentialRansac(sampler(), MsacNormalScorer(), ThresholdLabeler())
    looped = SequentialRansac(_BatchByBatch(fused.sampler), _BatchByBatch(fused.scorer),
                              fused.labeler)
    assert fused.compiled_search and not looped.compiled_search
    params = fused.config.params
    pools = [np.arange(cloud.size), np.flatnonzero(np.arange(cloud.size) % 3 != 1),
             np.arange(0, cloud.size, 7)[:40]]
    for pool in pools:
        rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
        a = fused._search(cloud, pool, rng_a, params)
        b = looped._search(cloud, pool, rng_b, params)
        assert a is not None and b is not None
        np.testing.assert_array_equal(a[0], b[0])
        np.testing.assert_array_equal(a[1], b[1])
        assert rng_a.bit_generator.state == rng_b.bit_generator.state


class _PluginUniform(Sampler):
    """A third-party sampler that draws as the built-in uniform one does, and says so."""

    name = "plugin-uniform"
    draws = "uniform"

    def __init__(self, config=None):
        super().__init__(config)
        self.calls = 0

    def sample(self, cloud, pool, count, rng, params):
        self.calls += 1
        return draw_triplets(rng, pool, count, count, count)


class _OwnUniform(UniformSampler):
    """A subclass of the built-in sampler with its own sample(), which states nothing."""

    name = "own-uniform"

    def __init__(self, config=None):
        super().__init__(config)
        self.calls = 0

    def sample(self, cloud, pool, count, rng, params):
        self.calls += 1
        return super().sample(cloud, pool, count, rng, params)


def _room_planes_recovered(rec, labels, planes):
    ids = match(rec, labels, planes)
    assert rec.num_planes == len(planes) and len(set(ids.tolist())) == len(planes)
    est = rec.planes[ids - 1]
    assert np.degrees(np.arccos(np.clip((est[:, :3] * planes[:, :3]).sum(1), -1, 1))).max() < 1e-3
    np.testing.assert_allclose(est[:, 3], planes[:, 3], atol=1e-5 * planes[:, 3].max())


def test_a_sampler_stating_its_draw_gets_the_compiled_search():
    frame, labels, planes = room()
    sampler = _PluginUniform()
    ransac = SequentialRansac(sampler, MsacNormalScorer(), ProximityGraphCutLabeler())
    assert ransac.compiled_search
    rec = ransac.run(frame)
    assert sampler.calls == 0  # the host drew its samples in the compiled search
    _room_planes_recovered(rec, labels, planes)
    builtin = SequentialRansac(UniformSampler(), MsacNormalScorer(),
                               ProximityGraphCutLabeler()).run(frame)
    np.testing.assert_array_equal(rec.labels, builtin.labels)


def test_a_subclass_overriding_sample_without_stating_is_called_batch_by_batch():
    assert UniformSampler.draws == "uniform" and _OwnUniform.draws is None
    frame, labels, planes = room()
    sampler = _OwnUniform()
    ransac = SequentialRansac(sampler, MsacNormalScorer(), ProximityGraphCutLabeler())
    assert not ransac.compiled_search
    rec = ransac.run(frame)
    assert sampler.calls > 0
    _room_planes_recovered(rec, labels, planes)
    # Its sample() draws what the built-in one does: batch by batch gives the compiled labels.
    builtin = SequentialRansac(UniformSampler(), MsacNormalScorer(),
                               ProximityGraphCutLabeler()).run(frame)
    np.testing.assert_array_equal(rec.labels, builtin.labels)


def test_statements_are_checked_and_kept_by_subclasses_that_do_not_override():
    with pytest.raises(PluginError, match="draws = 'gaussian'"):
        type("Gaussian", (Sampler,), {"draws": "gaussian"})

    class Thrifty(NormalConsistentSampler):
        def draw_budget(self, count):
            return 4 * count

    assert Thrifty.draws == "normal-consistent"
    assert SequentialRansac(Thrifty(), MsacNormalScorer(), ThresholdLabeler()).compiled_search
    # A scorer that states another cost keeps the batch-by-batch search.
    assert not SequentialRansac(UniformSampler(), MsacScorer(), ThresholdLabeler()).compiled_search


def tiled_frame() -> Frame:
    """48x96 depth-only frame: plane z = 3 as 4x4-pixel tiles 8 pixels apart over the left
    64 columns (768 px), a compact patch of plane z = 2 in the top right (384 px)."""
    h, w = 48, 96
    depth = np.zeros((h, w), dtype=np.float32)
    for r in range(0, h, 8):
        for c in range(0, 64, 8):
            depth[r:r + 4, c:c + 4] = 3.0
    depth[:24, 80:] = 2.0
    normals = np.tile(np.array([0, 0, -1], dtype=np.float32), (h, w, 1))
    return Frame(rgb=None, K=default_intrinsics(w, h, 60.0), depth=depth, normals=normals)


@pytest.mark.parametrize("rejections", [0, 1])
def test_max_rejections_passes_over_a_plane_that_falls_apart(rejections):
    # Plane z = 3 seen as 4x4-pixel tiles (768 px, no tile reaches the 10 % minimum support)
    # and one compact patch of plane z = 2 (384 px): the tiled plane has more inliers, so it
    # is found first and falls apart into its tiles. Stopping there loses the patch; passing
    # over the tiles once finds it.
    frame = tiled_frame()
    rec = make("monoplane-nocrf", split_components=True, min_support=0.1,
               max_rejections=rejections).run(frame)
    assert rec.num_planes == rejections
    if rejections:
        assert np.all(rec.labels[:24, 80:] == 1) and np.all(rec.labels[:, :64] == 0)
        np.testing.assert_allclose(rec.planes[0, 3], 2.0, rtol=1e-6)


@pytest.mark.parametrize(("sampling", "fragments", "found"),
                         [("grid", 0, 0), ("grid", 1, 1), ("random", 1, 0)])
def test_lattice_fragments_pass_over_a_plane_that_falls_apart_on_the_lattice(
        sampling, fragments, found):
    # The tiled plane of the test above on the pixel lattice (every pixel a sample): its
    # labelled inliers reach the minimum support, its parts do not. With lattice_fragments it
    # is passed over without max_rejections, and the patch is found; random samples ignore it.
    frame = tiled_frame()
    rec = make("monoplane-nocrf", split_components=True, min_support=0.1, sampling=sampling,
               lattice_fragments=fragments).run(frame)
    assert rec.num_planes == found
    if found:
        assert np.all(rec.labels[:24, 80:] == 1) and np.all(rec.labels[:, :64] == 0)
        np.testing.assert_allclose(rec.planes[0, 3], 2.0, rtol=1e-6)


def test_noise_factor_lowers_epsilon_to_the_depth_noise():
    # A wall 2 m away under 1 mm depth noise with a flat box 5 cm in front of it, in a scene
    # that a few pixels make 10 m deep: ε = 0.02 of the radius (about 15 cm) takes the box
    # into the wall; ε from the noise measured on the wall keeps it apart.
    h, w = 60, 80
    rng = np.random.default_rng(0)
    depth = np.full((h, w), 2.0) + rng.normal(0, 0.001, (h, w))
    depth[20:40, 30:50] -= 0.05
    depth[:2, :2] = 10.0
    normals = np.tile(np.array([0, 0, -1], dtype=np.float32), (h, w, 1))
    frame = Frame(rgb=None, K=default_intrinsics(w, h, 60.0), depth=depth.astype(np.float32),
                  normals=normals)
    loose = make("monoplane-nocrf", split_components=True).run(frame)
    assert loose.labels[30, 40] == loose.labels[10, 10]
    tight = make("monoplane-nocrf", split_components=True, noise_factor=3.0)
    rec = tight.run(frame)
    assert tight.params_used.epsilon < 0.2 * tight.config.epsilon
    box, wall = rec.labels[21:39, 31:49], rec.labels[45:, 5:75]
    assert np.all(box == box[0, 0]) and np.all(wall == wall[0, 0]) and box[0, 0] != wall[0, 0]
    np.testing.assert_allclose(rec.planes[box[0, 0] - 1, 3], 1.95, atol=2e-3)


@pytest.mark.parametrize("noise", [0.001, 0.008])
def test_noise_planes_caps_only_the_search_that_measures_the_noise(monkeypatch, noise):
    # Eight fronto-parallel steps 10 cm apart: the first search measures the noise on one
    # plane only, the second still finds every step, with ε lowered to 1 mm noise, or with
    # the configured ε when 8 mm of noise is too close to it to search again for.
    h, w = 64, 80
    rng = np.random.default_rng(1)
    depth = 2.0 + 0.1 * (np.arange(w) // 10)[None, :] + rng.normal(0, noise, (h, w))
    normals = np.tile(np.array([0, 0, -1], dtype=np.float32), (h, w, 1))
    frame = Frame(rgb=None, K=default_intrinsics(w, h, 60.0), depth=depth.astype(np.float32),
                  normals=normals)
    found: list[int] = []
    run = SequentialRansac._run

    def counted(self, *args, **kwargs):
        result = run(self, *args, **kwargs)
        found.append(len(result.planes))
        return result

    monkeypatch.setattr(SequentialRansac, "_run", counted)
    driver = make("monoplane-nocrf", split_components=True, noise_factor=3.0, noise_planes=1)
    weighed = []
    weights = driver.labeler._cut
    monkeypatch.setattr(driver.labeler, "_cut", lambda cloud, graph, ids, context: (
        weighed.append(context.weights is None), weights(cloud, graph, ids, context))[1])
    rec = driver.run(frame)
    assert (driver.params_used.epsilon < driver.config.epsilon) == (noise < 0.005)
    assert found == [1, 8] and rec.num_planes == 8
    # The two searches share the labeler's memory of the frame: its cut costs once.
    assert weighed.count(True) == 1
