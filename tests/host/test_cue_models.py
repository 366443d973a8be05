"""The cue provider decides what a run needs from the model catalogue; the host helpers act on
its answer before any image is read (``monoplane run`` only prints what they return)."""

from __future__ import annotations

from pathlib import Path

import pytest

from monoplane.contracts import CueProvider
from monoplane.errors import InvalidInput
from monoplane.host import cue_models
from monoplane.host.cue_models import prepare_cue_model, require_depth_source
from monoplane.host.pipeline import Pipeline
from monoplane.models import FetchResult


@pytest.fixture(autouse=True)
def empty_cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = tmp_path / "cache"
    monkeypatch.setenv("MONOPLANE_CACHE", str(root))
    return root


def _pipe(*overrides: str) -> Pipeline:
    return Pipeline.from_config(None, overrides=list(overrides))


@pytest.mark.parametrize("overrides, lacks", [
    ((), True),                                            # onnx, no model of any kind
    (("cues.model=depth-anything-v2-small",), False),      # a catalogue model
    (("cues.depth_model=my_depth.onnx",), False),          # a file of the user's
    (("cues.plugin=given",), False),                       # takes no catalogue model
])
def test_the_provider_says_whether_it_lacks_a_depth_model(overrides, lacks) -> None:
    assert _pipe(*overrides).stage("cues", CueProvider).lacks_depth_model() is lacks


def test_an_image_without_depth_and_model_names_the_next_step() -> None:
    with pytest.raises(InvalidInput, match=r"^photo.jpg has no depth and no depth model is set: "
                                           r"pass --cues NAME --fetch"):
        require_depth_source(_pipe(), "photo.jpg")
    require_depth_source(_pipe("cues.plugin=given"), "photo.jpg")  # its own error, later


def test_a_model_the_input_does_not_need_is_neither_checked_nor_fetched(monkeypatch) -> None:
    monkeypatch.setattr(cue_models, "fetch", lambda name: pytest.fail("fetched"))
    pipe = _pipe("cues.model=depth-anything-v2-small")
    assert prepare_cue_model(pipe, fetch_missing=True, has_depth=True,
                             has_normals=True) is None
    assert prepare_cue_model(_pipe(), fetch_missing=True, has_depth=False,
                             has_normals=False) is None  # no model configured


def test_a_missing_model_fails_naming_the_fetch_command_or_is_fetched(monkeypatch) -> None:
    pipe = _pipe("cues.model=depth-anything-v2-small")
    with pytest.raises(InvalidInput, match="monoplane models fetch depth-anything-v2-small"):
        prepare_cue_model(pipe, fetch_missing=False, has_depth=False, has_normals=False)
    done = FetchResult(Path("/cache/model.onnx"), "0" * 64, downloaded=True)
    asked: list[str] = []
    monkeypatch.setattr(cue_models, "fetch", lambda name: asked.append(name) or done)
    assert prepare_cue_model(pipe, fetch_missing=True, has_depth=False,
                             has_normals=False) == ("depth-anything-v2-small", done)
    assert asked == ["depth-anything-v2-small"]
