"""What a run needs from the model catalogue before it reads an image: the cue provider's
catalogue model in the cache (fetched on request), and a depth network for a frame without
depth."""

from __future__ import annotations

from monoplane.cues import CueNetwork
from monoplane.errors import InvalidInput
from monoplane.host.pipeline import Pipeline
from monoplane.models import cached_model, fetch, require_model
from monoplane.stages.base import CueProvider


def prepare_cue_model(pipe: Pipeline, *, fetch_missing: bool, has_depth: bool,
                      has_normals: bool, quiet: bool = False) -> None:
    """Make sure the pipeline's catalogue model (``cues.model``) is in the cache.

    The cue provider says which catalogue model the input needs
    (:meth:`~monoplane.stages.base.CueProvider.catalogue_model`). With ``fetch_missing`` a
    missing model is downloaded (the only download a run ever does); otherwise a missing model
    is a one-line error naming the fetch command, raised before any image is read.
    """
    name = pipe.stage("cues", CueProvider).catalogue_model(not has_depth, not has_normals)
    if not name or cached_model(name) is not None:
        return
    if fetch_missing:
        result = fetch(name)
        if not quiet:
            print(f"fetched {name} -> {result.path} (sha256 {result.sha256})")
        return
    require_model(name)


def require_depth_source(pipe: Pipeline, image: str) -> None:
    """Fail with the next step when an image has no depth and the cue provider, one that takes
    catalogue models (``--cues``), has no depth network to predict it.

    Other providers (``given``, plugins with their own model files) give their own error when
    they run.
    """
    provider = pipe.stage("cues", CueProvider)
    network = getattr(provider, "network", None)
    takes_catalogue = type(provider).catalogue_model is not CueProvider.catalogue_model
    if (takes_catalogue and isinstance(network, CueNetwork) and network.depth_path is None
            and provider.catalogue_model(True, True) is None):
        raise InvalidInput(
            f"{image} has no depth and no depth model is set: pass --cues NAME --fetch to "
            f"download a monocular model once (e.g. --cues depth-anything-v2-small; "
            f"'monoplane models list' shows them all), or give --depth FILE")
