"""Frames that carry depth and normals skip the cue provider (whatever the config names)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from monoplane import Pipeline
from monoplane.contracts import CueProvider, Stage
from monoplane.cues.given import use_given_cues
from monoplane.datamodel import pixel_rays
from monoplane.errors import InvalidInput, StageError
from monoplane.hookspecs import hookimpl
from monoplane.host.registry import get_plugin_manager
from monoplane.testing import box_frame


@dataclass
class _NoConfig:
    pass


class ExplodingCues(CueProvider):
    """A provider that must never run on complete frames."""

    name = "exploding"
    Config = _NoConfig

    def provide(self, frame):
        raise AssertionError("provide() called on a frame that has its cues")


class _Plugin:
    @hookimpl
    def monoplane_register_cue_providers(self) -> list[type[Stage]]:
        return [ExplodingCues]


def complete_frame():
    frame, _ = box_frame(96, 72)
    flipped = frame.normals.copy()
    flipped[:10] *= -1  # given normals facing away from the camera get flipped
    return frame.with_(normals=flipped)


def test_complete_frames_skip_the_provider() -> None:
    pm = get_plugin_manager()
    pm.register(_Plugin())
    pipe = Pipeline.from_preset(overrides=["cues.plugin=exploding"], pm=pm)
    rec = pipe.run(complete_frame())
    assert rec.num_planes >= 3
    assert "cues" in rec.timings
    with pytest.raises(StageError, match="provide"):
        pipe.run(complete_frame().with_(normals=None))


def test_uncached_catalogue_model_is_not_needed_for_complete_frames(
        tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("MONOPLANE_CACHE", str(tmp_path / "empty"))
    pipe = Pipeline.from_preset(overrides=["cues.model=moge-2-vits-normal"])
    assert pipe.run(complete_frame()).num_planes >= 3
    with pytest.raises(Exception, match="monoplane models fetch moge-2-vits-normal"):
        pipe.run(complete_frame().with_(depth=None, normals=None,
                                        rgb=np.zeros((72, 96, 3), np.uint8)))


def test_use_given_cues_orients_and_masks() -> None:
    frame = complete_frame()
    depth = frame.depth.copy()
    depth[-1] = 0
    out = use_given_cues(frame.with_(depth=depth))
    rays = pixel_rays(frame.K, frame.height, frame.width)
    assert np.all(np.sum(out.normals * rays, axis=-1) <= 1e-6)
    assert np.all(out.normals[-1] == 0)
    assert any("flipped" in n for n in out.notes)
    with pytest.raises(InvalidInput, match="both"):
        use_given_cues(frame.with_(normals=None))


def test_given_provider_still_recomputes_normals_when_asked() -> None:
    pipe = Pipeline.from_preset(overrides=["cues.plugin=given", "cues.recompute_normals=true"])
    cues = pipe.stage("cues", CueProvider)
    frame = complete_frame()
    assert cues.needs_cues(frame)
    assert any("estimated from depth" in n for n in pipe.prepare(frame).notes)


def test_given_cues_kernel_matches_face_camera_and_masking() -> None:
    # Reference: the numpy composition the kernel fuses, compared bit for bit.
    from monoplane.cues.transforms import face_camera

    rng = np.random.default_rng(3)
    frame = complete_frame()
    normals = rng.normal(size=frame.normals.shape).astype(np.float32)
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    normals[5, :7] = 0.0
    depth = frame.depth.copy()
    depth[::3, ::5] = 0
    out = use_given_cues(frame.with_(depth=depth, normals=normals))
    oriented = face_camera(normals, frame.K)
    expected = np.where((depth > 0)[..., None], oriented, 0).astype(np.float32)
    np.testing.assert_array_equal(out.normals, expected)
    flipped = int(np.sum(np.any(oriented != normals, axis=-1)))
    assert any(note.startswith(f"normals: {flipped} given normals") for note in out.notes)
