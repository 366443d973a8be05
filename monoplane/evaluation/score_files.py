"""Writing the scores and timings of ``monoplane eval`` and ``monoplane bench`` as JSON."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any


def _finite(x: Any) -> Any:
    """``x`` with every non-finite float (NaN, inf) replaced by None, which JSON can hold."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_finite(v) for v in x]
    return x


def write_scores(path: str | Path, data: dict[str, Any], nan_as_null: bool = True) -> Path:
    """Write ``data`` as indented JSON, creating the parent folders; the file appears whole
    (written beside it, then renamed).

    Parameters
    ----------
    path : str or Path
        Target file.
    data : dict
        JSON-serialisable scores.
    nan_as_null : bool
        Write non-finite floats as ``null`` (strict JSON: a score that could not be computed);
        otherwise as Python's ``NaN`` / ``Infinity``, which :mod:`json` reads back as floats.

    Returns
    -------
    Path
        The file written.
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(target.name + ".tmp")
    tmp.write_text(json.dumps(_finite(data) if nan_as_null else data, indent=2) + "\n")
    tmp.replace(target)
    return target
