"""XFeat through onnxruntime: output decoding against closed-form answers on a tiny stand-in
network with XFeat's signature, one-line errors, and the real backbone on a known warp."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.features.matching import mutual_nearest
from monoplane.features.xfeat import XFeatNetwork, _heatmap, _subpixel

REAL = Path(__file__).resolve().parents[3] / "shared" / "models" / "xfeat" / "xfeat.onnx"


def _tiny_xfeat(path: Path, descriptor_channels: int = 64) -> Path:
    """A network with XFeat's signature whose keypoint logits are 20 x the grey image,
    unfolded into cells by SpaceToDepth (channel r * 8 + c is pixel (r, c) of the cell, as
    XFeat's), with a "no keypoint" logit of 5: a lone bright pixel is a keypoint there."""
    from onnx import TensorProto, helper, numpy_helper, save_model

    rng = np.random.default_rng(0)
    inits = [
        numpy_helper.from_array(np.array([20.0], np.float32), "gain"),
        numpy_helper.from_array(np.full((1, 1, 80, 80), 5.0, np.float32), "dustbin"),
        numpy_helper.from_array(rng.normal(size=(1, descriptor_channels, 80, 80))
                                .astype(np.float32), "desc_const"),
        numpy_helper.from_array(np.full((1, 1, 80, 80), 0.5, np.float32), "rel_const"),
    ]
    nodes = [
        helper.make_node("ReduceMean", ["input"], ["grey"], axes=[1], keepdims=1),
        helper.make_node("Mul", ["grey", "gain"], ["scaled"]),
        helper.make_node("SpaceToDepth", ["scaled"], ["cells"], blocksize=8),
        helper.make_node("Concat", ["cells", "dustbin"], ["logits"], axis=1),
        helper.make_node("Identity", ["desc_const"], ["descriptors"]),
        helper.make_node("Identity", ["rel_const"], ["reliability"]),
    ]
    f = TensorProto.FLOAT
    graph = helper.make_graph(
        nodes, "tiny_xfeat", [helper.make_tensor_value_info("input", f, [1, 3, 640, 640])],
        [helper.make_tensor_value_info("descriptors", f, [1, descriptor_channels, 80, 80]),
         helper.make_tensor_value_info("logits", f, [1, 65, 80, 80]),
         helper.make_tensor_value_info("reliability", f, [1, 1, 80, 80])], initializer=inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    save_model(model, str(path))
    return path


def test_heatmap_unfolds_cell_channels_row_major() -> None:
    logits = np.zeros((65, 80, 80), np.float32)
    logits[64] = 3.0
    logits[3 * 8 + 5, 2, 7] = 12.0  # cell (row 2, column 7), pixel (3, 5) inside it
    heat = _heatmap(logits)
    assert heat.shape == (640, 640)
    assert np.unravel_index(np.argmax(heat), heat.shape) == (2 * 8 + 3, 7 * 8 + 5)
    # Each cell's 64 pixels and its dustbin share one softmax.
    cell = heat[16:24, 56:64]
    dustbin = np.exp(3.0) / (np.exp(12.0) + 63 + np.exp(3.0))
    np.testing.assert_allclose(cell.sum() + dustbin, 1.0, rtol=1e-5)


def test_subpixel_offset_of_a_parabola_peak() -> None:
    u, v = np.meshgrid(np.arange(20.0), np.arange(20.0))
    heat = (1.0 - 0.01 * ((u - 9.3) ** 2 + (v - 10.8) ** 2)).astype(np.float32)
    off = _subpixel(heat, np.array([11]), np.array([9]))
    np.testing.assert_allclose(off, [[0.3, -0.2]], atol=1e-5)


def test_keypoints_land_on_the_bright_pixels(tmp_path: Path) -> None:
    net = XFeatNetwork(_tiny_xfeat(tmp_path / "tiny.onnx"), threads=1)
    image = np.zeros((480, 640, 3), np.uint8)
    image[57, 101] = 255
    image[300, 400] = 255
    kp = net.detect(image)
    # Within 0.01 px: a neighbour across a cell border has another cell's softmax behind it.
    np.testing.assert_allclose(sorted(map(tuple, kp.pixels)), [(101, 57), (400, 300)], atol=0.01)
    assert kp.descriptors.shape == (2, 64)
    np.testing.assert_allclose(np.linalg.norm(kp.descriptors, axis=1), 1.0, rtol=1e-5)


def test_keypoints_come_back_in_the_images_own_pixels(tmp_path: Path) -> None:
    # A 1280 x 960 image is halved: its 2 x 2 bright block becomes one network pixel,
    # whose centre maps back to the block's centre.
    net = XFeatNetwork(_tiny_xfeat(tmp_path / "tiny.onnx"), threads=1)
    image = np.zeros((960, 1280, 3), np.uint8)
    image[114:116, 202:204] = 255
    kp = net.detect(image)
    np.testing.assert_allclose(kp.pixels, [[202.5, 114.5]], atol=1e-6)


def test_missing_and_mismatched_models_are_one_line_errors(tmp_path: Path) -> None:
    with pytest.raises(InvalidInput, match=r"xfeat model file not found: .*nothing\.onnx") as e:
        XFeatNetwork(tmp_path / "nothing.onnx")
    assert "\n" not in str(e.value)
    wrong = _tiny_xfeat(tmp_path / "wrong.onnx", descriptor_channels=32)
    with pytest.raises(InvalidInput, match=r"not an XFeat backbone.*descriptors\(1, 32, 80, 80\)"):
        XFeatNetwork(wrong)
    (tmp_path / "junk.onnx").write_bytes(b"not a model")
    with pytest.raises(InvalidInput, match="cannot load xfeat model"):
        XFeatNetwork(tmp_path / "junk.onnx")


@pytest.mark.skipif(not REAL.is_file(), reason="the shared XFeat model is not present")
def test_real_backbone_matches_follow_a_known_homography() -> None:
    # Overlapping rectangles of random colours: corners everywhere, as in a room's furniture.
    rng = np.random.default_rng(1)
    image = np.full((480, 640, 3), 128, np.uint8)
    for _ in range(150):
        x, y = rng.integers(0, 600), rng.integers(0, 440)
        w, h = rng.integers(10, 80, 2)
        colour = tuple(int(c) for c in rng.integers(0, 256, 3))
        cv2.rectangle(image, (int(x), int(y)), (int(x + w), int(y + h)), colour, -1)
    image = cv2.GaussianBlur(image, (0, 0), 0.8)
    H = np.array([[0.95, 0.08, 20.0], [-0.06, 0.97, 12.0], [2e-5, -1e-5, 1.0]])
    warped = cv2.warpPerspective(image, H, (640, 480), flags=cv2.INTER_CUBIC)
    net = XFeatNetwork(REAL)
    a, b = net.detect(image), net.detect(warped)
    index, _ = mutual_nearest(a.descriptors, b.descriptors, 0.82)
    assert len(index) > 500
    p = np.c_[a.pixels[index[:, 0]], np.ones(len(index))] @ H.T
    err = np.linalg.norm(p[:, :2] / p[:, 2:] - b.pixels[index[:, 1]], axis=1)
    # XFeat's keypoints come from an 8 x 8-cell head: about 1.4 px median error here (a
    # decoding mistake, e.g. transposed cells, gives 2.7 px and 11 % within 1 px).
    assert np.mean(err < 3.0) > 0.8
    assert np.mean(err < 1.0) > 0.3
    assert np.median(err) < 1.6


@pytest.mark.skipif(not REAL.is_file(), reason="the shared XFeat model is not present")
def test_the_catalogue_entry_is_the_shared_file(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    """The catalogue's size and SHA-256 are the real file's, and the ``xfeat`` features stage
    finds it in the cache by its catalogue name (as after 'monoplane models fetch xfeat')."""
    import shutil

    from monoplane.contracts import FeatureMatcher
    from monoplane.datamodel import Frame, intrinsics_matrix
    from monoplane.host.pipeline import Pipeline
    from monoplane.models import get_model, model_path, require_model
    from monoplane.models.cache import check_file

    monkeypatch.setenv("MONOPLANE_CACHE", str(tmp_path))
    record = get_model("xfeat")
    assert check_file(record, REAL, full=True) is None
    pipe = Pipeline.from_preset("monoplane", ["features.plugin=xfeat"])
    stage = pipe.stage("features", FeatureMatcher)
    frame = Frame(rgb=np.zeros((48, 64, 3), np.uint8), K=intrinsics_matrix(50, 50, 31.5, 23.5),
                  name="blank")
    with pytest.raises(InvalidInput, match="monoplane models fetch xfeat"):
        stage.detect(frame)
    model_path(record).parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(REAL, model_path(record))
    assert require_model("xfeat") == model_path(record)
    assert len(stage.detect(frame)) == 0  # a blank image has no keypoints, but it ran


def test_sift_plus_xfeat_says_what_colmap_maps(tmp_path: Path,
                                               monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture) -> None:
    from monoplane.contracts import FeatureMatcher
    from monoplane.errors import ConfigError
    from monoplane.host.pipeline import Pipeline

    monkeypatch.setenv("MONOPLANE_CACHE", str(tmp_path))  # an empty cache: no XFeat file
    pipe = Pipeline.from_preset("monoplane", ["features.plugin=sift+xfeat"])
    stage = pipe.stage("features", FeatureMatcher)
    assert stage.xfeat is None and stage.sfm_native == "sift"
    assert capsys.readouterr().err == ""  # nothing wanted XFeat yet
    from monoplane.datamodel import Frame, intrinsics_matrix

    frame = Frame(rgb=np.zeros((48, 64, 3), np.uint8), K=intrinsics_matrix(50, 50, 31.5, 23.5))
    stage.detect(frame)
    stage.detect(frame)
    assert capsys.readouterr().err.count("monoplane models fetch xfeat") == 1
    with pytest.raises(ConfigError, match="sfm must be 'sift' or 'both'"):
        Pipeline.from_preset("monoplane", ["features.plugin=sift+xfeat", "features.sfm=all"])
    if REAL.is_file():
        for sfm, native in (("sift", "sift"), ("both", None)):
            pipe = Pipeline.from_preset("monoplane", ["features.plugin=sift+xfeat",
                                                      f"features.model={REAL}",
                                                      f"features.sfm={sfm}"])
            stage = pipe.stage("features", FeatureMatcher)
            assert stage.xfeat is not None and stage.sfm_native == native
