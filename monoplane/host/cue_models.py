"""What a run needs from the model catalogue before it reads an image: the cue provider's
catalogue model in the cache (fetched on request), and a depth network for a frame without
depth.

The cue provider decides (:meth:`~monoplane.contracts.CueProvider.catalogue_model`,
:meth:`~monoplane.contracts.CueProvider.lacks_depth_model`); these helpers act on its answer
so that the command line only prints.
"""

from __future__ import annotations

from monoplane.contracts import CueProvider
from monoplane.errors import InvalidInput
from monoplane.host.pipeline import Pipeline
from monoplane.models import FetchResult, cached_model, fetch, require_model


def prepare_cue_model(pipe: Pipeline, *, fetch_missing: bool, has_depth: bool,
                      has_normals: bool) -> tuple[str, FetchResult] | None:
    """Make sure the pipeline's catalogue model (``cues.model``) is in the cache.

    The cue provider says which catalogue model the input needs
    (:meth:`~monoplane.contracts.CueProvider.catalogue_model`). With ``fetch_missing`` a
    missing model is downloaded (the only download a run ever does); otherwise a missing model
    is a one-line error naming the fetch command, raised before any image is read.

    Parameters
    ----------
    pipe : Pipeline
        The configured pipeline.
    fetch_missing : bool
        Download the model when it is not cached (``--fetch``).
    has_depth, has_normals : bool
        Whether the input brings its own depth and normals.

    Returns
    -------
    (str, FetchResult) or None
        The catalogue name and what its download did, or None when nothing was downloaded
        (no model needed, or it was cached already).

    Raises
    ------
    monoplane.errors.InvalidInput
        The model is missing and ``fetch_missing`` is False.
    """
    name = pipe.stage("cues", CueProvider).catalogue_model(not has_depth, not has_normals)
    if not name or cached_model(name) is not None:
        return None
    if fetch_missing:
        return name, fetch(name)
    require_model(name)
    return None


def require_depth_source(pipe: Pipeline, image: str) -> None:
    """Fail with the next step when ``image`` has no depth and the cue provider, one that takes
    catalogue models (``--cues``), has no depth network to predict it
    (:meth:`~monoplane.contracts.CueProvider.lacks_depth_model`).

    Other providers (``given``, plugins with their own model files) give their own error when
    they run.

    Raises
    ------
    monoplane.errors.InvalidInput
        Naming ``image`` and the two ways out (a catalogue model, a depth file).
    """
    if pipe.stage("cues", CueProvider).lacks_depth_model():
        raise InvalidInput(
            f"{image} has no depth and no depth model is set: pass --cues NAME --fetch to "
            f"download a monocular model once (e.g. --cues depth-anything-v2-small; "
            f"'monoplane models list' shows them all), or give --depth FILE")
