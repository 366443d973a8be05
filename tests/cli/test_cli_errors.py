"""Every bad input gives one line on stderr naming the culprit and a non-zero exit."""

import subprocess
import sys

import numpy as np
import pytest

from monoplane.cli import main


def one_line_error(capsys, argv, code=2):
    assert main(argv) == code
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    assert err.startswith("monoplane: error: "), err
    return err


def test_missing_image(capsys, tmp_path):
    err = one_line_error(capsys, ["run", str(tmp_path / "nope.png"), "--out", str(tmp_path / "o")])
    assert "image file not found" in err and "nope.png" in err
    assert not (tmp_path / "o").exists()


def test_unreadable_image(capsys, tmp_path):
    (tmp_path / "x.png").write_text("not a png")
    err = one_line_error(capsys, ["run", str(tmp_path / "x.png"), "--out", str(tmp_path / "o")])
    assert "cannot read image" in err and "x.png" in err


def test_depth_size_mismatch(capsys, sample_dir):
    np.save(sample_dir / "small.npy", np.ones((10, 10), np.float32))
    err = one_line_error(capsys, ["run", str(sample_dir / "rgb.png"), "--depth",
                                  str(sample_dir / "small.npy"), "--out", str(sample_dir / "o")])
    assert "depth size 10x10 differs from image size 64x48" in err


def test_all_invalid_depth(capsys, sample_dir):
    np.save(sample_dir / "zero.npy", np.zeros((48, 64), np.float32))
    err = one_line_error(capsys, ["run", str(sample_dir / "rgb.png"), "--depth",
                                  str(sample_dir / "zero.npy"), "--out", str(sample_dir / "o")])
    assert "zero.npy has no valid pixel" in err


def test_nan_depth(capsys, sample_dir):
    d = np.load(sample_dir / "depth.npy")
    d[3, 3] = np.inf
    np.save(sample_dir / "inf.npy", d)
    err = one_line_error(capsys, ["run", str(sample_dir / "rgb.png"), "--depth",
                                  str(sample_dir / "inf.npy"), "--out", str(sample_dir / "o")])
    assert "inf.npy" in err and "NaN or inf" in err


def test_wrong_normals_shape(capsys, sample_dir):
    np.save(sample_dir / "n.npy", np.ones((48, 64), np.float32))
    err = one_line_error(capsys, ["run", str(sample_dir / "rgb.png"), "--depth",
                                  str(sample_dir / "depth.npy"), "--normals",
                                  str(sample_dir / "n.npy"), "--out", str(sample_dir / "o")])
    assert "n.npy must have shape (H, W, 3)" in err


@pytest.mark.parametrize("spec", ["1,2", "fx,fy,cx,cy"])
def test_malformed_intrinsics(capsys, sample_dir, spec):
    err = one_line_error(capsys, ["run", str(sample_dir / "rgb.png"), "--depth",
                                  str(sample_dir / "depth.npy"), "--intrinsics", spec,
                                  "--out", str(sample_dir / "o")])
    assert "--intrinsics" in err


def test_malformed_intrinsics_json(capsys, sample_dir):
    (sample_dir / "k.json").write_text("{")
    err = one_line_error(capsys, ["run", str(sample_dir / "rgb.png"), "--intrinsics",
                                  str(sample_dir / "k.json"), "--out", str(sample_dir / "o")])
    assert "k.json is not valid JSON" in err


@pytest.mark.parametrize("extra, match", [
    (["--preset", "nope"], "unknown preset 'nope'; valid presets:"),
    (["--set", "labeler.plugin=nope"], "unknown labeler plugin 'nope'; valid choices:"),
    (["--set", "labeler.lamda=1"], "unknown key 'lamda'"),
])
def test_bad_config(capsys, sample_dir, extra, match):
    err = one_line_error(capsys, ["run", str(sample_dir / "rgb.png"), "--depth",
                                  str(sample_dir / "depth.npy"), "--out",
                                  str(sample_dir / "o"), *extra])
    assert match in err


def test_photo_without_depth_or_model_names_the_next_step(capsys, sample_dir):
    err = one_line_error(capsys, ["run", str(sample_dir / "rgb.png"), "--out",
                                  str(sample_dir / "o")])
    assert "rgb.png has no depth" in err
    assert "--cues NAME --fetch" in err and "monoplane models list" in err
    assert not (sample_dir / "o").exists()


def test_output_folder_exists_names_overwrite(capsys, sample_dir):
    (sample_dir / "o").mkdir()
    (sample_dir / "o" / "labels.png").write_text("x")
    err = one_line_error(capsys, ["run", str(sample_dir / "rgb.png"), "--depth",
                                  str(sample_dir / "depth.npy"), "--out", str(sample_dir / "o")])
    assert "exists and is not empty; pass --overwrite" in err


def test_output_path_is_a_file(capsys, sample_dir):
    (sample_dir / "taken").write_text("x")
    err = one_line_error(capsys, ["run", str(sample_dir / "rgb.png"), "--depth",
                                  str(sample_dir / "depth.npy"), "--out",
                                  str(sample_dir / "taken")])
    assert "taken is an existing file" in err


def test_subprocess_exit_status_and_no_traceback(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "monoplane.cli", "run", str(tmp_path / "a.png"),
                           "--out", str(tmp_path / "o")], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr


def test_help_is_useful(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for cmd in ("run", "multiview", "match", "eval", "bench", "plugins", "presets"):
        assert cmd in out
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = capsys.readouterr().out
    assert "--depth-scale" in out and "--set" in out and "labels.png" in out


@pytest.mark.parametrize("argv,words", [
    (["--depth-only"], "apply to --data only"),
    (["--data", "{tmp}/nope"], "nope"),
    (["--data", "{tmp}", "--sizes", "64x48"], "--sizes applies to synthetic frames"),
    (["--data", "{tmp}", "--batch"], "--data applies to the frame bench"),
])
def test_bench_data_arguments(capsys, tmp_path, argv, words):
    err = one_line_error(capsys, ["bench", "--no-progress",
                                  *[a.format(tmp=tmp_path) for a in argv]])
    assert words in err
