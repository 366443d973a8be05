"""Every catalogue model, run end to end through ``monoplane run --cues NAME``.

The real weights are not downloaded. For each entry a tiny ONNX stand-in with the real export's
input and output names, ranks and value ranges is built, placed in a temporary cache
(``MONOPLANE_CACHE``) under the entry's file name, and the entry's size and SHA-256 are set to
the stand-in's, so the cache's own checks pass. The stand-ins compute exact geometry from the
image (a test encodes depth or points in the pixel values), so the planes that come out of the
whole pipeline are compared with closed-form answers.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from monoplane.cli import main
from monoplane.cues import IMAGENET_MEAN, IMAGENET_STD, get_profile, plan_letterbox
from monoplane.cues.tiny_models import tiny_depth_model, tiny_joint_model, tiny_point_map_model
from monoplane.datamodel import default_intrinsics, pixel_rays
from monoplane.models import CATALOGUE, model_path, sha256_of
from monoplane.testing import BOX_PLANES, box_frame

pytest.importorskip("onnx")

W, H = 128, 96
#: A tilted plane (camera frame, OpenCV axes) filling the view, facing the camera.
TILTED = np.array([0.25, -0.8, -0.55])
TILTED_N = TILTED / np.linalg.norm(TILTED)
TILTED_D = 2.0


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = tmp_path / "cache"
    monkeypatch.setenv("MONOPLANE_CACHE", str(root))
    return root


def install_stand_in(name: str, build, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Build a stand-in at the entry's cache path; make the entry describe it."""
    path = model_path(CATALOGUE[name])
    path.parent.mkdir(parents=True, exist_ok=True)
    build(path)
    monkeypatch.setitem(CATALOGUE, name, dataclasses.replace(
        CATALOGUE[name], size=path.stat().st_size, sha256=sha256_of(path)))
    return path


def write_rgb(path: Path, rgb: np.ndarray) -> Path:
    cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    return path


def run(image: Path, name: str, out: Path) -> dict:
    assert main(["run", str(image), "--cues", name, "--out", str(out), "--quiet"]) == 0
    return json.loads((out / "planes.json").read_text())


def angle_deg(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.degrees(np.arccos(np.clip(abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b),
                                              -1, 1))))


def tilted_depth(K: np.ndarray) -> np.ndarray:
    return -TILTED_D / (pixel_rays(K, H, W) @ TILTED_N)


def test_depth_anything_v2_small(cache: Path, tmp_path: Path,
                                 monkeypatch: pytest.MonkeyPatch) -> None:
    # Relative inverse depth (pixel_values -> predicted_depth (N, H, W)), ImageNet-normalised
    # input. The image holds the box room's disparity; the stand-in returns it exactly.
    k1 = float(np.mean(1 / np.asarray(IMAGENET_STD)))
    k0 = float(np.mean(np.asarray(IMAGENET_MEAN) / np.asarray(IMAGENET_STD)))
    install_stand_in("depth-anything-v2-small", lambda p: tiny_depth_model(
        p, scale=255 / k1, offset=255 * k0 / k1, image_input="pixel_values",
        output_name="predicted_depth", squeeze_channel=True), monkeypatch)
    K = default_intrinsics(W, H)  # what a photo without intrinsics is assumed to have
    frame, _ = box_frame(W, H, focal=K[0, 0])
    disparity = 250 * frame.depth.min() / frame.depth
    image = write_rgb(tmp_path / "room.png",
                      np.repeat(np.round(disparity).astype(np.uint8)[..., None], 3, axis=2))
    doc = run(image, "depth-anything-v2-small", tmp_path / "out")
    assert doc["depth_kind"] == "relative"
    found = [p["normal"] for p in doc["planes"]]
    for plane in BOX_PLANES:
        assert min(angle_deg(plane[:3], n) for n in found) < 3.0
    assert any("depth-anything-v2" in note for note in doc["notes"])


def test_metric3d_v2_small(cache: Path, tmp_path: Path,
                           monkeypatch: pytest.MonkeyPatch) -> None:
    # pixel_values holds raw 0-255 RGB; predicted_depth is depth for a 1000 px focal length at
    # the input resolution; predicted_normal (N, 3, H, W) unit normals in OpenCV axes.
    K = default_intrinsics(W, H)
    spec = get_profile("metric3d-v2").depth
    box = plan_letterbox(H, W, spec)
    fx_net = K[0, 0] * box.resized[1] / W
    z = tilted_depth(K)
    # raw = 1 / (c * I) and depth = raw * fx_net / 1000, so I = fx_net / (1000 c z).
    c = fx_net / (1000 * 250 * z.min())
    install_stand_in("metric3d-v2-small", lambda p: tiny_joint_model(
        p, tuple(TILTED_N), scale=c, reciprocal=True), monkeypatch)
    value = np.round(fx_net / (1000 * c * z)).astype(np.uint8)
    image = write_rgb(tmp_path / "plane.png", np.repeat(value[..., None], 3, axis=2))
    doc = run(image, "metric3d-v2-small", tmp_path / "out")
    assert doc["depth_kind"] == "metric" and doc["depth_units"] == "m"
    best = max(doc["planes"], key=lambda p: p["area_px"])
    assert best["area_px"] > 0.8 * W * H
    assert angle_deg(best["normal"], TILTED_N) < 1.0
    assert best["offset"] == pytest.approx(TILTED_D, rel=0.01)
    assert any("fx / 1000" in note for note in doc["notes"])


def test_moge_2_vits_normal(cache: Path, tmp_path: Path,
                            monkeypatch: pytest.MonkeyPatch) -> None:
    # image in [0, 1] and num_tokens in; points (affine, OpenCV axes), normal, mask and
    # metric_scale out. The camera has a 50° field of view, not the 60° a photo without
    # intrinsics is assumed to have: the network's point map must replace the guess.
    K = default_intrinsics(W, H, hfov_deg=50.0)
    z = tilted_depth(K)
    points = pixel_rays(K, H, W) * z[..., None]
    scale, shift = 2.0, 0.5
    affine = points / scale
    affine[..., 2] -= shift
    low, high = affine.reshape(-1, 3).min(0) - 0.01, affine.reshape(-1, 3).max(0) + 0.01
    install_stand_in("moge-2-vits-normal", lambda p: tiny_point_map_model(
        p, tuple(low), tuple(high), tuple(TILTED_N), metric_scale=scale), monkeypatch)
    rgb = np.round((affine - low) / (high - low) * 255).astype(np.uint8)
    image = write_rgb(tmp_path / "plane.png", rgb)
    doc = run(image, "moge-2-vits-normal", tmp_path / "out")
    assert doc["depth_kind"] == "metric"
    assert doc["intrinsics"]["fx"] == pytest.approx(K[0, 0], rel=0.01)
    assert any("estimated from the moge-2 network" in note for note in doc["notes"])
    best = max(doc["planes"], key=lambda p: p["area_px"])
    assert best["area_px"] > 0.8 * W * H
    assert angle_deg(best["normal"], TILTED_N) < 1.0
    assert best["offset"] == pytest.approx(TILTED_D, rel=0.01)


def test_every_catalogue_entry_has_an_end_to_end_test() -> None:
    # xfeat: tests/features/test_xfeat.py::test_the_catalogue_entry_is_the_shared_file
    tested = {"depth-anything-v2-small", "metric3d-v2-small", "moge-2-vits-normal", "xfeat"}
    assert set(CATALOGUE) == tested
