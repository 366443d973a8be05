"""Score files: strict JSON by default, NaN kept for the bench's round trip."""

from __future__ import annotations

import json
import math
from pathlib import Path

from monoplane.evaluation.score_files import write_scores


def test_non_finite_scores_become_null_at_any_depth(tmp_path: Path) -> None:
    path = write_scores(tmp_path / "a" / "b" / "scores.json",
                        {"x": float("nan"), "rows": [{"y": float("inf"), "z": 1.5}], "n": 3})
    assert path == tmp_path / "a" / "b" / "scores.json"
    assert json.loads(path.read_text()) == {"x": None, "rows": [{"y": None, "z": 1.5}], "n": 3}
    assert [p.name for p in path.parent.iterdir()] == ["scores.json"]  # no temporary left


def test_nan_can_be_kept_as_a_float(tmp_path: Path) -> None:
    path = write_scores(tmp_path / "bench.json", {"t": float("nan")}, nan_as_null=False)
    assert math.isnan(json.loads(path.read_text())["t"])
