"""PlaneCloud: unprojection, unit-sphere normalisation, plane frame changes, propagation."""

import numpy as np
import pytest

from monoplane.datamodel import Frame, default_intrinsics, intrinsics_matrix, pixel_rays
from monoplane.errors import InvalidInput
from monoplane.geometry.cloud import (
    PROPAGATION_NEIGHBOURS,
    PROPAGATION_RADIUS_FACTOR,
    PlaneCloud,
    lattice_lines,
    lattice_step,
    lattice_stride,
)
from monoplane.geometry.distance_transform import nearest_true_pixel
from monoplane.geometry.graph import NeighbourGraph
from monoplane.testing import ROOM, room_cues

K = intrinsics_matrix(40.0, 40.0, 15.5, 11.5)


def slanted_frame(rgb=True, grey=False, hole=True):
    """A 24x32 view of the plane z = 2 + 0.5 x (camera frame), with an invalid 4x4 hole."""
    rays = pixel_rays(K, 24, 32)
    depth = 2.0 / (1.0 - 0.5 * rays[..., 0])  # z = 2 + 0.5 x with x = z * ray_x
    n = np.array([0.5, 0.0, -1.0]) / np.linalg.norm([0.5, 0.0, -1.0])
    normals = np.broadcast_to(n, (24, 32, 3)).copy()
    if hole:
        depth[5:9, 5:9] = 0.0
    image = None
    if rgb:
        image = np.zeros((24, 32, 3), np.uint8)
        image[..., 0] = 200
        image[..., 1] = 100 if not grey else 200
        image[..., 2] = 50 if not grey else 200
    return Frame(rgb=image, K=K, depth=depth.astype(np.float32),
                 normals=normals.astype(np.float32))


def test_points_lie_in_unit_sphere_and_invert_to_camera_points():
    f = slanted_frame()
    c = PlaneCloud.from_frame(f)
    assert c.size == 24 * 32 - 16
    norms = np.linalg.norm(c.points, axis=1)
    assert norms.max() == pytest.approx(1.0)
    np.testing.assert_allclose(c.points.mean(axis=0), 0.0, atol=1e-12)
    cam = f.points().reshape(-1, 3)[c.pixels]
    np.testing.assert_allclose(c.points * c.scale + c.center, cam, atol=1e-6)
    assert not np.isin(np.ravel_multi_index((6, 6), (24, 32)), c.pixels)
    np.testing.assert_allclose(np.linalg.norm(c.normals, axis=1), 1.0)
    assert c.colors.shape == (c.size, 3)
    np.testing.assert_allclose(c.colors[0], [200 / 255, 100 / 255, 50 / 255])


@pytest.mark.parametrize("rgb,grey", [(False, False), (True, True)])
def test_colour_is_dropped_without_rgb_or_for_grey_images(rgb, grey):
    c = PlaneCloud.from_frame(slanted_frame(rgb=rgb, grey=grey))
    assert c.colors is None


def test_missing_normals_is_an_input_error():
    f = slanted_frame().with_(normals=None)
    with pytest.raises(InvalidInput, match="normals"):
        PlaneCloud.from_frame(f)


def test_plane_frame_changes_round_trip_and_hold_the_points():
    f = slanted_frame()
    c = PlaneCloud.from_frame(f)
    n = np.array([0.5, 0.0, -1.0]) / np.linalg.norm([0.5, 0.0, -1.0])
    cam_plane = np.r_[n, 2.0 / np.linalg.norm([0.5, 0.0, -1.0])]  # n . X + d = 0
    cam = f.points().reshape(-1, 3)[c.pixels]
    np.testing.assert_allclose(cam @ cam_plane[:3] + cam_plane[3], 0.0, atol=1e-5)
    norm_plane = c.plane_to_normalised(cam_plane)
    np.testing.assert_allclose(c.points @ norm_plane[:3] + norm_plane[3], 0.0, atol=1e-5)
    np.testing.assert_allclose(c.plane_to_camera(norm_plane), cam_plane, atol=1e-12)
    both = c.plane_to_camera(np.stack([norm_plane, norm_plane]))
    assert both.shape == (2, 4)


def test_subsampling_is_deterministic_and_propagation_fills_valid_pixels_only():
    f = slanted_frame()
    a = PlaneCloud.from_frame(f, max_points=200, rng=np.random.default_rng(3))
    b = PlaneCloud.from_frame(f, max_points=200, rng=np.random.default_rng(3))
    assert a.size == 200 and a.subsampled
    np.testing.assert_array_equal(a.pixels, b.pixels)
    assert np.all(np.diff(a.pixels) > 0)
    # Label the left half of the samples 1, the right half 2 (by image column).
    cols = a.pixels % 32
    labels = np.where(cols < 16, 1, 2)
    full = a.propagate(labels)
    assert full.shape == (24, 32) and full.dtype == np.int32
    assert np.all(full[5:9, 5:9] == 0)  # invalid pixels stay unlabelled
    valid = f.valid
    assert np.all(full[valid] > 0)
    # Away from the split every pixel gets its side's label.
    assert np.all(full[:, :12][valid[:, :12]] == 1)
    assert np.all(full[:, 20:][valid[:, 20:]] == 2)


def test_propagation_does_not_jump_far_gaps():
    f = slanted_frame(hole=False)
    depth = f.depth.copy()
    depth[:, 28:] *= 3.0  # a far-away strip: none of it gets sampled below
    f = f.with_(depth=depth)
    c = PlaneCloud.from_frame(f)
    keep = (c.pixels % 32) < 28
    sub = PlaneCloud(points=c.points[keep], normals=c.normals[keep], colors=None,
                     pixels=c.pixels[keep], center=c.center, scale=c.scale, shape=c.shape,
                     all_points=c.all_points, all_pixels=c.all_pixels)
    full = sub.propagate(np.ones(sub.size, dtype=np.int32))
    assert np.all(full[:, :28] == 1)
    assert np.all(full[:, 28:] == 0)


def noisy_room_cloud(seed=0, max_points=3000):
    """A subsampled cloud of the box room with 1 % depth noise, its true sample labels and
    planes (normalised frame): many pixels lie off their sample's plane and across creases."""
    rgb, depth, normals, labels, K = room_cues(96, 128, seed=seed)
    rng = np.random.default_rng(seed)
    depth = (depth * (1 + 0.01 * rng.normal(size=depth.shape))).astype(np.float32)
    depth[40:50, 60:80] = 0.0  # a hole, so some pixels' nearest sample is far in the image
    frame = Frame(rgb=rgb, K=K, depth=depth, normals=normals)
    cloud = PlaneCloud.from_frame(frame, max_points=max_points, rng=rng)
    planes = cloud.plane_to_normalised(ROOM)
    sample_labels = labels.ravel()[cloud.pixels].astype(np.int32)
    sample_labels[rng.random(cloud.size) < 0.05] = 0  # some non-planar samples
    return cloud, sample_labels, planes


def reference_propagation(cloud, labels, planes, graph, tolerance, tree_k=None):
    """Pixel by pixel, in Python: the rule of PlaneCloud.propagate. With ``tree_k``, every
    doubtful pixel's candidates are its exact ``tree_k`` nearest samples in 3D instead of its
    image-nearest sample and that sample's graph neighbours."""
    from scipy.ndimage import distance_transform_edt

    h, w = cloud.shape
    radius = PROPAGATION_RADIUS_FACTOR * graph.spacing
    missing = np.ones(h * w, bool)
    missing[cloud.pixels] = False
    _, (rows, cols) = distance_transform_edt(missing.reshape(h, w), return_indices=True)
    sample_of = np.full(h * w, -1)
    sample_of[cloud.pixels] = np.arange(cloud.size)
    k = PROPAGATION_NEIGHBOURS
    out = np.zeros(h * w, np.int32)
    for v, pix in enumerate(cloud.all_pixels):
        x = cloud.all_points[v]
        s = sample_of[rows.ravel()[pix] * w + cols.ravel()[pix]]
        gap = np.linalg.norm(x - cloud.points[s]) > radius
        lab = labels[s]
        if not gap and (lab == 0 or abs(planes[lab - 1, :3] @ x + planes[lab - 1, 3])
                        <= tolerance):
            out[pix] = lab
            continue
        if gap or tree_k:
            dist, cand = cloud.tree.query(x, k=k, distance_upper_bound=radius)
            cand = cand[np.isfinite(dist)]
        else:
            cand = np.r_[s, graph.neighbours(s)]
            dist = np.linalg.norm(cloud.points[cand] - x, axis=1)
            keep = dist <= radius
            cand = cand[keep][np.argsort(dist[keep], kind="stable")][:k]
        if cand.size == 0 or labels[cand[0]] == 0:
            continue
        planar = cand[labels[cand] > 0]
        res = [abs(planes[labels[c] - 1, :3] @ x + planes[labels[c] - 1, 3]) for c in planar]
        out[pix] = labels[planar[int(np.argmin(res))]]
    out[cloud.pixels] = labels
    return out.reshape(h, w)


@pytest.mark.parametrize("seed", range(3))
def test_propagation_kernel_follows_its_rule_and_nearly_matches_exact_3d_neighbours(seed):
    cloud, labels, planes = noisy_room_cloud(seed)
    graph = NeighbourGraph.build(cloud.points, 8)
    got = cloud.propagate(labels, planes, tolerance=0.005, graph=graph)
    np.testing.assert_array_equal(got, reference_propagation(cloud, labels, planes, graph,
                                                             0.005))
    # Candidates from the graph stand in for the exact 3D nearest samples: same labels but
    # on a handful of pixels.
    exact = reference_propagation(cloud, labels, planes, graph, 0.005, tree_k=True)
    valid = np.zeros(cloud.shape, bool).ravel()
    valid[cloud.all_pixels] = True
    assert np.mean(got.ravel()[valid] != exact.ravel()[valid]) < 0.005


@pytest.mark.parametrize("seed", range(3))
def test_pixels_across_a_depth_jump_find_their_samples_in_the_image_as_in_the_point_index(
        seed):
    # The room with a box in front of the back wall: the pixels along its outline whose
    # image-nearest sample lies on the other side of the jump look up their nearest samples
    # in 3D around them in the image (the intrinsics bound the window), which must give what
    # the point index gives; skewed intrinsics too.
    import dataclasses

    rgb, depth, normals, _, K = room_cues(96, 128, seed=seed)
    rng = np.random.default_rng(seed)
    depth = (depth * (1 + 0.01 * rng.normal(size=depth.shape))).astype(np.float32)
    depth[30:60, 40:90] *= 0.5
    K[0, 1] = (0.0, 3.0, -2.0)[seed]
    frame = Frame(rgb=rgb, K=K, depth=depth, normals=normals)
    cloud = PlaneCloud.from_frame(frame, max_points=2000, rng=rng)
    labels = rng.integers(0, 4, cloud.size).astype(np.int32)
    planes = cloud.plane_to_normalised(ROOM[:3])
    graph = NeighbourGraph.build(cloud.points, 8)
    radius = PROPAGATION_RADIUS_FACTOR * graph.spacing
    near = cloud.image_nearest_sample
    across = np.linalg.norm(cloud.all_points - cloud.points[near], axis=1) > radius
    assert across.sum() > 50
    got = cloud.propagate(labels, planes, tolerance=0.005, graph=graph)
    indexed = dataclasses.replace(cloud, intrinsics=None)
    np.testing.assert_array_equal(got, indexed.propagate(labels, planes, tolerance=0.005,
                                                         graph=graph))


def test_propagation_in_threaded_chunks_gives_the_single_thread_labels(monkeypatch):
    cloud, labels, planes = noisy_room_cloud(1)
    graph = NeighbourGraph.build(cloud.points, 8)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    one = cloud.propagate(labels, planes, tolerance=0.005, graph=graph)
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    monkeypatch.setattr("monoplane.geometry.cloud.THREADED_PIXELS", 1000)
    np.testing.assert_array_equal(
        cloud.propagate(labels, planes, tolerance=0.005, graph=graph), one)


@pytest.mark.parametrize("seed", range(4))
def test_unprojection_kernel_matches_frame_points(seed):
    # Reference: Frame.points() (pixel rays times depth), centred and scaled with numpy; random
    # intrinsics with skew, random depth with invalid pixels.
    rng = np.random.default_rng(seed)
    h, w = rng.integers(2, 40, size=2)
    K = intrinsics_matrix(*rng.uniform(20, 80, 2), *rng.uniform(0, 30, 2))
    K[0, 1] = rng.uniform(-2, 2)
    depth = rng.uniform(0.5, 9.0, (h, w)).astype(np.float32)
    depth[rng.random((h, w)) < 0.3] = 0.0
    depth.flat[:3] = 1.0
    frame = Frame(rgb=None, K=K, depth=depth, normals=np.tile(np.float32([0, 0, -1]), (h, w, 1)))
    cloud = PlaneCloud.from_frame(frame)
    cam = frame.points().reshape(-1, 3)[cloud.all_pixels]
    center = cam.mean(axis=0)
    scale = np.sqrt(((cam - center) ** 2).sum(axis=1).max())
    np.testing.assert_allclose(cloud.center, center, rtol=1e-12, atol=1e-12)
    assert cloud.scale == pytest.approx(scale, rel=1e-12)
    np.testing.assert_allclose(cloud.all_points, (cam - center) / scale, atol=1e-12)


@pytest.mark.parametrize("seed", range(10))
def test_nearest_true_pixel_is_at_the_exact_euclidean_distance(seed):
    # Reference: scipy's exact Euclidean distance transform; ties may pick another pixel at the
    # same distance, so distances are compared.
    from scipy.ndimage import distance_transform_edt

    rng = np.random.default_rng(seed)
    h, w = rng.integers(1, 60, size=2)
    mask = rng.random((h, w)) < rng.uniform(0.002, 0.5)
    mask[rng.integers(h), rng.integers(w)] = True
    near = nearest_true_pixel(mask)
    assert mask.ravel()[near].all()
    rows, cols = np.divmod(np.arange(h * w), w)
    dist = np.hypot(rows - near // w, cols - near % w).reshape(h, w)
    np.testing.assert_allclose(dist, distance_transform_edt(~mask), rtol=0, atol=1e-12)
    assert (nearest_true_pixel(np.zeros((3, 4), bool)) == -1).all()


def test_a_cloud_without_an_image_has_no_pixel_grid_and_labels_points_in_3d():
    rng = np.random.default_rng(0)
    xy = rng.uniform(-0.5, 0.5, (400, 2))
    points = np.column_stack([xy, np.where(xy[:, 0] < 0, 0.0, 0.3)])  # two parallel planes
    normals = np.tile([0.0, 0.0, 1.0], (400, 1))
    cloud = PlaneCloud.from_points(points, normals, None, np.zeros(3), 1.0)
    assert cloud.pixels is None and cloud.shape is None and not cloud.subsampled
    with pytest.raises(InvalidInput, match="no pixel grid"):
        cloud.pixel_grid()
    labels = np.where(xy[:, 0] < 0, 1, 2).astype(np.int32)
    planes = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 1.0, -0.3]])
    # Not subsampled: every point keeps its own label.
    np.testing.assert_array_equal(cloud.propagate(labels, planes), labels)
    queries = np.array([[-0.2, 0.0, 0.01], [0.2, 0.0, 0.29], [5.0, 5.0, 5.0]])
    assert cloud.label_points(queries, labels, planes, radius=0.2).tolist() == [1, 2, 0]


def test_a_subsampled_cloud_without_an_image_propagates_to_all_its_points():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-0.5, 0.5, (2000, 2))
    points = np.column_stack([xy, np.where(xy[:, 0] < 0, 0.0, 0.3)])  # two parallel planes
    points[0] = [5.0, 5.0, 5.0]  # far from every sample
    truth = np.where(xy[:, 0] < 0, 1, 2).astype(np.int32)
    sampled = np.sort(rng.choice(np.arange(1, 2000), 300, replace=False))
    cloud = PlaneCloud.from_points(points[sampled], np.tile([0.0, 0.0, 1.0], (300, 1)), None,
                                   np.zeros(3), 1.0, all_points=points, sampled=sampled)
    assert cloud.subsampled and cloud.pixels is None
    planes = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 1.0, -0.3]])
    out = cloud.propagate(truth[sampled], planes)
    assert out.shape == (2000,) and out.dtype == np.int32
    assert out[0] == 0  # no sample within the radius
    np.testing.assert_array_equal(out[1:], truth[1:])
    # A sampled point keeps its own label, even one its neighbours contradict.
    wrong = truth[sampled].copy()
    wrong[5] = 3 - wrong[5]
    assert cloud.propagate(wrong, planes)[sampled[5]] == wrong[5]
    with pytest.raises(InvalidInput, match="given together"):
        PlaneCloud.from_points(points[sampled], np.zeros((300, 3)), None, np.zeros(3), 1.0,
                               all_points=points)


def test_pixel_fields_come_all_or_none():
    with pytest.raises(InvalidInput, match="all given or all None"):
        PlaneCloud(points=np.zeros((3, 3)), normals=np.tile([0.0, 0.0, 1.0], (3, 1)),
                   colors=None, pixels=np.arange(3), center=np.zeros(3), scale=1.0,
                   shape=None, all_points=np.zeros((3, 3)), all_pixels=None)


def test_lattice_lines_centre_whole_and_fractional_steps():
    # A whole step s gives every s-th line from s // 2, as a slice would.
    for step in (1, 2, 3, 4):
        np.testing.assert_array_equal(lattice_lines(19, float(step)),
                                      np.arange(step // 2, 19, step))
    # A fractional step mixes its floor and ceiling and keeps the count it promises.
    lines = lattice_lines(100, 2.5)
    np.testing.assert_array_equal(lines[:4], [1, 3, 6, 8])
    assert set(np.diff(lines)) == {2, 3} and lines.size == 40 and lines[-1] < 100


def test_lattice_stride_is_the_smallest_that_fits():
    valid = np.ones((48, 64), dtype=bool)
    assert lattice_stride(valid, 48 * 64) == 1
    assert lattice_stride(valid, 48 * 64 // 4) == 2  # 24 x 32 lattice points
    assert lattice_stride(valid, 48 * 64 // 4 - 1) == 3
    valid[:, 32:] = False  # half the frame: the stride drops with the count
    assert lattice_stride(valid, 48 * 32 // 4) == 2
    with pytest.raises(InvalidInput, match="at least 3"):
        lattice_stride(valid, 2)


def test_lattice_step_is_the_smallest_that_fits():
    valid = np.ones((48, 64), dtype=bool)
    assert lattice_step(valid, 48 * 64) == 1.0
    assert lattice_step(valid, 48 * 64 // 4) == 2.0  # 24 x 32 lattice points
    # Between whole steps the lattice keeps nearly as many points as allowed, not a quarter.
    step = lattice_step(valid, 48 * 64 // 3)
    kept = lattice_lines(48, step).size * lattice_lines(64, step).size
    assert 1.6 < step < 1.8 and 0.97 * 48 * 64 // 3 <= kept <= 48 * 64 // 3
    valid[:, 32:] = False  # half the frame: the step drops with the count
    assert lattice_step(valid, 48 * 32 // 4) == 2.0
    with pytest.raises(InvalidInput, match="at least 3"):
        lattice_step(valid, 2)


def test_grid_sampling_keeps_the_valid_lattice_pixels_in_pixel_order():
    h, w = 30, 40
    depth = np.full((h, w), 2.0, dtype=np.float32)
    depth[:5] = 0.0  # invalid rows
    normals = np.zeros((h, w, 3), dtype=np.float32)
    normals[..., 2] = -1.0
    frame = Frame(rgb=None, K=default_intrinsics(w, h, 60.0), depth=depth, normals=normals)
    # A whole stride: 2, the valid pixels at odd rows and columns.
    whole = PlaneCloud.from_frame(frame, max_points=300, grid=True)
    v, u = np.divmod(whole.pixels, w)
    assert whole.stride == 2 and np.all(v % 2 == 1) and np.all(u % 2 == 1)
    assert whole.size == len(range(5, h, 2)) * len(range(1, w, 2))
    assert whole.lattice.shape == (15, 20)
    # A fractional step keeps more of the 300 allowed points.
    cloud = PlaneCloud.from_frame(frame, max_points=300, grid=True, fractional=True)
    assert cloud.stride is None and whole.size < cloud.size
    step = lattice_step(frame.valid, 300)
    rows, cols = lattice_lines(h, step), lattice_lines(w, step)
    v, u = np.divmod(cloud.pixels, w)
    assert np.all(np.isin(v, rows)) and np.all(np.isin(u, cols)) and np.all(v >= 5)
    assert cloud.size == np.count_nonzero(rows >= 5) * cols.size <= 300
    assert np.all(np.diff(cloud.pixels) > 0)
    assert cloud.subsampled and cloud.all_points.shape[0] == 25 * 40
    # The lattice: one node per lattice pixel, its point or -1 on the invalid rows.
    assert cloud.lattice.shape == (rows.size, cols.size)
    assert np.all(cloud.lattice[rows < 5] == -1)
    np.testing.assert_array_equal(cloud.lattice[rows >= 5].ravel(), np.arange(cloud.size))
    # Room for every pixel: all of them, on the lattice of step 1.
    every = PlaneCloud.from_frame(frame, max_points=10**6, grid=True, fractional=True)
    assert every.lattice.shape == (h, w) and not every.subsampled and every.stride == 1
    assert PlaneCloud.from_frame(frame, max_points=300, rng=np.random.default_rng(0)
                                 ).lattice is None


