"""Which inputs the proximity labeler's normal gate reaches, end to end through the pipeline:
normals estimated from a sensor's depth only (``PlaneCloud.normals_from_sensor_depth``), never
normals given with the frame, normals estimated from a network's depth, or a cloud's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from monoplane import Pipeline
from monoplane.datamodel import Frame
from monoplane.stages.labelers import ProximityGraphCutLabeler
from monoplane.synth import generate

GATE = np.deg2rad(20.0)  # the default preset's normal_gate_deg


@pytest.fixture
def gates(monkeypatch: pytest.MonkeyPatch) -> list[float]:
    """The gate (radians) of every label call, recorded as the labeler computes it."""
    seen: list[float] = []
    gate = ProximityGraphCutLabeler._gate

    def record(self: ProximityGraphCutLabeler, cloud) -> float:
        seen.append(gate(self, cloud))
        return seen[-1]

    monkeypatch.setattr(ProximityGraphCutLabeler, "_gate", record)
    return seen


def room() -> Frame:
    """A small synthetic room with depth, normals and colour."""
    return generate(0, level="mild", width=64, height=48).views[0].frame


def test_only_normals_from_a_sensors_depth_are_gated(gates: list[float]) -> None:
    pipe = Pipeline.from_preset("monoplane-nocrf")
    frame = room()
    pipe.run(frame.with_(rgb=None, normals=None))   # depth-only: normals from the sensor's depth
    assert gates and set(gates) == {GATE}
    gates.clear()
    pipe.run(frame)                                  # normals given with the frame
    assert gates and set(gates) == {np.pi}


def test_a_cloud_is_not_gated(gates: list[float]) -> None:
    frame = room()
    points = frame.depth[..., None] * np.linalg.solve(
        frame.K, np.stack([*np.meshgrid(np.arange(64), np.arange(48)), np.ones((48, 64))],
                          axis=-1)[..., None])[..., 0]
    Pipeline.from_preset("monoplane-nocrf").run_cloud(points[frame.depth > 0])
    assert gates and set(gates) == {np.pi}


def test_normals_from_a_networks_depth_are_not_gated(gates: list[float],
                                                     tmp_path: Path) -> None:
    pytest.importorskip("onnx")
    pytest.importorskip("onnxruntime")
    from monoplane.cues.tiny_models import tiny_depth_model

    # A MiDaS-like stand-in without a normals network predicting a constant disparity (a wall
    # facing the camera): the cue stage estimates the normals from the network's depth.
    model = tiny_depth_model(tmp_path / "tiny.onnx", scale=0.0, offset=2.0)
    pipe = Pipeline.from_preset("monoplane-nocrf", overrides=[
        "cues.profile=midas", f"cues.depth_model={model}", "cues.input_size=[48,64]"])
    rec = pipe.run(room().with_(depth=None, normals=None))
    assert rec.frame.depth_predicted and rec.frame.normals_from_depth
    assert gates and set(gates) == {np.pi}
