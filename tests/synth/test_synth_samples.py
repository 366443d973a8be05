"""On-disk synthetic samples: write_sample round trip and the bundled data_samples/."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from monoplane.synth import generate, write_sample
from monoplane.synth.samples import BUNDLED
from monoplane.synth.writer import write_scene

DATA = Path(__file__).resolve().parents[2] / "data_samples"


def test_write_sample_round_trip(tmp_path: Path) -> None:
    v = generate(1, "mild", 64, 48).views[0]
    write_sample(v, tmp_path / "s")
    d = tmp_path / "s"
    rgb = cv2.cvtColor(cv2.imread(str(d / "rgb.png")), cv2.COLOR_BGR2RGB)
    assert np.array_equal(rgb, v.frame.rgb)
    assert np.array_equal(np.load(d / "depth.npy"), v.frame.depth)
    assert np.array_equal(np.load(d / "gt_depth.npy"), v.gt_depth)
    normals = np.load(d / "normals.npy").astype(np.float32)
    assert np.abs(normals - v.frame.normals).max() < 1e-3
    labels = cv2.imread(str(d / "gt_labels.png"), cv2.IMREAD_UNCHANGED)
    assert labels.dtype == np.uint16 and np.array_equal(labels, v.gt_labels)
    intr = json.loads((d / "intrinsics.json").read_text())
    assert intr == pytest.approx({"fx": v.frame.K[0, 0], "fy": v.frame.K[1, 1],
                                  "cx": v.frame.K[0, 2], "cy": v.frame.K[1, 2]})
    gt = json.loads((d / "gt_planes.json").read_text())
    params = np.array([p["normal"] + [p["offset"]] for p in gt["planes"]])
    assert np.allclose(params, v.gt_params)
    assert [p["id"] for p in gt["planes"]] == list(range(1, len(v.gt_params) + 1))
    assert sum(p["area_px"] for p in gt["planes"]) == int((v.gt_labels > 0).sum())


def test_write_scene_cameras(tmp_path: Path) -> None:
    scene = generate(2, "mild", 64, 48, n_views=2)
    write_scene(scene, tmp_path)
    meta = json.loads((tmp_path / "cameras.json").read_text())
    assert [c["name"] for c in meta["views"]] == ["view0", "view1"]
    for cam, v in zip(meta["views"], scene.views, strict=True):
        assert np.allclose(cam["R"], v.R) and np.allclose(cam["t"], v.t)
        assert np.allclose(cam["K"], v.frame.K)
        assert (tmp_path / cam["name"] / "rgb.png").is_file()
    assert np.allclose(meta["gt_planes_world"], scene.gt_planes_world)
    assert meta["view_to_global"][1] == {str(k): g for k, g in scene.view_to_global[1].items()}


@pytest.mark.skipif(not DATA.is_dir(), reason="data_samples/ not present (installed package)")
def test_bundled_samples_match_generator() -> None:
    """data_samples/ is what `python -m monoplane.synth.samples data_samples` writes."""
    total = sum(f.stat().st_size for f in DATA.rglob("*") if f.is_file())
    assert total < 5e6
    for name, seed, level, width, height, n_views in BUNDLED:
        scene = generate(seed, level, width, height, n_views)
        dirs = [DATA / name] if n_views == 1 else [DATA / name / f"view{i}"
                                                   for i in range(n_views)]
        for d, v in zip(dirs, scene.views, strict=True):
            # Tolerances, not bytes: another CPU may round the ray casts differently.
            assert np.allclose(np.load(d / "gt_depth.npy"), v.gt_depth, rtol=1e-5)
            assert np.allclose(np.load(d / "depth.npy"), v.frame.depth, rtol=1e-4)
            labels = cv2.imread(str(d / "gt_labels.png"), cv2.IMREAD_UNCHANGED)
            assert np.mean(labels == v.gt_labels) > 0.999
        if n_views > 1:
            assert (DATA / name / "cameras.json").is_file()
