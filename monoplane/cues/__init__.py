"""Cue machinery shared by cue providers: ONNX model profiles, sessions, pre/post-processing
and intrinsics handling.

This is public API for third-party cue plugins. A plugin that wraps another monocular network
declares a :class:`ModelSpec` / :class:`OnnxProfile` and lets a :class:`CueNetwork` do the
loading, letterboxing, inference and conversion::

    from monoplane.cues import CueNetwork, ModelSpec, OnnxProfile

    PROFILE = OnnxProfile(name="my-net", depth=ModelSpec(output="inverse_depth",
                                                         size=(518, 518), multiple_of=14))
    frame = CueNetwork(PROFILE, depth_model="my-net.onnx").provide(frame)

A profile can also be declared in TOML, with no Python at all (:mod:`monoplane.cues.profile_files`,
``cues.profile = "my_model.toml"``). See ``docs/cues.md`` for profile files and for exporting
networks to ONNX.
"""

from monoplane.cues.intrinsics import (
    ASSUMED_INTRINSICS_NOTE,
    DEFAULT_HFOV_DEG,
    assume_intrinsics,
    intrinsics_assumed,
    reassume_intrinsics,
)
from monoplane.cues.network import CueNetwork
from monoplane.cues.profile_files import (
    BUILTIN_PROFILES,
    DeclaredProfile,
    get_profile,
    load_profile_file,
    profile_from_table,
    profile_to_toml,
)
from monoplane.cues.profiles import (
    IMAGENET_MEAN,
    IMAGENET_STD,
    OUTPUT_KINDS,
    ModelSpec,
    OnnxProfile,
    parse_axes,
)
from monoplane.cues.session import OnnxModel
from monoplane.cues.transforms import (
    Letterbox,
    decode_normals,
    depth_from_disparity,
    face_camera,
    plan_letterbox,
    prepare_image,
    relative_depth_from_depth,
    restore_map,
    scaled_intrinsics,
)
from monoplane.deprecation import renamed_names

__all__ = [
    "ASSUMED_INTRINSICS_NOTE", "BUILTIN_PROFILES", "CueNetwork", "DEFAULT_HFOV_DEG",
    "DeclaredProfile", "load_profile_file", "profile_from_table", "profile_to_toml",
    "IMAGENET_MEAN", "IMAGENET_STD", "Letterbox", "ModelSpec", "OUTPUT_KINDS", "OnnxModel",
    "OnnxProfile", "assume_intrinsics", "decode_normals", "depth_from_disparity",
    "face_camera", "get_profile", "intrinsics_assumed", "parse_axes", "plan_letterbox",
    "prepare_image", "reassume_intrinsics", "relative_depth_from_depth", "restore_map",
    "scaled_intrinsics",
]


# The old name of face_camera (monoplane.geometry.orientation.orient_normals is another).
__getattr__ = renamed_names(__name__, {"orient_normals": "monoplane.cues.transforms:face_camera"})
