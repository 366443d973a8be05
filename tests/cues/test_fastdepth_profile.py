"""A real network from configuration alone: FastDepth (../shared/models/fastdepth-224) run by
``monoplane run`` with the profile file printed in docs/cues.md, on the NYU frame of
../shared/data/rgbd-real-frames; the floor must come out as one plane.

Where the floor is comes from the frame's own sensor depth: a plane fitted inside a floor
polygon drawn on the image. Only the RGB image goes to monoplane.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

pytest.importorskip("onnxruntime")

from monoplane.cli import main  # noqa: E402

SHARED = Path(__file__).resolve().parents[3] / "shared"
MODEL = SHARED / "models" / "fastdepth-224" / "fastdepth_224.onnx"
FRAMES = SHARED / "data" / "rgbd-real-frames"
DOCS = Path(__file__).resolve().parents[2] / "docs" / "cues.md"
pytestmark = pytest.mark.skipif(not (MODEL.is_file() and FRAMES.is_dir()),
                                reason=f"FastDepth or the real RGB-D frames not found in {SHARED}")

FX, FY, CX, CY = 525.0, 525.0, 319.5, 239.5
#: Floor seen in the bottom of the NYU image, clear of the pole (left), the box and the chair
#: (right); (u, v) pixels.
FLOOR = np.array([[100, 395], [320, 385], [590, 400], [600, 470], [100, 470]], np.int32)


def documented_profile() -> str:
    """The FastDepth profile exactly as docs/cues.md shows it."""
    blocks = re.findall(r"^```toml\n(.*?)^```", DOCS.read_text(), re.M | re.S)
    found = [b for b in blocks if 'name = "fastdepth-224"' in b]
    assert len(found) == 1, "docs/cues.md must show the FastDepth profile once"
    return found[0]


def nyu_sensor_depth() -> np.ndarray:
    """(480, 640) metres, 0 = invalid (decoding as the frames' README says)."""
    raw = cv2.imread(str(FRAMES / "NYU_depth.pgm"), cv2.IMREAD_UNCHANGED).byteswap()
    d = raw.astype(np.float64)
    return np.where((d > 0) & (d < 1092.5), 351.3 / (1092.5 - np.minimum(d, 1092)), 0.0)


def fit_floor(depth: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit normal (facing the camera) and RMS residual in metres of the plane through the
    sensor points in ``mask``."""
    v, u = np.nonzero(mask)
    z = depth[mask]
    pts = np.stack([(u - CX) / FX * z, (v - CY) / FY * z, z], axis=1)
    centre = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - centre, full_matrices=False)
    n = vt[2] if vt[2] @ centre < 0 else -vt[2]
    return n, float(np.sqrt(np.mean(((pts - centre) @ n) ** 2)))


def test_fastdepth_from_a_profile_file_finds_the_floor(tmp_path: Path) -> None:
    # The profile names its model relative to itself: put both side by side, as docs say.
    (tmp_path / "fastdepth_224.onnx").symlink_to(MODEL)
    profile = tmp_path / "fastdepth-224.toml"
    profile.write_text(documented_profile())
    out = tmp_path / "out"
    code = main(["run", str(FRAMES / "NYU_color.ppm"), "--intrinsics", f"{FX},{FY},{CX},{CY}",
                 "--set", "cues.plugin=onnx", "--set", f"cues.profile={profile}",
                 "--out", str(out), "--quiet"])
    assert code == 0
    doc = json.loads((out / "planes.json").read_text())
    assert doc["depth_kind"] == "metric"
    assert any("fastdepth-224 network fastdepth_224.onnx" in n for n in doc["notes"])

    depth = nyu_sensor_depth()
    mask = np.zeros(depth.shape, np.uint8)
    cv2.fillPoly(mask, [FLOOR], 1)
    floor = mask.astype(bool) & (depth > 0)
    assert floor.sum() > 30_000
    n_floor, rms = fit_floor(depth, floor)
    assert rms < 0.03, "the polygon must hold floor only"
    assert n_floor @ [0, -1, 0] > np.cos(np.radians(40)), "the floor normal points up"

    labels = cv2.imread(str(out / "labels.png"), cv2.IMREAD_UNCHANGED)
    up = [p for p in doc["planes"] if np.dot(p["normal"], n_floor) > np.cos(np.radians(25))]
    assert up, "no plane facing roughly up"
    best = max(up, key=lambda p: p["area_px"])
    coverage = np.mean(labels[floor] == best["id"])
    angle = np.degrees(np.arccos(min(1.0, abs(float(np.dot(best["normal"], n_floor))))))
    # Measured: 99 % and 4.6 degrees.
    assert coverage > 0.8, f"the floor plane covers only {coverage:.0%} of the floor region"
    assert angle < 10.0, f"the floor plane is {angle:.1f} degrees off the sensor's floor"
