"""Monocular models on demand: a catalogue of published ONNX exports and a local cache.

::

    from monoplane.models import fetch, require_model
    fetch("depth-anything-v2-small")            # downloads once, verified
    path = require_model("depth-anything-v2-small")

or in a config: ``[cues] model = "depth-anything-v2-small"``.
"""

from monoplane.models.cache import (
    CACHE_ENV,
    FetchResult,
    cache_dir,
    cached_model,
    fetch,
    fetch_command,
    model_path,
    require_model,
    sha256_of,
)
from monoplane.models.catalogue import CATALOGUE, TASKS, ModelRecord, get_model

__all__ = [
    "CACHE_ENV", "CATALOGUE", "FetchResult", "ModelRecord", "TASKS", "cache_dir",
    "cached_model", "fetch", "fetch_command", "get_model", "model_path", "require_model",
    "sha256_of",
]
