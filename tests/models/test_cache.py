"""The model catalogue, the cache and ``monoplane models``, with no network.

Downloads go through a fake downloader that writes chosen bytes (or fails), so every outcome a
real download can have is exercised: success, a truncated file, wrong bytes of the right size,
an unreachable host.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from monoplane.cli import main
from monoplane.errors import ConfigError, InvalidInput
from monoplane.host.pipeline import Pipeline
from monoplane.models import (
    CATALOGUE,
    ModelRecord,
    cache_dir,
    cached_model,
    fetch,
    get_model,
    model_path,
    require_model,
)
from monoplane.models import cache as cache_mod

PAYLOAD = b"not really an onnx file, but bytes with a known hash" * 100


def record(name: str = "tiny", **changes) -> ModelRecord:
    fields = dict(name=name, task="depth", licence="MIT", size=len(PAYLOAD),
                  profile="depth-anything-v2", repo="someone/tiny", revision="a" * 40,
                  filename="onnx/model.onnx", sha256=hashlib.sha256(PAYLOAD).hexdigest(),
                  summary="test entry", provenance="built by the test")
    fields.update(changes)
    return ModelRecord(**fields)


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    root = tmp_path / "cache"
    monkeypatch.setenv("MONOPLANE_CACHE", str(root))
    return root


@pytest.fixture
def tiny(monkeypatch: pytest.MonkeyPatch) -> ModelRecord:
    rec = record()
    monkeypatch.setitem(CATALOGUE, rec.name, rec)
    return rec


def downloader(payload: bytes, calls: list | None = None):
    """A fake huggingface_hub download that writes ``payload`` where the real one would."""
    def download(repo_id: str, filename: str, revision: str, local_dir: Path) -> Path:
        if calls is not None:
            calls.append((repo_id, filename, revision))
        target = Path(local_dir) / filename
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(payload)
        return target
    return download


def offline(repo_id: str, filename: str, revision: str, local_dir: Path) -> Path:
    raise ConnectionError("Name or service not known\nsecond line of a long report")


def leftovers(rec: ModelRecord) -> list[Path]:
    """Everything in the record's cache folder except a complete file."""
    folder = model_path(rec).parent
    return [p for p in folder.rglob("*") if p != model_path(rec)] if folder.exists() else []


def test_cache_location_follows_monoplane_cache(cache: Path, tiny: ModelRecord,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    assert cache_dir() == cache
    assert model_path(tiny) == cache / "models" / "tiny" / ("a" * 40) / "model.onnx"
    monkeypatch.delenv("MONOPLANE_CACHE")
    assert cache_dir() == Path.home() / ".cache" / "monoplane"


def test_fetch_downloads_verifies_and_renames(cache: Path, tiny: ModelRecord) -> None:
    calls: list = []
    result = fetch("tiny", downloader=downloader(PAYLOAD, calls))
    assert calls == [("someone/tiny", "onnx/model.onnx", "a" * 40)]
    assert result.downloaded and result.path == model_path(tiny)
    assert result.path.read_bytes() == PAYLOAD
    assert result.sha256 == hashlib.sha256(PAYLOAD).hexdigest()
    assert leftovers(tiny) == []
    assert cached_model("tiny") == require_model("tiny") == result.path
    again = fetch("tiny", downloader=offline)  # cached: no download attempted
    assert not again.downloaded and again.sha256 == result.sha256


def test_truncated_download_keeps_nothing(cache: Path, tiny: ModelRecord) -> None:
    with pytest.raises(InvalidInput, match=r"truncated download.*nothing was kept"):
        fetch("tiny", downloader=downloader(PAYLOAD[:-7]))
    assert not model_path(tiny).exists() and leftovers(tiny) == []
    assert cached_model("tiny") is None


def test_wrong_checksum_keeps_nothing(cache: Path, tiny: ModelRecord) -> None:
    bad = bytes(reversed(PAYLOAD))
    with pytest.raises(InvalidInput, match="SHA-256 is .* the catalogue expects"):
        fetch("tiny", downloader=downloader(bad))
    assert not model_path(tiny).exists() and leftovers(tiny) == []


def test_offline_is_one_line_naming_the_url_and_the_manual_path(cache: Path,
                                                                tiny: ModelRecord) -> None:
    with pytest.raises(InvalidInput) as err:
        fetch("tiny", downloader=offline)
    msg = str(err.value)
    assert "\n" not in msg
    assert tiny.url in msg and "huggingface.co/someone/tiny/resolve/" + "a" * 40 in msg
    assert f"place it at {model_path(tiny)}" in msg
    assert not model_path(tiny).exists() and leftovers(tiny) == []


def test_hash_prefix_and_size_only_records(cache: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    digest = hashlib.sha256(PAYLOAD).hexdigest()
    monkeypatch.setitem(CATALOGUE, "prefix", record("prefix", sha256=digest[:16]))
    assert fetch("prefix", downloader=downloader(PAYLOAD)).sha256 == digest
    monkeypatch.setitem(CATALOGUE, "sizeonly", record("sizeonly", sha256=None))
    assert fetch("sizeonly", downloader=downloader(PAYLOAD)).sha256 == digest
    monkeypatch.setitem(CATALOGUE, "sizeonly2", record("sizeonly2", sha256=None))
    with pytest.raises(InvalidInput, match="bytes"):
        fetch("sizeonly2", downloader=downloader(PAYLOAD + b"x"))


def test_a_wrong_size_file_in_the_cache_is_never_used(cache: Path, tiny: ModelRecord) -> None:
    path = model_path(tiny)
    path.parent.mkdir(parents=True)
    path.write_bytes(PAYLOAD[:10])  # e.g. an interrupted manual copy
    with pytest.raises(InvalidInput, match="unusable.*monoplane models fetch tiny"):
        cached_model("tiny")
    assert fetch("tiny", downloader=downloader(PAYLOAD)).downloaded
    assert path.read_bytes() == PAYLOAD


def test_missing_model_names_the_fetch_command(cache: Path, tiny: ModelRecord) -> None:
    with pytest.raises(InvalidInput, match="run 'monoplane models fetch tiny'"):
        require_model("tiny")


def test_default_downloader_uses_huggingface_hub(cache: Path, tiny: ModelRecord,
                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    import huggingface_hub

    seen: dict = {}

    def fake_hf_hub_download(**kwargs) -> str:
        seen.update(kwargs)
        return str(downloader(PAYLOAD)(kwargs["repo_id"], kwargs["filename"],
                                       kwargs["revision"], Path(kwargs["local_dir"])))
    monkeypatch.setattr(huggingface_hub, "hf_hub_download", fake_hf_hub_download)
    assert fetch("tiny").downloaded
    assert seen["repo_id"] == "someone/tiny" and seen["revision"] == "a" * 40
    assert Path(seen["local_dir"]).parent == model_path(tiny).parent  # same filesystem: atomic


def test_catalogue_records_are_well_formed() -> None:
    assert set(CATALOGUE) == {"depth-anything-v2-small", "metric3d-v2-small",
                              "moge-2-vits-normal", "xfeat"}
    for rec in CATALOGUE.values():
        host = ("https://raw.githubusercontent.com/" if rec.host == "github"
                else "https://huggingface.co/")
        assert rec.url.startswith(f"{host}{rec.repo}/")
        assert rec.size and rec.sha256 and rec.licence and rec.provenance
        assert "NC" not in rec.licence.split(" ")[0]  # no non-commercial defaults
        assert "  " not in rec.summary + rec.provenance  # TOML line continuations trimmed
    assert not get_model("moge-2-vits-normal").pinned  # honest: no commit hash known
    assert get_model("depth-anything-v2-small").pinned
    with pytest.raises(ConfigError, match="catalogue models: depth-anything-v2-small"):
        get_model("nope")
    with pytest.raises(ConfigError, match="sha256"):
        record(sha256="XYZ")
    with pytest.raises(ConfigError, match="task"):
        record(task="segmentation")
    with pytest.raises(ConfigError, match="host"):
        record(host="ftp")


def test_models_cli_list_fetch_path(cache: Path, tiny: ModelRecord,
                                    monkeypatch: pytest.MonkeyPatch,
                                    capsys: pytest.CaptureFixture) -> None:
    assert main(["models", "list"]) == 0
    out = capsys.readouterr().out
    assert "depth-anything-v2-small" in out and "Apache-2.0" in out and "99 MB" in out
    assert main(["models", "path", "tiny"]) == 2
    assert "monoplane models fetch tiny" in capsys.readouterr().err
    monkeypatch.setattr(cache_mod, "_hf_download", downloader(PAYLOAD))
    assert main(["models", "fetch", "tiny"]) == 0
    out = capsys.readouterr().out
    assert hashlib.sha256(PAYLOAD).hexdigest() in out and "verified" in out
    assert main(["models", "path", "tiny"]) == 0
    assert capsys.readouterr().out.strip() == str(model_path(tiny))
    assert main(["models", "list", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows["tiny"]["cached"] and rows["tiny"]["pinned"]
    assert not rows["moge-2-vits-normal"]["cached"]
    assert rows["metric3d-v2-small"]["task"] == "both"
    monkeypatch.setattr(cache_mod, "_hf_download", offline)
    assert main(["models", "fetch", "moge-2-vits-normal"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "cannot download https://huggingface.co/" in err


def test_run_never_downloads_without_fetch(cache: Path, tiny: ModelRecord, tmp_path: Path,
                                           monkeypatch: pytest.MonkeyPatch,
                                           capsys: pytest.CaptureFixture) -> None:
    import cv2
    import numpy as np

    image = tmp_path / "photo.png"
    cv2.imwrite(str(image), np.full((24, 32, 3), 128, np.uint8))
    calls: list = []
    monkeypatch.setattr(cache_mod, "_hf_download", downloader(PAYLOAD, calls))
    out = tmp_path / "out"
    assert main(["run", str(image), "--cues", "tiny", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "monoplane models fetch tiny" in err and "--fetch" in err
    assert calls == [] and not out.exists()
    # With --fetch the download happens; the fake file is then not a loadable network.
    assert main(["run", str(image), "--cues", "tiny", "--fetch", "--out", str(out)]) == 2
    assert len(calls) == 1 and model_path(tiny).is_file() and not out.exists()
    assert "cannot load" in capsys.readouterr().err


def test_config_model_key(cache: Path, tiny: ModelRecord) -> None:
    pipe = Pipeline.from_preset(overrides=["cues.model=tiny"])
    assert pipe.config.stages["cues"][1].resolved_profile().name == "depth-anything-v2"
    with pytest.raises(ConfigError, match="either cues.model"):
        Pipeline.from_preset(overrides=["cues.model=tiny", "cues.depth_model=x.onnx"])
    with pytest.raises(ConfigError, match="unknown model"):
        Pipeline.from_preset(overrides=["cues.model=nope"])


def test_run_with_given_depth_needs_no_depth_model(cache: Path, tiny: ModelRecord,
                                                   tmp_path: Path) -> None:
    import numpy as np

    from monoplane.testing import box_frame

    frame, _ = box_frame(96, 72)
    np.save(tmp_path / "depth.npy", frame.depth)
    out = tmp_path / "out"
    # tiny's profile (depth-anything-v2) predicts no normals: they come from the given depth.
    assert main(["run", "--depth", str(tmp_path / "depth.npy"), "--cues", "tiny",
                 "--out", str(out), "--quiet"]) == 0
    doc = json.loads((out / "planes.json").read_text())
    assert len(doc["planes"]) >= 3 and not model_path(tiny).exists()
