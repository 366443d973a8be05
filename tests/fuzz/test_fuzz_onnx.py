"""The ONNX model loader on truncated, corrupted and mismatched models."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

pytest.importorskip("onnx")

from monoplane.cues import OnnxModel, get_profile  # noqa: E402
from monoplane.cues.tiny_models import tiny_depth_model, tiny_normals_model  # noqa: E402
from monoplane.datamodel import default_intrinsics  # noqa: E402
from monoplane.errors import InvalidInput  # noqa: E402

# Small input boxes keep each inference in the millisecond range.
SPECS = {f"{name}-{kind}": dataclasses.replace(spec, size=(32, 48))
         for name in ("omnidata", "zerodepth", "midas")
         for kind, spec in (("depth", get_profile(name).depth),
                            ("normals", get_profile(name).normals)) if spec is not None}


@pytest.fixture(scope="module")
def good_model(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    path = tiny_depth_model(tmp_path_factory.mktemp("onnx") / "depth.onnx", scale=2.0)
    return path.read_bytes()


def _check_outcome(path: Path, spec_name: str, rgb: np.ndarray) -> None:
    """Load and run; either a one-line error naming the file, or a map of the image's size."""
    spec = SPECS[spec_name]
    try:
        model = OnnxModel(path, spec, threads=1, label="fuzzed model")
        out = model.predict(rgb, default_intrinsics(rgb.shape[1], rgb.shape[0]))
    except InvalidInput as exc:
        msg = str(exc)
        assert "\n" not in msg and str(path) in msg, msg
        return
    expected = rgb.shape[:2] if spec.is_depth else (*rgb.shape[:2], 3)
    assert out.shape == expected and out.dtype == np.float32


_IMAGES = st.tuples(st.integers(1, 40), st.integers(1, 40)).map(
    lambda hw: np.full((*hw, 3), 100, np.uint8))


def test_truncated_or_corrupted_model(fuzz, good_model: bytes, tmp_path: Path) -> None:
    @fuzz
    @given(st.integers(0, len(good_model)), st.lists(st.tuples(st.integers(0, 10**6),
                                                               st.integers(0, 255)), max_size=3),
           st.sampled_from(sorted(SPECS)), _IMAGES)
    def check(cut: int, flips: list[tuple[int, int]], spec_name: str, rgb: np.ndarray) -> None:
        data = bytearray(good_model[:cut])
        for pos, value in flips:
            if data:
                data[pos % len(data)] = value
        path = tmp_path / "model.onnx"
        path.write_bytes(bytes(data))
        _check_outcome(path, spec_name, rgb)

    check()


@st.composite
def mismatched_model(draw: st.DrawFn, folder: Path) -> Path:
    """A tiny network whose signature may or may not fit the spec it is loaded with."""
    path = folder / "model.onnx"
    size = draw(st.one_of(st.none(), st.tuples(st.integers(1, 48), st.integers(1, 48))))
    image_input = draw(st.sampled_from(["image", "rgb", "input"]))
    if draw(st.booleans()):
        return tiny_normals_model(path, draw(st.tuples(*[st.floats(-2, 2)] * 3)),
                                  image_input=image_input,
                                  output_name=draw(st.sampled_from(["normals", "out"])), size=size)
    return tiny_depth_model(
        path, scale=draw(st.floats(-3, 3)), offset=draw(st.floats(-1, 1)),
        image_input=image_input, output_name=draw(st.sampled_from(["depth", "out"])),
        intrinsics_input=draw(st.sampled_from([None, "intrinsics", "K"])),
        fx_coefficient=draw(st.floats(0, 1)), size=size, channels=draw(st.integers(1, 4)),
        squeeze_channel=draw(st.booleans()))


def test_mismatched_model(fuzz, tmp_path: Path) -> None:
    @fuzz
    @given(mismatched_model(tmp_path), st.sampled_from(sorted(SPECS)), _IMAGES)
    def check(path: Path, spec_name: str, rgb: np.ndarray) -> None:
        _check_outcome(path, spec_name, rgb)

    check()
