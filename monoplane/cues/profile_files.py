"""Cue profiles declared in TOML: any ONNX depth or normals network from configuration alone.

A profile table describes one network (``[model]``) and optionally a second network for
normals (``[normals_model]``); each says how to feed its image input (``input``) and what its
outputs mean (``depth``, ``normals``). The same tables come from a profile file
(``cues.profile = "my_model.toml"``) or inline in a config (``[cues.custom]`` with
``cues.profile = "custom"``). Every key is checked; a bad key or value is one
:class:`~monoplane.errors.ConfigError` naming the file and the table. Checking the tables
against the model file itself happens when the model loads
(:class:`~monoplane.cues.session.OnnxModel`).

The built-in profiles are such files too (``builtin_profiles/*.toml``); :func:`profile_to_table`
writes any profile as these tables (what ``monoplane models profile NAME`` prints).

Example (the FastDepth export described in ``docs/cues.md``)::

    name = "fastdepth-224"
    [model]
    file = "fastdepth_224.onnx"          # relative to this file
    [model.input]
    name = "input_nhwc"
    layout = "NHWC"
    size = [224, 224]
    resize = "stretch"
    [model.depth]
    name = "depth"
    kind = "metric_depth"
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Literal

from monoplane.contracts import param
from monoplane.contracts.config_fields import build_dataclass
from monoplane.cues.profiles import ModelSpec, OnnxProfile
from monoplane.errors import ConfigError

#: ``cues.profile`` value that selects the inline ``[cues.custom]`` table.
CUSTOM_PROFILE = "custom"


@dataclass
class InputTable:
    """``[model.input]``: how an image becomes the network's input tensor."""

    name: str = param("", "name of the image input (empty: the model's only image input)")
    layout: Literal["NCHW", "NHWC"] = param(
        "NCHW", "axis order: NCHW (channels first) or NHWC (channels last, TensorFlow/TFLite)")
    colour_order: Literal["RGB", "BGR"] = param("RGB", "channel order the network expects")
    size: list[int] = param(
        [384, 384], "[height, width] input box in pixels (a model with fixed spatial "
                    "dimensions is always fed exactly its own size)")
    multiple_of: int = param(32, "padded or stretched sides are multiples of this")
    resize: Literal["keep_aspect", "stretch"] = param(
        "keep_aspect", "keep_aspect: fit the box and pad bottom/right; stretch: resize to the "
                       "box, ignoring the aspect ratio")
    value_range: list[float] = param(
        [0.0, 1.0], "[low, high] onto which pixel values 0..255 are mapped linearly")
    mean: list[float] = param([0.0, 0.0, 0.0], "per-channel mean subtracted after scaling")
    std: list[float] = param([1.0, 1.0, 1.0], "per-channel std divided by after the mean")
    intrinsics: str = param(
        "", "name of a (N, 3, 3) float32 intrinsics input (camera-aware networks), rescaled "
            "to the input resolution")
    constants: dict[str, int] = param(
        {}, "further integer scalar inputs and their fixed values, e.g. {num_tokens = 1800}")


@dataclass
class DepthTable:
    """``[model.depth]``: the depth-like output and what it means."""

    kind: Literal["metric_depth", "relative_depth", "inverse_depth", "point_map"] = param(
        "metric_depth", "metric_depth (metres x depth_scale), relative_depth (affine-invariant, "
                        "shift assumed 0), inverse_depth (disparity), point_map (MoGe)")
    name: str = param("", "output name (empty: the model's first output)")
    depth_scale: float = param(1.0, "metric_depth: factor to metres (0.001 for millimetres)")
    canonical_focal: float = param(
        0.0, "metric_depth: depth is for this focal length in pixels and is rescaled by "
             "fx / canonical_focal (Metric3D; 0: off)")
    mask: str = param("", "point_map: name of a (N, H, W) validity-probability output")
    metric_scale: str = param("", "point_map: name of a (N,) metric-scale output")


@dataclass
class NormalsTable:
    """``[model.normals]`` / ``[normals_model.normals]``: a normal-map output."""

    name: str = param("", "output name (empty: the model's first output)")
    encoding: Literal["signed", "unsigned"] = param(
        "signed", "signed: components in [-1, 1]; unsigned: (n + 1) / 2 in [0, 1]")
    axes: str = param(
        "x,y,z", "model axes (with signs) that become OpenCV camera x (right), y (down), "
                 "z (forward); 'x,y,-z' for Omnidata, 'x,-y,-z' for OpenGL")


@dataclass
class NetworkTable:
    """``[model]`` / ``[normals_model]``: one ONNX file and its sub-tables."""

    file: str = param("", "the .onnx file, relative to the profile file (cues.depth_model / "
                          "cues.normal_model override it)")
    input: dict[str, Any] = param({}, "the image input, see InputTable")
    depth: dict[str, Any] = param({}, "the depth output, see DepthTable")
    normals: dict[str, Any] = param({}, "a normals output, see NormalsTable")


@dataclass
class ProfileTable:
    """The top level of a profile file."""

    name: str = param("", "profile name used in messages and notes (default: the file name)")
    summary: str = param("", "one line for listings")
    hfov_deg: float = param(
        0.0, "horizontal field of view to assume for images without intrinsics (0: 60)")
    model: dict[str, Any] = param({}, "the depth network (required)")
    normals_model: dict[str, Any] = param({}, "a second network that predicts normals")


@dataclass(frozen=True)
class DeclaredProfile:
    """A profile read from TOML tables, with the model files they name.

    Attributes
    ----------
    profile : OnnxProfile
        The networks' description.
    depth_model, normal_model : pathlib.Path or None
        ``file`` of ``[model]`` and ``[normals_model]``, resolved against the profile file's
        folder; ``None`` when not given.
    """

    profile: OnnxProfile
    depth_model: Path | None = None
    normal_model: Path | None = None


def is_profile_file(value: str) -> bool:
    """Whether a ``cues.profile`` value names a profile file rather than a built-in profile."""
    return value.lower().endswith(".toml")


def _spec(net: NetworkTable, where: str, *, normals_network: bool) -> ModelSpec:
    """The :class:`ModelSpec` of one network table."""
    inp = build_dataclass(InputTable, net.input, f"{where}.input")
    for key, n in (("size", 2), ("value_range", 2), ("mean", 3), ("std", 3)):
        if len(getattr(inp, key)) != n:
            raise ConfigError(f"{where}.input.{key} needs {n} values, got {getattr(inp, key)}")
    normals = (build_dataclass(NormalsTable, net.normals, f"{where}.normals")
               if net.normals else None)
    common: dict[str, Any] = dict(
        size=(inp.size[0], inp.size[1]), resize=inp.resize, multiple_of=inp.multiple_of,
        layout=inp.layout, colour_order=inp.colour_order,
        value_range=(inp.value_range[0], inp.value_range[1]), mean=tuple(inp.mean),
        std=tuple(inp.std), image_input=inp.name or None,
        intrinsics_input=inp.intrinsics or None,
        constant_inputs=tuple(sorted(inp.constants.items())))
    if normals is not None:
        common.update(normal_encoding=normals.encoding, normal_axes=normals.axes)
    if normals_network:
        if net.depth:
            raise ConfigError(f"{where}: a normals network has no [depth] output table; put "
                              f"a joint network's depth and normals under [model]")
        if normals is None:
            raise ConfigError(f"{where} needs a [{where}.normals] table naming its output")
        return ModelSpec(output="normals", output_name=normals.name or None, **common)
    if not net.depth:
        raise ConfigError(f"{where} needs a [{where}.depth] table: the output's name and kind")
    depth = build_dataclass(DepthTable, net.depth, f"{where}.depth")
    if normals is not None and not normals.name:
        raise ConfigError(f"{where}.normals needs a name: the normals output of the depth "
                          f"network")
    return ModelSpec(
        output=depth.kind, output_name=depth.name or None, depth_scale=depth.depth_scale,
        canonical_focal=depth.canonical_focal or None, mask_output=depth.mask or None,
        scale_output=depth.metric_scale or None,
        normals_output=normals.name if normals is not None else None, **common)


def profile_from_table(table: dict[str, Any], where: str, *,
                       base_dir: Path | None = None, default_name: str = "custom"
                       ) -> DeclaredProfile:
    """Build a profile from TOML tables.

    Parameters
    ----------
    table : dict
        The tables of a profile file (see the module docstring and ``docs/cues.md``).
    where : str
        Where they came from, the prefix of every error message.
    base_dir : pathlib.Path, optional
        Folder that relative ``file`` paths are relative to (the profile file's folder);
        ``None`` leaves them relative to the working directory.
    default_name : str
        Profile name when the tables give none.

    Raises
    ------
    ConfigError
        One line naming ``where`` and the table at fault.
    """
    top = build_dataclass(ProfileTable, table, where)
    if not top.model:
        raise ConfigError(f"{where} needs a [model] table: the depth network's input and "
                          f"outputs (see docs/cues.md, 'Your own model')")

    def network(key: str, values: dict[str, Any]) -> tuple[ModelSpec, Path | None]:
        try:
            net = build_dataclass(NetworkTable, values, key)
            spec = _spec(net, key, normals_network=key == "normals_model")
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        path = Path(net.file).expanduser() if net.file else None
        if path is not None and base_dir is not None and not path.is_absolute():
            path = base_dir / path
        return spec, path

    depth, depth_path = network("model", top.model)
    normals, normal_path = (network("normals_model", top.normals_model) if top.normals_model
                            else (None, None))
    if top.hfov_deg < 0 or top.hfov_deg >= 180:
        raise ConfigError(f"{where}: hfov_deg must be in [0, 180), got {top.hfov_deg}")
    try:
        profile = OnnxProfile(name=top.name or default_name, depth=depth, normals=normals,
                              hfov_deg=top.hfov_deg or None, summary=top.summary)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None
    return DeclaredProfile(profile, depth_path, normal_path)


def load_profile_file(path: str | Path) -> DeclaredProfile:
    """Read a profile file; model ``file`` paths are relative to its folder.

    Raises
    ------
    ConfigError
        When the file is missing, is not TOML, or its tables are invalid (one line naming it).
    """
    p = Path(path).expanduser()
    if not p.is_file():
        raise ConfigError(f"cue profile file not found: {p} (expected a TOML file with a "
                          f"[model] table, see docs/cues.md)")
    try:
        table = tomllib.loads(p.read_text())
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{p}: invalid TOML: {exc}") from None
    except OSError as exc:
        raise ConfigError(f"cannot read cue profile file {p}: {exc.strerror}") from None
    return profile_from_table(table, str(p), base_dir=p.parent, default_name=p.stem)


def load_builtin_profiles() -> dict[str, OnnxProfile]:
    """The profiles shipped in ``monoplane/cues/builtin_profiles/*.toml``, by name.

    Raises
    ------
    ConfigError
        When a shipped file is invalid or its ``name`` is not its file name.
    """
    folder = resources.files(__package__) / "builtin_profiles"
    profiles = {}
    for entry in sorted(folder.iterdir(), key=lambda e: e.name):
        if not entry.name.endswith(".toml"):
            continue
        stem, where = entry.name[:-5], f"built-in profile {entry.name}"
        profile = profile_from_table(tomllib.loads(entry.read_text("utf-8")), where,
                                     default_name=stem).profile
        if profile.name != stem:
            raise ConfigError(f"{where}: name {profile.name!r} is not the file name")
        profiles[stem] = profile
    return profiles


#: Profiles shipped with monoplane, by name.
BUILTIN_PROFILES: dict[str, OnnxProfile] = load_builtin_profiles()


def get_profile(name: str) -> OnnxProfile:
    """Look up a built-in profile; unknown names raise :class:`ConfigError` listing the valid."""
    try:
        return BUILTIN_PROFILES[name]
    except KeyError:
        raise ConfigError(
            f"unknown cue profile {name!r}; valid profiles: {', '.join(sorted(BUILTIN_PROFILES))}"
            f", or a profile file ending in .toml (see docs/cues.md)"
        ) from None


def _network_table(spec: ModelSpec) -> dict[str, Any]:
    inp: dict[str, Any] = {"name": spec.image_input} if spec.image_input else {}
    inp |= {
        "layout": spec.layout, "colour_order": spec.colour_order, "size": list(spec.size),
        "multiple_of": spec.multiple_of, "resize": spec.resize,
        "value_range": list(spec.value_range), "mean": list(spec.mean), "std": list(spec.std)}
    if spec.intrinsics_input:
        inp["intrinsics"] = spec.intrinsics_input
    if spec.constant_inputs:
        inp["constants"] = dict(spec.constant_inputs)
    out: dict[str, Any] = {"input": inp}
    normals = {"encoding": spec.normal_encoding, "axes": spec.normal_axes}
    if not spec.is_depth:
        out["normals"] = {**({"name": spec.output_name} if spec.output_name else {}), **normals}
        return out
    depth: dict[str, Any] = {"kind": spec.output}
    for key, value in (("name", spec.output_name), ("mask", spec.mask_output),
                       ("metric_scale", spec.scale_output)):
        if value:
            depth[key] = value
    if spec.depth_scale != 1.0:
        depth["depth_scale"] = spec.depth_scale
    if spec.canonical_focal:
        depth["canonical_focal"] = spec.canonical_focal
    out["depth"] = depth
    if spec.normals_output:
        out["normals"] = {"name": spec.normals_output, **normals}
    return out


def profile_to_table(profile: OnnxProfile) -> dict[str, Any]:
    """Any profile as the TOML tables :func:`profile_from_table` reads (no ``file`` keys).

    Every key is written out, defaults included, so that the result documents the profile in
    full and reads back to an equal :class:`OnnxProfile`.
    """
    table: dict[str, Any] = {"name": profile.name}
    if profile.summary:
        table["summary"] = profile.summary
    if profile.hfov_deg:
        table["hfov_deg"] = profile.hfov_deg
    table["model"] = _network_table(profile.depth)
    if profile.normals is not None:
        table["normals_model"] = _network_table(profile.normals)
    return table



def _toml_value(value: Any) -> str:
    """One TOML value on one line: strings, booleans, numbers, flat lists, inline tables."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)  # a JSON string is a valid TOML basic string
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + "}"
    return "[" + ", ".join(_toml_value(v) for v in value) + "]"


def profile_to_toml(profile: OnnxProfile) -> str:
    """:func:`profile_to_table` as a profile file's text, one key a line, tables in order."""
    table = profile_to_table(profile)
    lines = [f"{k} = {_toml_value(v)}" for k, v in table.items() if not isinstance(v, dict)]
    for net in ("model", "normals_model"):
        if net not in table:
            continue
        lines += ["", f"[{net}]", '# file = "path/to/model.onnx"   # relative to this file']
        for sub, values in table[net].items():
            lines += ["", f"[{net}.{sub}]"]
            lines += [f"{k} = {_toml_value(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"
