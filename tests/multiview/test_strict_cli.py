"""``monoplane multiview`` with a view no method can place: named in the warning and in
scene.json; ``--strict`` makes it a one-line error that leaves no output folder."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from monoplane.cli import main
from monoplane.synth.sequence import generate_sequence


def _write_views(tmp_path: Path) -> list[str]:
    synth = generate_sequence(1, 3, "star", level="clean", width=320, height=240)
    args: list[str] = []
    depths: list[str] = []
    for k, view in enumerate(synth.views):
        rgb = view.frame.rgb if k < 2 else np.full_like(view.frame.rgb, 128)  # view 2: blank
        image = tmp_path / f"v{k}.png"
        cv2.imwrite(str(image), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        np.save(tmp_path / f"d{k}.npy", view.frame.depth)
        args.append(str(image))
        depths.append(str(tmp_path / f"d{k}.npy"))
    K = synth.views[0].frame.K
    return [*args, "--depth", *depths, "--intrinsics",
            f"{K[0, 0]},{K[1, 1]},{K[0, 2]},{K[1, 2]}", "--set", "cues.plugin=given",
            "--set", "refiner.plugin=none", "--workers", "1", "--quiet"]


def test_an_unplaceable_view_is_named_and_strict_fails_cleanly(tmp_path: Path, capsys) -> None:
    argv = _write_views(tmp_path)
    out = tmp_path / "scene"
    assert main(["multiview", *argv, "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "v2 (" in err and "left out" in err
    doc = json.loads((out / "scene.json").read_text())
    assert doc["unregistered"] == ["v2"]
    assert "v2" in doc["unregistered_reasons"]
    assert len(doc["cameras"]) == 2
    strict_out = tmp_path / "strict"
    assert main(["multiview", *argv, "--out", str(strict_out), "--strict"]) != 0
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("monoplane: error: ") and "could not register 1 of 3 images: v2" in err
    assert not strict_out.exists()
    # The textureless view did not stop SfM from building the others' model.
    methods = [c["registration"]["method"] for c in doc["cameras"]]
    assert methods == ["sfm", "sfm"]
