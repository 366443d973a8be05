"""Headless 3D rendering in a child process: real pictures, and clean failures.

Rendering tests skip (with the renderer's reason) only when OpenGL/EGL cannot start at all; a
hang or a blank picture fails.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from monoplane.geometry.mesh import planar_mesh
from monoplane.report import render3d
from monoplane.report.colors import plane_palette, shade
from monoplane.report.render3d import Mesh, RenderResult, Shot, render
from monoplane.report.viewpoints import facing_triangles, orbit_viewpoints

W, H = 320, 240


def _require_gl(result: RenderResult) -> None:
    if result.reason and "OpenGL/EGL is unavailable" in result.reason:
        pytest.skip(f"no headless OpenGL here: {result.reason}")
    assert result.reason is None, result.reason


def _room_job(room):
    v, t, _, ids = planar_mesh(room, step=1)
    expected = shade(plane_palette(room.num_planes)[ids - 1] / 255.0,
                     room.params[ids - 1, :3])
    K = room.frame.K.copy()
    K[:2] *= W / room.frame.width
    bird = orbit_viewpoints(v, np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, 1.0]), W, H)[0]
    keep = facing_triangles(ids[t[:, 0]] - 1, room.params, bird.eye)
    shots = [Shot("frontal", K, np.eye(4), {0: None}),
             Shot("bird", bird.K, bird.world_to_cam, {0: keep})]
    return [Mesh(v, t, expected)], shots


@pytest.mark.render
def test_rendered_planes_match_labels_and_colours(room, tmp_path: Path) -> None:
    meshes, shots = _room_job(room)
    result = render(meshes, [], shots, tmp_path, W, H, timeout=120)
    _require_gl(result)
    img = cv2.imread(str(result.paths["frontal"]))[..., ::-1].astype(int)
    assert img.shape == (H, W, 3)
    assert img.std() > 20  # not blank
    # The frontal view uses the input camera, so each plane lands on its labelled pixels.
    labels = cv2.resize(room.labels.astype(np.uint8), (W, H), interpolation=cv2.INTER_NEAREST)
    palette = plane_palette(room.num_planes) / 255.0
    found = 0
    for i in range(room.num_planes):
        inner = cv2.erode((labels == i + 1).astype(np.uint8), np.ones((7, 7), np.uint8)) > 0
        if inner.sum() < 50:
            continue
        want = 255 * shade(palette[i][None], room.params[i, :3][None])[0]
        got = np.median(img[inner], axis=0)
        assert np.abs(got - want).max() < 12, (i + 1, got, want)
        found += 1
    assert found >= 6
    # The bird's eye view shows several planes and some background, and is not the frontal one.
    bird = cv2.imread(str(result.paths["bird"]))[..., ::-1].astype(int)
    white = np.all(bird > 245, axis=-1).mean()
    assert 0.05 < white < 0.9
    colours = {tuple(c) for c in (bird[~np.all(bird > 245, axis=-1)] // 16).tolist()}
    assert len(colours) >= 4


@pytest.mark.render
def test_egl_failure_is_reported_not_raised(room, tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    meshes, shots = _room_job(room)
    monkeypatch.setattr(render3d, "RENDER_ENV", {"EGL_PLATFORM": "x11"})
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    result = render(meshes, [], shots[:1], tmp_path, W, H, timeout=120)
    assert result.reason is not None and "crashed" in result.reason and "EGL" in result.reason
    assert result.paths == {}


def test_timeout_is_reported_not_raised(room, tmp_path: Path) -> None:
    meshes, shots = _room_job(room)
    result = render(meshes, [], shots, tmp_path, W, H, timeout=0.2)
    assert result.reason is not None and "timed out after 0.2 s" in result.reason
    assert result.paths == {}
