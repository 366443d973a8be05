"""Built-in ONNX profiles and overrides."""

from __future__ import annotations

import pytest

from monoplane.cues import BUILTIN_PROFILES, ModelSpec, OnnxProfile, get_profile
from monoplane.errors import ConfigError


def test_builtin_profiles_and_their_outputs() -> None:
    assert set(BUILTIN_PROFILES) == {"omnidata", "zerodepth", "midas", "depth-anything-v2",
                                     "metric3d-v2", "moge-2"}
    omni = get_profile("omnidata")
    assert omni.depth.output == "relative_depth"
    assert omni.normals is not None and omni.normals.normal_encoding == "unsigned"
    zero = get_profile("zerodepth")
    assert zero.depth.output == "metric_depth" and zero.depth.intrinsics_input == "intrinsics"
    assert get_profile("midas").depth.output == "inverse_depth"
    assert get_profile("midas").normals is None
    assert get_profile("depth-anything-v2").task == "depth"
    m3d = get_profile("metric3d-v2").depth
    assert m3d.canonical_focal == 1000.0 and m3d.normals_output == "predicted_normal"
    moge = get_profile("moge-2").depth
    assert moge.output == "point_map" and moge.constant_inputs == (("num_tokens", 1800),)
    assert get_profile("moge-2").task == get_profile("metric3d-v2").task == "both"


def test_joint_normals_and_a_normals_network_exclude_each_other() -> None:
    joint = ModelSpec(output="metric_depth", normals_output="normals")
    with pytest.raises(ConfigError, match="not both"):
        OnnxProfile(name="x", depth=joint, normals=ModelSpec(output="normals"))
    with pytest.raises(ConfigError, match="canonical_focal"):
        ModelSpec(output="inverse_depth", canonical_focal=1000.0)


def test_unknown_profile_lists_valid_ones() -> None:
    with pytest.raises(ConfigError, match="midas, moge-2, omnidata, zerodepth"):
        get_profile("dpt")


def test_overrides_apply_to_both_networks() -> None:
    p = get_profile("omnidata").with_overrides(size=(256, 320), mean=(0.1, 0.2, 0.3),
                                               normal_axes="x,-y,-z")
    assert p.depth.size == (256, 320) and p.normals.size == (256, 320)
    assert p.depth.mean == (0.1, 0.2, 0.3)
    assert p.normals.normal_axes == "x,-y,-z"
    assert p.depth.std == get_profile("omnidata").depth.std


@pytest.mark.parametrize("kwargs", [
    {"output": "disparity"}, {"output": "metric_depth", "resize": "crop"},
    {"output": "metric_depth", "size": (0, 10)}, {"output": "metric_depth", "std": (1, 0, 1)},
    {"output": "normals", "normal_encoding": "rgb"}, {"output": "normals", "normal_axes": "x"},
])
def test_bad_specs_are_config_errors(kwargs: dict) -> None:
    with pytest.raises(ConfigError):
        ModelSpec(**kwargs)


def test_profile_checks_roles() -> None:
    depth = ModelSpec(output="metric_depth")
    with pytest.raises(ConfigError, match="depth model"):
        OnnxProfile(name="x", depth=ModelSpec(output="normals"))
    with pytest.raises(ConfigError, match="normals model"):
        OnnxProfile(name="x", depth=depth, normals=depth)
