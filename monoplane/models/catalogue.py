"""The model catalogue: published ONNX exports monoplane knows how to fetch and run.

Models are data, not code. A record says where a file comes from (a Hugging Face repository, a
revision and a path inside it), how to check it (size and SHA-256), its licence, and which
profile (:mod:`monoplane.cues.profiles`) runs it; the profile stays the one place that knows
the network's inputs and outputs. Nothing here downloads: see :mod:`monoplane.models.cache`.

Facts a record could not be checked against (a revision that is a branch name, a missing hash)
are marked as such in the record and in ``docs/cues.md``; ``monoplane models fetch`` prints the
hash it got so that a maintainer can pin it.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from typing import Any

from monoplane.cues.profiles import get_profile
from monoplane.errors import ConfigError

TASKS: tuple[str, ...] = ("depth", "normals", "both")
_HEX = re.compile(r"[0-9a-f]+")


@dataclass(frozen=True)
class ModelRecord:
    """One downloadable model file.

    Attributes
    ----------
    name : str
        Catalogue name used on the command line and in ``cues.model``.
    task : str
        ``"depth"``, ``"normals"`` or ``"both"``.
    licence : str
        SPDX identifier(s) and where the claim comes from.
    size : int or None
        File size in bytes; ``None`` when unknown (then only the hash, if any, is checked).
    profile : str
        The :mod:`~monoplane.cues.profiles` profile that runs the file.
    repo : str
        Hugging Face model repository, ``owner/name``.
    revision : str
        A 40-digit commit hash (pinned) or a branch name such as ``"main"`` (not pinned).
    filename : str
        Path of the file inside the repository.
    sha256 : str or None
        Lower-case hex SHA-256 of the file, or its first 16+ digits when only a prefix is
        published; ``None`` means "size check only".
    summary : str
        What the model is good at, one line.
    provenance : str
        Where the revision, size and hash come from, and what is not verified.
    """

    name: str
    task: str
    licence: str
    size: int | None
    profile: str
    repo: str
    revision: str
    filename: str
    sha256: str | None
    summary: str
    provenance: str

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ConfigError(f"model {self.name!r}: task must be one of {', '.join(TASKS)}")
        get_profile(self.profile)
        if self.sha256 is not None and (len(self.sha256) < 16 or len(self.sha256) > 64
                                        or not _HEX.fullmatch(self.sha256)):
            raise ConfigError(f"model {self.name!r}: sha256 must be 16-64 lower-case hex digits")
        if self.size is not None and self.size <= 0:
            raise ConfigError(f"model {self.name!r}: size must be positive")

    @property
    def pinned(self) -> bool:
        """True when ``revision`` is a commit hash rather than a moving branch."""
        return len(self.revision) == 40 and bool(_HEX.fullmatch(self.revision))

    @property
    def url(self) -> str:
        """Direct download URL of the file at the revision."""
        return f"https://huggingface.co/{self.repo}/resolve/{self.revision}/{self.filename}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields plus ``url`` and ``pinned``."""
        return {**asdict(self), "url": self.url, "pinned": self.pinned}


#: The catalogue, by name. Every entry has a licence that allows any use (see docs/cues.md).
CATALOGUE: dict[str, ModelRecord] = {r.name: r for r in (
    ModelRecord(
        name="depth-anything-v2-small",
        task="depth",
        licence="Apache-2.0 (model card; only the Small size is Apache-2.0, the larger ones "
                "are CC-BY-NC-4.0)",
        size=99_060_839,
        profile="depth-anything-v2",
        repo="onnx-community/depth-anything-v2-small",
        revision="4472b7362082ad9968fee890ca0f1e5aca36b93d",
        filename="onnx/model.onnx",
        sha256="afb6a5c28f3b6bf1618c6e43f02073ef9dfdc70e937502d51603e57b0a1df10c",
        summary="fast, sharp relative depth of any scene; normals estimated from depth",
        provenance="revision, size and SHA-256 as recorded by independent projects that pin "
                   "this file (the hash by two of them); not re-downloaded by monoplane's "
                   "authors",
    ),
    ModelRecord(
        name="metric3d-v2-small",
        task="both",
        licence="CC0-1.0 (ONNX model card); upstream Metric3D code BSD-2-Clause",
        size=150_739_433,
        profile="metric3d-v2",
        repo="onnx-community/metric3d-vit-small",
        revision="ee63b95d92d2f629b3e019e88f57eea7c1e97d4b",
        filename="onnx/model.onnx",
        sha256="674a665052f01bb2",
        summary="metric depth and surface normals in one network; depth scale follows the "
                "focal length",
        provenance="revision, size and the first 16 SHA-256 digits as recorded by an "
                   "independent project that pins this file; the full hash is not published "
                   "there, so fetch checks the prefix and prints the full hash",
    ),
    ModelRecord(
        name="moge-2-vits-normal",
        task="both",
        licence="MIT (upstream MoGe repository; the ONNX repository's card names none)",
        size=140_852_051,
        profile="moge-2",
        repo="Ruicheng/moge-2-vits-normal-onnx",
        revision="main",
        filename="model.onnx",
        sha256="24eacb5dc7a2c54c7bc98f7de085ffbed79ad006ea5b664c2c2cdc02ff3a52f0",
        summary="metric point map, normals and the camera's field of view in one network",
        provenance="size and SHA-256 as recorded by an independent project; the revision is "
                   "the moving branch 'main' (no commit hash was available), so a changed "
                   "upstream file fails the size/hash check instead of being used",
    ),
)}


def get_model(name: str) -> ModelRecord:
    """Look up a catalogue entry; unknown names raise :class:`ConfigError` listing the valid."""
    try:
        return CATALOGUE[name]
    except KeyError:
        raise ConfigError(f"unknown model {name!r}; catalogue models: "
                          f"{', '.join(sorted(CATALOGUE))} (see 'monoplane models list')"
                          ) from None
