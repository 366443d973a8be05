"""Which inputs the default preset treats as a depth-only sensor frame, end to end through the
pipeline: normals estimated from a sensor's metric depth only
(``Frame.normals_from_sensor_depth``), never normals given with the frame, normals estimated
from a relative or a network's depth, or a cloud's. On such a frame alone the proximity
labeler gates normals, the RANSAC searches the pixel lattice (``ransac.sampling = "auto"``)
and the cue stage fits normals with box sums (``cues.normals_method = "auto"``)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from monoplane import Pipeline
from monoplane.datamodel import Frame
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.normals import normals_from_depth
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


@pytest.fixture
def lattices(monkeypatch: pytest.MonkeyPatch) -> list[bool]:
    """Whether each cloud the RANSAC builds from a frame is the pixel lattice."""
    seen: list[bool] = []
    from_frame = PlaneCloud.from_frame.__func__  # type: ignore[attr-defined]

    def record(cls, *args, **kwargs) -> PlaneCloud:
        cloud = from_frame(cls, *args, **kwargs)
        seen.append(cloud.lattice is not None)
        return cloud

    monkeypatch.setattr(PlaneCloud, "from_frame", classmethod(record))
    return seen


def room() -> Frame:
    """A small synthetic room with depth, normals and colour (monocular-like: relative depth)."""
    return generate(0, level="mild", width=64, height=48).views[0].frame


def sensor_room() -> Frame:
    """:func:`room` as a depth-only sensor frame: metric depth, no normals, no colour."""
    return room().with_(rgb=None, normals=None, depth_kind="metric")


def test_only_normals_from_a_sensors_depth_are_gated(gates: list[float],
                                                     lattices: list[bool]) -> None:
    pipe = Pipeline.from_preset("monoplane-nocrf")
    rec = pipe.run(sensor_room())                    # normals from the sensor's depth
    assert rec.frame.normals_from_sensor_depth
    assert gates and set(gates) == {GATE}
    assert lattices == [True]
    for frame in (room(),                            # normals given with the frame
                  room().with_(normals=None)):       # normals from a relative depth
        gates.clear()
        lattices.clear()
        rec = pipe.run(frame)
        assert not rec.frame.normals_from_sensor_depth
        assert gates and set(gates) == {np.pi}
        assert lattices == [False]


def test_the_paper_preset_keeps_the_papers_search_on_sensor_frames(
        gates: list[float], lattices: list[bool]) -> None:
    rec = Pipeline.from_preset("monoplane-paper").run(sensor_room())
    assert rec.frame.normals_from_sensor_depth
    assert gates and set(gates) == {np.pi}
    assert lattices == [False]
    assert np.array_equal(rec.frame.normals,
                          normals_from_depth(rec.frame.depth, rec.frame.K, method="gated"))


@pytest.mark.parametrize(("kind", "method"), [("metric", "box"), ("relative", "gated")])
def test_auto_normals_fit_box_sums_on_a_sensors_depth_only(kind: str, method: str) -> None:
    frame = room().with_(rgb=None, normals=None, depth_kind=kind)
    got = Pipeline.from_preset("monoplane").run(frame).frame.normals
    assert np.array_equal(got, normals_from_depth(frame.depth, frame.K, method=method))
    other = normals_from_depth(frame.depth, frame.K, method={"box": "gated"}.get(method, "box"))
    assert not np.array_equal(got, other)   # the two fits differ on this frame


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
