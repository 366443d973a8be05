"""The pipeline on real sensor-like RGB-D (../shared/data/rgbd-livingroom): an RGB-D frame and
the same depth as a depth-only range image."""

from pathlib import Path

import numpy as np
import pytest

from monoplane import Pipeline, load_frame

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "rgbd-livingroom"
pytestmark = pytest.mark.skipif(not DATA.is_dir(), reason=f"real RGB-D frames not found at {DATA}")
INTRINSICS = "525,525,319.5,239.5"


def check_planes_explain_depth(rec):
    depth = rec.frame.depth
    labelled = (rec.labels > 0) & (depth > 0)
    # Indoor scenes are mostly planar: walls, floor, furniture faces.
    assert labelled.sum() > 0.5 * (depth > 0).sum()
    rel = np.abs(rec.planar_depth()[labelled] - depth[labelled]) / depth[labelled]
    assert np.median(rel) < 0.01, "planes must agree with the sensor depth on their pixels"
    big = np.argsort(rec.area_px)[::-1][:3]
    assert np.all(rec.rmse[big] < 0.03), "the largest planes fit to a few centimetres (metres)"
    assert np.all(rec.params[:, 3] > 0), "normals face the camera"


@pytest.fixture(scope="module")
def pipe():
    return Pipeline.from_preset("monoplane")


def test_rgbd_frame(pipe):
    frame = load_frame(DATA / "color_00000.jpg", depth=DATA / "depth_00000.png",
                       depth_scale=1000.0, intrinsics=INTRINSICS)
    rec = pipe.run(frame)
    assert rec.frame.depth_units == "m" and 3 <= rec.num_planes <= 30
    check_planes_explain_depth(rec)


def test_depth_only_range_image(pipe):
    frame = load_frame(depth=DATA / "depth_00000.png", depth_scale=1000.0,
                       intrinsics=INTRINSICS)
    assert frame.rgb is None
    rec = pipe.run(frame)
    assert 3 <= rec.num_planes <= 30
    check_planes_explain_depth(rec)
