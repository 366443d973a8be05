"""The local model cache and the one function that downloads into it.

Files live at ``<cache>/models/<name>/<revision>/<file name>``, where ``<cache>`` is
``$MONOPLANE_CACHE`` or ``~/.cache/monoplane``. :func:`fetch` is the only code in monoplane that
touches the network, and only when a user asks for it (``monoplane models fetch``,
``monoplane run --fetch``). A download goes to a temporary folder inside the cache, is checked
against the catalogue's size and hash, and is renamed into place only when it passes, so the
cache never holds a partial or unverified file under a model's name.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

from monoplane.errors import InvalidInput
from monoplane.models.catalogue import ModelRecord, get_model

CACHE_ENV = "MONOPLANE_CACHE"

#: ``downloader(repo_id, filename, revision, local_dir) -> path of the downloaded file``.
Downloader = Callable[[str, str, str, Path], Path]


def cache_dir() -> Path:
    """The cache root: ``$MONOPLANE_CACHE`` or ``~/.cache/monoplane``."""
    env = os.environ.get(CACHE_ENV)
    return Path(env).expanduser() if env else Path.home() / ".cache" / "monoplane"


def model_path(record: ModelRecord) -> Path:
    """Where the record's file lives in the cache (whether or not it is there)."""
    return (cache_dir() / "models" / record.name / record.revision
            / PurePosixPath(record.filename).name)


def fetch_command(record: ModelRecord) -> str:
    """The command that downloads a record."""
    return f"monoplane models fetch {record.name}"


def sha256_of(path: Path) -> str:
    """Hex SHA-256 of a file, read in 8 MiB chunks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(8 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def check_file(record: ModelRecord, path: Path, *, full: bool) -> str | None:
    """Check a file against its record.

    Parameters
    ----------
    full : bool
        Also hash the file (a size check alone is what every run does).

    Returns
    -------
    str or None
        ``None`` when it matches, else why not (one phrase).
    """
    size = path.stat().st_size
    if record.size is not None and size != record.size:
        return (f"it has {size:,} bytes, the catalogue expects {record.size:,} (a truncated "
                f"download or a changed upstream file)")
    if full and record.sha256 is not None:
        digest = sha256_of(path)
        if not digest.startswith(record.sha256):
            return f"its SHA-256 is {digest}, the catalogue expects {record.sha256}"
    return None


def cached_model(name: str) -> Path | None:
    """The cached file of a catalogue model, or ``None`` when it is not there.

    Raises
    ------
    InvalidInput
        When a file is there but has the wrong size (it is never used then).
    """
    record = get_model(name)
    path = model_path(record)
    if not path.is_file():
        return None
    problem = check_file(record, path, full=False)
    if problem:
        raise InvalidInput(f"{path}: the cached {record.name} model is unusable: {problem}; "
                           f"delete it and run '{fetch_command(record)}'")
    return path


def require_model(name: str) -> Path:
    """The cached file of a catalogue model; a one-line error naming the fetch command if not."""
    path = cached_model(name)
    if path is None:
        record = get_model(name)
        raise InvalidInput(
            f"model {name!r} is not downloaded yet: run '{fetch_command(record)}' (about "
            f"{_megabytes(record.size)}), or pass --fetch to 'monoplane run'; it will be stored "
            f"at {model_path(record)}")
    return path


def _megabytes(size: int | None) -> str:
    return "unknown size" if size is None else f"{size / 1e6:.0f} MB"


def _hf_download(repo_id: str, filename: str, revision: str, local_dir: Path) -> Path:
    """Download one file with huggingface_hub into ``local_dir`` (no shared HF cache)."""
    import logging

    from huggingface_hub import hf_hub_download

    # huggingface_hub logs every retry of an unreachable host; the caller reports the failure
    # once, in one line.
    hub_logger = logging.getLogger("huggingface_hub")
    level = hub_logger.level
    hub_logger.setLevel(logging.ERROR)
    try:
        return Path(hf_hub_download(repo_id=repo_id, filename=filename, revision=revision,
                                    local_dir=str(local_dir)))
    finally:
        hub_logger.setLevel(level)


def _github_download(repo: str, filename: str, revision: str, local_dir: Path) -> Path:
    """Download one file of a GitHub repository at a revision into ``local_dir``."""
    import urllib.request

    url = f"https://raw.githubusercontent.com/{repo}/{revision}/{filename}"
    target = local_dir / Path(filename).name
    with urllib.request.urlopen(url, timeout=60) as response, open(target, "wb") as out:
        shutil.copyfileobj(response, out)
    return target


@dataclass(frozen=True)
class FetchResult:
    """What :func:`fetch` did.

    Attributes
    ----------
    path : pathlib.Path
        The verified file in the cache.
    sha256 : str
        Its full SHA-256 (print it so a maintainer can pin an unpinned record).
    downloaded : bool
        False when the file was already cached and verified.
    """

    path: Path
    sha256: str
    downloaded: bool


def fetch(name: str, *, downloader: Downloader | None = None) -> FetchResult:
    """Download a catalogue model into the cache (or verify the copy already there).

    Parameters
    ----------
    name : str
        Catalogue name.
    downloader : callable, optional
        Replaces the download from the record's host (tests).

    Raises
    ------
    InvalidInput
        One line: the network is unreachable (naming the URL and where to place the file by
        hand), or the download does not match the catalogue (nothing is kept).
    """
    record = get_model(name)
    final = model_path(record)
    if final.is_file():
        problem = check_file(record, final, full=True)
        if problem is None:
            return FetchResult(final, sha256_of(final), downloaded=False)
        final.unlink()  # a bad copy (e.g. placed by hand) is replaced, never used
    final.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".fetch-", dir=final.parent))
    try:
        try:
            download = downloader or (_github_download if record.host == "github"
                                      else _hf_download)
            got = download(record.repo, record.filename, record.revision, tmp)
        except Exception as exc:  # offline, DNS, HTTP errors: huggingface_hub raises many types
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            # Library messages run on; keep their first sentence so the line stays readable.
            first = first.split(". ")[0].rstrip(".")[:160]
            raise InvalidInput(
                f"cannot download {record.url} ({type(exc).__name__}: {first}); without a "
                f"network, download that file elsewhere and place it at {final}") from None
        got = Path(got)
        if not got.is_file():
            raise InvalidInput(f"download of {record.url} produced no file")
        problem = check_file(record, got, full=True)
        if problem:
            raise InvalidInput(f"downloaded {record.url}, but {problem}; nothing was kept")
        digest = sha256_of(got)
        os.replace(got, final)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return FetchResult(final, digest, downloaded=True)
