"""16-bit depth in datasets' own encodings (monoplane.io.depth_encodings): each decoder on
hand-made values with known metres, the file readers and manifests that use them, and the
three real frames of ../shared/data/rgbd-real-frames (TUM, SUN RGB-D, NYU v2)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from monoplane.batch import read_frames
from monoplane.cli import main
from monoplane.errors import InvalidInput
from monoplane.evaluation.bench_frames import DataSource, load_data_frames
from monoplane.io.depth_encodings import DEPTH_ENCODINGS, check_depth_encoding, decode_depth
from monoplane.io.frames import load_frame, read_depth
from monoplane.testing import CORNER_PLANES, box_frame

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "rgbd-real-frames"


def test_tum_is_metres_times_5000() -> None:
    raw = np.array([[5000, 12000], [0, 1]], np.uint16)
    np.testing.assert_allclose(decode_depth(raw, "tum", "x"), [[1.0, 2.4], [0.0, 0.0002]])


def test_sun_rotated_undoes_a_left_rotation_by_3_bits() -> None:
    # 2700 mm << 3 = 21600 (no bit wraps); 9870 mm = 0b10_0110_1000_1110: rotated left by 3 its
    # top bit wraps to bit 0, 13424 | 1 = 13425; 1 mm rotated left is 8.
    raw = np.array([[21600, 13425], [0, 8]], np.uint16)
    np.testing.assert_allclose(decode_depth(raw, "sun-rotated", "x"),
                               [[2.7, 9.87], [0.0, 0.001]], rtol=1e-12)


def test_kinect_disparity_in_either_byte_order() -> None:
    d = np.array([[1000, 0], [1092, 2047], [1093, 842]], np.uint16)
    expected = [[351.3 / 92.5, 351.3 / 1092.5], [351.3 / 0.5, 0.0], [0.0, 351.3 / 250.5]]
    np.testing.assert_allclose(decode_depth(d, "kinect-disparity", "x"), expected, rtol=1e-12)
    # NYU's raw PGMs are read byte-swapped: the values exceed 11 bits, swapped back they do not.
    swapped = d.byteswap()
    assert swapped.max() > 2047
    np.testing.assert_allclose(decode_depth(swapped, "kinect-disparity", "x"), expected,
                               rtol=1e-12)
    with pytest.raises(InvalidInput, match="f.pgm: values up to 2056 are not 11-bit"):
        decode_depth(np.array([[0x0808]], np.uint16), "kinect-disparity", "f.pgm")


def test_encodings_are_checked_with_their_choices() -> None:
    assert DEPTH_ENCODINGS == ("scaled", "tum", "sun-rotated", "kinect-disparity")
    with pytest.raises(InvalidInput, match="--depth-encoding: unknown depth encoding 'nyu'; "
                                           "valid encodings: scaled, tum, sun-rotated, "
                                           "kinect-disparity"):
        check_depth_encoding("nyu", None, "--depth-encoding")
    with pytest.raises(InvalidInput, match=r"a depth scale \(1000\) applies to the 'scaled' "
                                           "encoding only; 'tum'"):
        check_depth_encoding("tum", 1000.0, "--depth-encoding")
    check_depth_encoding("scaled", 1000.0, "--depth-encoding")
    with pytest.raises(InvalidInput, match="reads 16-bit integers, got float32"):
        decode_depth(np.ones((2, 2), np.float32), "tum", "x")


def test_read_depth_decodes_png_pgm_and_uint16_npy(tmp_path: Path) -> None:
    mm = np.array([[2700, 0], [1000, 9870]], np.uint16)
    cv2.imwrite(str(tmp_path / "sun.png"), (mm << 3) | (mm >> 13))
    np.testing.assert_allclose(read_depth(tmp_path / "sun.png", depth_encoding="sun-rotated"),
                               mm / 1000.0, rtol=1e-6)
    tum = np.array([[12000, 0], [5000, 2500]], np.uint16)
    cv2.imwrite(str(tmp_path / "tum.png"), tum)
    np.save(tmp_path / "tum.npy", tum)
    for name in ("tum.png", "tum.npy"):
        got = read_depth(tmp_path / name, depth_encoding="tum")
        assert got.dtype == np.float32
        np.testing.assert_allclose(got, [[2.4, 0.0], [1.0, 0.5]], rtol=1e-6)
    # A PGM written the NYU way: the little-endian bytes of the disparity, which a PGM reader
    # takes as big-endian.
    disparity = np.array([[1000, 2047], [842, 900]], np.uint16)
    cv2.imwrite(str(tmp_path / "nyu.pgm"), disparity.byteswap())
    np.testing.assert_allclose(read_depth(tmp_path / "nyu.pgm", depth_encoding="kinect-disparity"),
                               [[351.3 / 92.5, 0.0], [351.3 / 250.5, 351.3 / 192.5]], rtol=1e-6)
    frame = load_frame(depth=tmp_path / "tum.png", depth_encoding="tum")
    assert frame.depth_units == "m"


def test_read_depth_rejects_what_an_encoding_cannot_read(tmp_path: Path) -> None:
    cv2.imwrite(str(tmp_path / "mm.png"), np.full((2, 2), 1000, np.uint16))
    np.save(tmp_path / "metres.npy", np.ones((2, 2), np.float32))
    with pytest.raises(InvalidInput, match="needs --depth-scale .* or --depth-encoding"):
        read_depth(tmp_path / "mm.png")
    with pytest.raises(InvalidInput, match="applies to the 'scaled' encoding only"):
        read_depth(tmp_path / "mm.png", 1000.0, depth_encoding="tum")
    with pytest.raises(InvalidInput, match="unknown depth encoding 'kinect'; valid encodings"):
        read_depth(tmp_path / "mm.png", depth_encoding="kinect")
    with pytest.raises(InvalidInput, match="metres.npy: depth encoding 'tum' reads 16-bit"):
        read_depth(tmp_path / "metres.npy", depth_encoding="tum")
    # The default encoding reads as before: the scale divides.
    np.testing.assert_array_equal(read_depth(tmp_path / "mm.png", 1000.0), np.ones((2, 2)))


def test_manifest_rows_name_their_own_encoding(tmp_path: Path) -> None:
    for name in ("a.png", "b.png", "c.png"):
        cv2.imwrite(str(tmp_path / name), np.full((2, 2), 5000, np.uint16))
    rows = [{"image": "", "depth": "a.png", "depth_encoding": "tum"},
            {"image": "", "depth": "b.png"},
            {"image": "", "depth": "c.png", "depth_encoding": " "}]
    manifest = tmp_path / "frames.jsonl"
    manifest.write_text("".join(json.dumps(r) + "\n" for r in rows))
    specs = read_frames(manifest, depth_scale=1000.0)
    # The row's encoding wins and drops the default scale; the other rows keep the defaults.
    assert [(s.depth_encoding, s.depth_scale) for s in specs] == [
        ("tum", None), ("scaled", 1000.0), ("scaled", 1000.0)]
    frames = load_data_frames(DataSource(str(manifest), depth_scale=1000.0))
    assert [float(f.depth[0, 0]) for f in frames] == [1.0, 5.0, 5.0]
    with pytest.raises(InvalidInput, match="--depth-encoding: a depth scale"):
        read_frames(manifest, depth_scale=1000.0, depth_encoding="tum")
    for row, message in [
            ({"image": "", "depth": "a.png", "depth_encoding": "tumm"},
             "row 1: column 'depth_encoding': unknown depth encoding 'tumm'; valid encodings: "
             "scaled, tum"),
            ({"image": "", "depth": "a.png", "depth_encoding": "tum", "depth_scale": 5000},
             "row 1: a depth scale .* applies to the 'scaled' encoding only"),
            ({"image": "", "depth": "a.png", "depth_encoding": 3},
             "row 1: column 'depth_encoding' must be a name")]:
        manifest.write_text(json.dumps(row) + "\n")
        with pytest.raises(InvalidInput, match=message):
            read_frames(manifest)


def test_run_and_batch_read_an_encoding_as_the_same_depth_in_metres(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    frame, _ = box_frame(64, 48, CORNER_PLANES, focal=50.0)
    tum = np.round(frame.depth * 5000).astype(np.uint16)
    cv2.imwrite(str(tmp_path / "depth.png"), tum)
    np.save(tmp_path / "depth.npy", tum / 5000.0)
    intr = "50,50,31.5,23.5"
    args = ["run", "--intrinsics", intr, "--preset", "seq-ransac", "--quiet", "--out"]
    assert main([*args, str(tmp_path / "npy"), "--depth", str(tmp_path / "depth.npy")]) == 0
    assert main([*args, str(tmp_path / "tum"), "--depth", str(tmp_path / "depth.png"),
                 "--depth-encoding", "tum"]) == 0
    labels = [cv2.imread(str(tmp_path / d / "labels.png"), cv2.IMREAD_UNCHANGED)
              for d in ("npy", "tum")]
    assert labels[0].max() >= 2
    np.testing.assert_array_equal(labels[0], labels[1])
    (tmp_path / "frames.jsonl").write_text(json.dumps(
        {"name": "f", "image": "", "depth": "depth.png", "intrinsics": intr}) + "\n")
    assert main(["batch", str(tmp_path / "frames.jsonl"), "--out", str(tmp_path / "batch"),
                 "--depth-encoding", "tum", "--preset", "seq-ransac", "--workers", "1",
                 "--quiet"]) == 0
    np.testing.assert_array_equal(
        cv2.imread(str(tmp_path / "batch" / "f" / "labels.png"), cv2.IMREAD_UNCHANGED),
        labels[0])
    with pytest.raises(SystemExit):
        main([*args, str(tmp_path / "x"), "--depth", str(tmp_path / "depth.png"),
              "--depth-encoding", "nyu"])
    err = capsys.readouterr().err
    assert "--depth-encoding: invalid choice: 'nyu' (choose from" in err
    assert all(name in err.partition("choose from")[2] for name in DEPTH_ENCODINGS)


def test_bench_takes_the_encoding_with_data_only(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--depth-encoding", "tum", "--no-progress"]) == 2
    assert "--depth-encoding, --intrinsics and --depth-only apply to --data only" in \
        capsys.readouterr().err


real = pytest.mark.skipif(not REAL.is_dir(), reason=f"real RGB-D frames not found at {REAL}")


@real
def test_the_three_real_frames_read_in_their_own_encodings(tmp_path: Path) -> None:
    """Median depth as the frames' README gives it (TUM 2.4 m, SUN 2.7 m, NYU 3.3 m) and the
    valid fraction (NYU 93 %; TUM and SUN as measured: 80.8 % and 81.8 %), through a manifest
    that lists the three frames with each row's encoding, as ``bench --data`` reads it."""
    rows = [("TUM", "TUM_color.png", "TUM_depth.png", "tum", 2.4, 0.808),
            ("SUN", "SUN_color.jpg", "SUN_depth.png", "sun-rotated", 2.7, 0.818),
            ("NYU", "NYU_color.ppm", "NYU_depth.pgm", "kinect-disparity", 3.3, 0.93)]
    manifest = tmp_path / "real.jsonl"
    manifest.write_text("".join(json.dumps(
        {"name": name, "image": str(REAL / colour), "depth": str(REAL / depth),
         "depth_encoding": encoding}) + "\n" for name, colour, depth, encoding, *_ in rows))
    frames = load_data_frames(DataSource(str(manifest), intrinsics="525,525,319.5,239.5",
                                         depth_only=True))
    assert [f.name for f in frames] == ["TUM", "SUN", "NYU"]
    for frame, (name, *_, median, valid) in zip(frames, rows, strict=True):
        assert frame.rgb is None and frame.depth.shape == (480, 640) and frame.depth_units == "m"
        good = frame.depth > 0
        assert abs(float(np.median(frame.depth[good])) - median) < 0.05, name
        assert abs(float(good.mean()) - valid) < 0.01, name
        assert float(frame.depth.max()) < 10.0, f"{name}: indoor depth beyond 10 m"
