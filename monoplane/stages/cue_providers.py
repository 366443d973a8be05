"""Cue providers: where a frame's depth and normals come from.

* ``given``: depth (and optionally normals) supplied by the user, e.g. an RGB-D frame; missing
  normals are estimated from depth with edge-aware fits
  (:func:`monoplane.geometry.normals.normals_from_depth`).
* ``onnx``: monocular networks run with onnxruntime on the CPU, described by a profile
  (see :mod:`monoplane.cues.profiles` and :mod:`monoplane.cues.profile_files`). Either name
  a catalogue model, fetched once with ``monoplane models fetch NAME`` (see
  :mod:`monoplane.models`)::

      [cues]
      plugin = "onnx"
      model = "depth-anything-v2-small"

  or bring your own export and choose its profile::

      [cues]
      plugin = "onnx"
      profile = "omnidata"
      depth_model = "models/omnidata_dpt_depth.onnx"
      normal_model = "models/omnidata_dpt_normal.onnx"

  or describe any ONNX network in a profile file (see :mod:`monoplane.cues.profile_files`)::

      [cues]
      plugin = "onnx"
      profile = "models/fastdepth-224.toml"

Both keep cues the user already gave, orient normals towards the camera and record what they
did in ``frame.notes`` (written to ``planes.json``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from monoplane.contracts import CueProvider, NetworkCues, Stage, param
from monoplane.cues.given import use_given_cues
from monoplane.cues.network import CueNetwork
from monoplane.cues.profile_files import (
    BUILTIN_PROFILES,
    CUSTOM_PROFILE,
    DeclaredProfile,
    get_profile,
    is_profile_file,
    load_profile_file,
    profile_from_table,
)
from monoplane.cues.profiles import OnnxProfile
from monoplane.datamodel import Frame
from monoplane.errors import ConfigError, InvalidInput
from monoplane.geometry.normals import (
    DEFAULT_NORMALS_METHOD,
    NORMALS_CHOICES,
    cue_normals_from_depth,
)
from monoplane.hookspecs import hookimpl
from monoplane.models import get_model, require_model


@dataclass
class NormalsFromDepthOptions:
    """Options of the normals-from-depth estimator, shared by every cue provider that uses it."""

    normals_radius: int = param(
        0, "half-size in pixels of the window that estimates normals from depth "
           "(0: about 1 % of the longer image side)")
    normals_stride: int = param(
        0, "spacing in pixels of the samples in that window, larger = wider at the same cost "
           "(0: automatic)")
    max_jump: float = param(
        0.05, "relative depth jump between neighbouring pixels that marks a depth edge")
    normals_method: str = param(
        DEFAULT_NORMALS_METHOD,
        "how normals are fitted: 'gated' (per-sample gating near edges), 'box' (window sums; "
        "faster) or 'auto' ('box' on a sensor's metric depth, 'gated' on a network's or a "
        "relative depth)")

    def __post_init__(self) -> None:
        if self.normals_method not in NORMALS_CHOICES:
            raise ConfigError(f"normals_method must be one of {', '.join(NORMALS_CHOICES)}, "
                              f"got {self.normals_method!r}")
        r, st = self.normals_radius, self.normals_stride
        if r < 0 or st < 0 or (r and st > r):
            raise ConfigError(f"need 0 <= normals_stride <= normals_radius (0 = automatic), "
                              f"got radius {r}, stride {st}")
        if self.max_jump <= 0:
            raise ConfigError(f"max_jump must be positive, got {self.max_jump}")

    def normals_options(self) -> dict:
        """Keyword arguments for :func:`~monoplane.geometry.normals.normals_from_depth`, with
        ``method`` still a choice: :func:`~monoplane.geometry.normals.cue_normals_from_depth`
        resolves it per depth map."""
        return {"radius": self.normals_radius or None, "stride": self.normals_stride or None,
                "max_jump": self.max_jump, "method": self.normals_method}


@dataclass
class GivenCuesConfig(NormalsFromDepthOptions):
    """Parameters of the ``given`` cue provider."""

    recompute_normals: bool = param(
        False, "estimate normals from depth even when normals are given")


class GivenCues(CueProvider):
    """Depth and normals given with the image (RGB-D, precomputed network outputs)."""

    name = "given"
    Config = GivenCuesConfig

    def provide(self, frame: Frame) -> Frame:
        """Check the given cues, estimate missing normals, orient normals to the camera.

        Parameters
        ----------
        frame : Frame
            Must have ``depth``; ``normals`` are optional.

        Returns
        -------
        Frame
            With ``normals`` set: unit, camera frame (OpenCV axes), facing the camera, zero
            where depth is invalid.
        """
        cfg = self.config
        if frame.depth is None:
            raise InvalidInput(
                f"{frame.name}: cue provider 'given' needs a depth map (--depth FILE); to "
                f"predict depth from the image use cues.plugin=onnx")
        if frame.normals is not None and not cfg.recompute_normals:
            return use_given_cues(frame)
        # Already float32 and zero wherever the depth is not positive (or not finite).
        normals, note = cue_normals_from_depth(frame.depth, frame.K, cfg.normals_options(),
                                               frame.depth_measured)
        return frame.with_(normals=normals, normals_from_depth=True,
                           notes=[*frame.notes, note])

    def needs_cues(self, frame: Frame) -> bool:
        """Also run on complete frames when told to recompute the given normals."""
        return self.config.recompute_normals or super().needs_cues(frame)


@dataclass
class OnnxCuesConfig(NormalsFromDepthOptions):
    """Parameters of the ``onnx`` cue provider."""

    model: str = param(
        "", "catalogue model name (see 'monoplane models list'); sets the profile and the "
            "depth model file, downloaded once with 'monoplane models fetch NAME'")
    profile: str = param(
        "omnidata", f"network profile: {', '.join(sorted(BUILTIN_PROFILES))}, a profile file "
                    f"'path/to/model.toml', or '{CUSTOM_PROFILE}' for the [cues.custom] table "
                    f"(ignored when 'model' is set; see docs/cues.md)")
    custom: dict[str, Any] = param(
        {}, f"an inline profile, the tables of a profile file (used when profile = "
            f"'{CUSTOM_PROFILE}')")
    depth_model: str = param(
        "", "path to the depth network's .onnx file (default: the profile file's [model] file)")
    normal_model: str = param(
        "", "path to the normals network's .onnx file (default: the profile file's "
            "[normals_model] file; none: normals estimated from depth)")
    threads: int = param(2, "onnxruntime CPU threads per network")
    input_size: list[int] = param(
        [], "override the profile's network input box [height, width] in pixels")
    mean: list[float] = param([], "override the profile's RGB mean (3 values, 0-1 scale)")
    std: list[float] = param([], "override the profile's RGB std (3 values, 0-1 scale)")
    normal_axes: str = param(
        "", "override the normals network's axis convention, e.g. 'x,-y,-z' (see docs/cues.md)")
    hfov_deg: float = param(
        0.0, "field of view to assume for images without intrinsics (0: the profile's, or 60)")
    disparity_floor: float = param(
        0.01, "inverse-depth networks: disparities below this fraction of the median are "
              "invalid")

    def __post_init__(self) -> None:
        if self.custom and self.profile != CUSTOM_PROFILE:
            raise ConfigError(f"[cues.custom] is set but cues.profile is {self.profile!r}; set "
                              f"profile = \"{CUSTOM_PROFILE}\" to use it")
        if self.model:
            if get_model(self.model).task == "features":
                raise ConfigError(f"cues.model {self.model!r} is a features model, not a depth "
                                  f"or normals network; use it as [features] model")
            if self.depth_model:
                raise ConfigError("set either cues.model (a catalogue name) or "
                                  "cues.depth_model (a file), not both")
        if self.threads < 1:
            raise ConfigError(f"threads must be >= 1, got {self.threads}")
        if self.input_size and (len(self.input_size) != 2 or min(self.input_size) < 1):
            raise ConfigError(f"input_size must be [height, width], got {self.input_size}")
        for key in ("mean", "std"):
            if getattr(self, key) and len(getattr(self, key)) != 3:
                raise ConfigError(f"{key} needs 3 values, got {getattr(self, key)}")
        if self.hfov_deg < 0 or self.hfov_deg >= 180:
            raise ConfigError(f"hfov_deg must be in [0, 180), got {self.hfov_deg}")
        if not 0 < self.disparity_floor < 1:
            raise ConfigError(f"disparity_floor must be in (0, 1), got {self.disparity_floor}")
        super().__post_init__()
        # Validates the overrides (axes, sizes) now, at config time.
        self.resolved_profile()

    def declared_profile(self) -> DeclaredProfile:
        """The chosen profile before overrides, with the model files its tables name.

        A catalogue model's profile, a built-in profile, a profile file (read now, model paths
        relative to it) or the inline ``[cues.custom]`` table.
        """
        if self.model:
            return DeclaredProfile(get_profile(get_model(self.model).profile))
        if is_profile_file(self.profile):
            return load_profile_file(self.profile)
        if self.profile == CUSTOM_PROFILE:
            if not self.custom:
                raise ConfigError(f"cues.profile = \"{CUSTOM_PROFILE}\" needs a [cues.custom] "
                                  f"table (the tables of a profile file, see docs/cues.md)")
            return profile_from_table(self.custom, "[cues.custom]")
        return DeclaredProfile(get_profile(self.profile))

    def resolved_profile(self) -> OnnxProfile:
        """The chosen profile with this config's overrides applied."""
        def triple(v: list[float]) -> tuple[float, float, float] | None:
            return (v[0], v[1], v[2]) if v else None

        size = (self.input_size[0], self.input_size[1]) if self.input_size else None
        return self.declared_profile().profile.with_overrides(
            size=size, mean=triple(self.mean), std=triple(self.std),
            normal_axes=self.normal_axes or None)


class OnnxCues(NetworkCues):
    """Monocular depth and normals from ONNX networks, described by a profile."""

    name = "onnx"
    Config = OnnxCuesConfig

    def build_network(self, config: OnnxCuesConfig) -> CueNetwork:
        """The profile's networks, with the config's files (else the profile file's) and
        options."""
        declared = config.declared_profile()
        return CueNetwork(
            config.resolved_profile(), config.depth_model or declared.depth_model,
            config.normal_model or declared.normal_model,
            threads=config.threads, disparity_floor=config.disparity_floor,
            hfov_deg=config.hfov_deg or None, normals_options=config.normals_options())

    @classmethod
    def catalogue_config(cls, model: str) -> dict[str, Any] | None:
        """``{"model": model}``: the catalogue entry sets the profile and the depth model; a
        profile file (``--cues my_model.toml``) is ``{"profile": model}``."""
        return {"profile": model} if is_profile_file(model) else {"model": model}

    def catalogue_model(self, missing_depth: bool, missing_normals: bool) -> str | None:
        """``cues.model`` when a frame lacking these cues needs the network: always without
        depth, and without normals when the network predicts them jointly."""
        joint = self.config.resolved_profile().depth.joint_normals
        if self.config.model and (missing_depth or (joint and missing_normals)):
            return self.config.model
        return None

    def lacks_depth_model(self) -> bool:
        """True when no depth network is configured: no ``cues.model``, no ``depth_model``
        and none in the profile file."""
        return self.network.depth_path is None and self.catalogue_model(True, True) is None

    def provide(self, frame: Frame) -> Frame:
        """Predict the frame's missing depth and normals (see :meth:`CueNetwork.provide`).

        A catalogue model (``cues.model``) is looked up in the cache only when a frame needs
        the network, so frames that carry their own cues run without it.
        """
        cfg = self.config
        net = self.network
        needs_net = frame.depth is None or (
            net.profile.depth.joint_normals and frame.normals is None and frame.rgb is not None)
        if cfg.model and net.depth_path is None and needs_net:
            net.depth_path = require_model(cfg.model)
        return super().provide(frame)


@hookimpl
def monoplane_register_cue_providers() -> list[type[Stage]]:
    """Register the built-in cue providers."""
    return [GivenCues, OnnxCues]
