"""The kNN graph of a frame's samples found through the image: the point index's answer."""

import numpy as np
import pytest

from monoplane.datamodel import Frame, intrinsics_matrix, pixel_rays
from monoplane.errors import InvalidInput
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.graph import NeighbourGraph
from monoplane.geometry.neighbours import PointIndex
from monoplane.geometry.propagation import SampleImage, image_knn


def room_frame(seed, h=120, w=160, skew=0.0):
    """Depth from 0.8 to 9 m: a slanted floor, a wall, a box in front (depth jumps), sensor
    noise, holes and isolated valid pixels far from any other."""
    rng = np.random.default_rng(seed)
    K = intrinsics_matrix(130.0, 125.0, 79.5, 59.5)
    K[0, 1] = skew
    rays = pixel_rays(K, h, w)
    wall = np.full((h, w), 9.0)
    floor = 1.2 / np.maximum(rays[..., 1], 1e-3)  # the plane y = 1.2 below the camera
    depth = np.minimum(wall, floor)
    depth[30:70, 50:90] = 0.8 + 0.3 * rays[30:70, 50:90, 0]  # a box close by
    depth *= 1.0 + 0.002 * rng.standard_normal((h, w))
    depth[rng.random((h, w)) < 0.1] = 0.0
    depth[5:40, 100:150] = 0.0  # a large hole ...
    depth[20, 120] = 3.0  # ... with two lone valid pixels in it
    depth[22, 140] = 6.0
    normals = np.tile(np.float32([0, 0, -1]), (h, w, 1))
    return Frame(rgb=None, K=K, depth=depth.astype(np.float32), normals=normals)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("k", [1, 9])
def test_image_search_gives_the_point_index_answer(seed, k):
    cloud = PlaneCloud.from_frame(room_frame(seed), 4000, np.random.default_rng(seed))
    d2, idx, missed = image_knn(cloud.points, cloud.sample_image, k)
    ref_d, ref_i = PointIndex(cloud.points).query_indexed(k)
    found = np.ones(cloud.size, dtype=bool)
    found[missed] = False
    np.testing.assert_array_equal(idx[found], ref_i[found])
    np.testing.assert_array_equal(np.sqrt(d2[found]), ref_d[found])
    assert missed.size < 0.02 * cloud.size  # lone samples and the far floor, not the rest


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("skew", [0.0, 1.5])
def test_graph_through_the_image_is_the_kd_graph(threads, skew, monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", str(threads))
    monkeypatch.setattr("monoplane.geometry.propagation.KNN_THREADED", 500)
    cloud = PlaneCloud.from_frame(room_frame(7, skew=skew), 5000, np.random.default_rng(1))
    ref = NeighbourGraph.build(cloud.points, 8)
    g = cloud.neighbour_graph(8)
    np.testing.assert_array_equal(g.edges, ref.edges)
    assert g.spacing == ref.spacing
    # The lone pixels' samples (when drawn) are left to the cloud's own point index, built
    # for them and kept on the cloud.
    _, _, missed = image_knn(cloud.points, cloud.sample_image, 9)
    assert (g.tree is None) == (missed.size == 0)
    assert g.tree is None or g.tree is cloud.tree


def test_frames_of_fewer_samples_than_neighbours():
    depth = np.zeros((6, 8), np.float32)
    depth[1, 1], depth[4, 6], depth[2, 5] = 1.0, 2.0, 2.5
    frame = Frame(rgb=None, K=intrinsics_matrix(10.0, 10.0, 3.5, 2.5), depth=depth,
                  normals=np.tile(np.float32([0, 0, -1]), (6, 8, 1)))
    cloud = PlaneCloud.from_frame(frame)
    for k in (1, 2, 5):
        g = cloud.neighbour_graph(k)
        ref = NeighbourGraph.build(cloud.points, k)
        np.testing.assert_array_equal(g.edges, ref.edges)
        assert g.spacing == ref.spacing


def test_sample_image_needs_pixels_and_a_pinhole_camera():
    cloud = PlaneCloud.from_frame(room_frame(0), 500, np.random.default_rng(0))
    image = cloud.sample_image
    assert isinstance(image, SampleImage) and image.pixels is cloud.pixels
    bare = PlaneCloud.from_points(cloud.points, cloud.normals, None, cloud.center, cloud.scale)
    assert bare.sample_image is None
    with pytest.raises(InvalidInput, match="image holds 500 samples"):
        NeighbourGraph.build(cloud.points[:-1], 4, image=image)


@pytest.mark.parametrize("spread", [0.0, 1.0])
def test_frames_without_image_neighbours_are_left_to_the_point_index(spread):
    """Depth drawn at random per pixel (no surface) or a few scattered valid pixels: the
    samples' neighbours in 3D are not near them in the image, and the search gives up."""
    rng = np.random.default_rng(3)
    h, w = 120, 160
    depth = rng.uniform(1.0, 9.0, (h, w))
    if not spread:
        depth[rng.random((h, w)) < 0.97] = 0.0
    frame = Frame(rgb=None, K=intrinsics_matrix(130.0, 130.0, 79.5, 59.5),
                  depth=depth.astype(np.float32),
                  normals=np.tile(np.float32([0, 0, -1]), (h, w, 1)))
    cloud = PlaneCloud.from_frame(frame, 4000, np.random.default_rng(0))
    _, _, missed = image_knn(cloud.points, cloud.sample_image, 9)
    np.testing.assert_array_equal(missed, np.arange(cloud.size))
    g = cloud.neighbour_graph(8)
    np.testing.assert_array_equal(g.edges, NeighbourGraph.build(cloud.points, 8).edges)
    assert g.tree is cloud.tree  # one index per cloud: the graph's is the cloud's


def test_a_runs_first_sample_widens_its_window_to_hold_k():
    # Samples every 6 pixels: the first window (two tiles either way) holds 9 samples, fewer
    # than the 10 asked for, and no earlier sample gives it a limit. It doubles instead of
    # leaving the sample (and, with no limit for the next, every sample) to the point index.
    h, w = 60, 80
    depth = np.zeros((h, w), np.float32)
    depth[::6, ::6] = 2.0
    frame = Frame(rgb=None, K=intrinsics_matrix(70.0, 70.0, 39.5, 29.5), depth=depth,
                  normals=np.tile(np.float32([0, 0, -1]), (h, w, 1)))
    cloud = PlaneCloud.from_frame(frame)
    d2, idx, missed = image_knn(cloud.points, cloud.sample_image, 10)
    assert missed.size == 0
    ref_d, ref_i = PointIndex(cloud.points).query_indexed(10)
    np.testing.assert_array_equal(idx, ref_i)
    np.testing.assert_array_equal(np.sqrt(d2), ref_d)
