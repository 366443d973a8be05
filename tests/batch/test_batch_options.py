"""run_batch's options: one typed bundle, and the keyword call of earlier versions."""

from __future__ import annotations

from pathlib import Path

import pytest

from monoplane.batch import BatchOptions, run_batch
from monoplane.errors import ConfigError


def test_keywords_replace_fields_of_the_options() -> None:
    opts = BatchOptions.of(BatchOptions(workers=2, preset="range"), preset="monoplane")
    assert (opts.workers, opts.preset, opts.engine) == (2, "monoplane", "local")
    assert BatchOptions.of() == BatchOptions()


def test_an_unknown_keyword_names_the_options(tmp_path: Path) -> None:
    with pytest.raises(TypeError, match="'wrokers'; options: config, depth_encoding, depth_kind"):
        run_batch([], tmp_path / "out", wrokers=2)


@pytest.mark.parametrize("call", [
    lambda out: run_batch([], out, {"ransac": {"no_such_key": 1}}),  # config, positionally
    lambda out: run_batch([], out, config={"ransac": {"no_such_key": 1}}),
    lambda out: run_batch([], out, BatchOptions(config={"ransac": {"no_such_key": 1}})),
])
def test_the_config_reaches_the_pipeline_however_it_is_given(call, tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no_such_key"):
        call(tmp_path / "out")
    assert not (tmp_path / "out").exists()  # checked before any output
