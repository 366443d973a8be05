import json
import os
import stat

import cv2
import numpy as np
import pytest

from monoplane.errors import InvalidInput
from monoplane.export.files import atomic_output_dir
from monoplane.io.frames import (
    load_frame,
    read_depth,
    read_intrinsics,
    read_normals,
)


def test_depth_png_uses_scale(tmp_path):
    raw = np.array([[0, 1000], [2500, 65535]], dtype=np.uint16)
    cv2.imwrite(str(tmp_path / "d.png"), raw)
    assert np.allclose(read_depth(tmp_path / "d.png", 1000.0), raw / 1000.0)
    with pytest.raises(InvalidInput, match="--depth-scale"):
        read_depth(tmp_path / "d.png")


def test_nan_depth_rejected_unless_asked(tmp_path):
    d = np.ones((4, 4), np.float32)
    d[0, 0] = np.nan
    np.save(tmp_path / "d.npy", d)
    with pytest.raises(InvalidInput, match=r"d.npy: 1 pixels are NaN or inf"):
        read_depth(tmp_path / "d.npy")
    assert read_depth(tmp_path / "d.npy", nan_as_invalid=True)[0, 0] == 0


def test_normal_png_round_trip(tmp_path):
    n = np.zeros((2, 3, 3))
    n[..., 2] = -1
    n[0, 0] = [0.6, 0, -0.8]
    png = np.round((n + 1) / 2 * 255).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "n.png"), cv2.cvtColor(png, cv2.COLOR_RGB2BGR))
    assert np.allclose(read_normals(tmp_path / "n.png"), n, atol=0.01)


@pytest.mark.parametrize("spec, match", [
    ("1,2,3", "fx,fy,cx,cy"), ("a,b,c,d", "must be numbers"), ("-1,1,0,0", "positive"),
])
def test_bad_intrinsics_strings(spec, match):
    with pytest.raises(InvalidInput, match=match):
        read_intrinsics(spec)


def test_intrinsics_json(tmp_path):
    (tmp_path / "k.json").write_text(json.dumps({"fx": 5, "fy": 6, "cx": 1, "cy": 2}))
    assert read_intrinsics(tmp_path / "k.json")[1, 1] == 6
    (tmp_path / "bad.json").write_text("{fx: 5")
    with pytest.raises(InvalidInput, match="bad.json is not valid JSON"):
        read_intrinsics(tmp_path / "bad.json")
    (tmp_path / "partial.json").write_text('{"fx": 5}')
    with pytest.raises(InvalidInput, match="lacks fy, cx, cy"):
        read_intrinsics(tmp_path / "partial.json")


def test_load_frame_notes_assumed_intrinsics(sample_dir):
    f = load_frame(sample_dir / "rgb.png", depth=sample_dir / "depth.npy")
    assert any("60" in note for note in f.notes)
    assert f.depth.shape == f.shape == (48, 64)


def test_atomic_dir_leaves_nothing_on_failure(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(RuntimeError):
        with atomic_output_dir(out) as tmp:
            (tmp / "labels.png").write_text("x")
            raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "file").write_text("x")
    with pytest.raises(InvalidInput, match="existing file"):
        with atomic_output_dir(tmp_path / "file"):
            pass


def test_atomic_dir_gets_umask_permissions(tmp_path):
    old = os.umask(0o022)
    try:
        with atomic_output_dir(tmp_path / "out") as tmp:
            (tmp / "labels.png").write_text("x")
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "out").stat().st_mode) == 0o755


def test_depth_outside_float32_range(tmp_path):
    np.save(tmp_path / "big.npy", np.array([[1e300, 1.0]]))
    with pytest.raises(InvalidInput, match=r"big.npy has values beyond 3.4e\+38"):
        read_depth(tmp_path / "big.npy")
    np.save(tmp_path / "tiny.npy", np.array([[1e-320, 0.0]]))
    with pytest.raises(InvalidInput, match="no valid pixel"):
        read_depth(tmp_path / "tiny.npy")
