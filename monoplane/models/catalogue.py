"""The model catalogue: published ONNX exports monoplane knows how to fetch and run.

Models are data, not code: the records are the tables of ``catalogue.toml``, next to this
module, which reads and checks them. A record says where a file comes from (a Hugging Face
repository, a revision and a path inside it), how to check it (size and SHA-256), its licence,
and which profile (:mod:`monoplane.cues.profiles`) runs it; the profile stays the one place
that knows the network's inputs and outputs. Nothing here downloads: see
:mod:`monoplane.models.cache`.

Facts a record could not be checked against (a revision that is a branch name, a missing hash)
are marked as such in the record and in ``docs/cues.md``; ``monoplane models fetch`` prints the
hash it got so that a maintainer can pin it.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import asdict, dataclass
from importlib import resources
from typing import Any

from monoplane.cues.profile_files import get_profile
from monoplane.errors import ConfigError

TASKS: tuple[str, ...] = ("depth", "normals", "both", "features")
#: Tasks of cue networks (run by a cue profile); ``features`` models run in a features stage.
CUE_TASKS: tuple[str, ...] = ("depth", "normals", "both")
#: Where a record's file is published.
HOSTS: tuple[str, ...] = ("huggingface", "github")
_HEX = re.compile(r"[0-9a-f]+")


@dataclass(frozen=True)
class ModelRecord:
    """One downloadable model file.

    Attributes
    ----------
    name : str
        Catalogue name used on the command line and in ``cues.model``.
    task : str
        ``"depth"``, ``"normals"`` or ``"both"`` for cue networks; ``"features"`` for a
        keypoint network (run by the ``[features]`` stage named by ``profile``).
    licence : str
        SPDX identifier(s) and where the claim comes from.
    size : int or None
        File size in bytes; ``None`` when unknown (then only the hash, if any, is checked).
    profile : str
        The :mod:`~monoplane.cues.profiles` profile that runs the file; for a ``features``
        model, the features stage that runs it.
    repo : str
        Repository on ``host``, ``owner/name``.
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
    host: str = "huggingface"

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ConfigError(f"model {self.name!r}: task must be one of {', '.join(TASKS)}")
        if self.host not in HOSTS:
            raise ConfigError(f"model {self.name!r}: host must be one of {', '.join(HOSTS)}")
        if self.task in CUE_TASKS:
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
        if self.host == "github":
            return (f"https://raw.githubusercontent.com/{self.repo}/{self.revision}/"
                    f"{self.filename}")
        return f"https://huggingface.co/{self.repo}/resolve/{self.revision}/{self.filename}"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields plus ``url`` and ``pinned``."""
        return {**asdict(self), "url": self.url, "pinned": self.pinned}


def _load_catalogue() -> dict[str, ModelRecord]:
    """The records of ``catalogue.toml``, by name, in the file's order (each checked by
    :class:`ModelRecord`; a bad one raises :class:`ConfigError` on import)."""
    tables = tomllib.loads((resources.files(__package__) / "catalogue.toml").read_text("utf-8"))
    # TOML has no null: an unknown size or hash is a key left out.
    return {name: ModelRecord(name=name, **{"size": None, "sha256": None, **fields})
            for name, fields in tables.items()}


#: The catalogue, by name. Every entry has a licence that allows any use (see docs/cues.md).
CATALOGUE: dict[str, ModelRecord] = _load_catalogue()


def get_model(name: str) -> ModelRecord:
    """Look up a catalogue entry; unknown names raise :class:`ConfigError` listing the valid."""
    try:
        return CATALOGUE[name]
    except KeyError:
        raise ConfigError(f"unknown model {name!r}; catalogue models: "
                          f"{', '.join(sorted(CATALOGUE))} (see 'monoplane models list')"
                          ) from None
