"""The three reports: files written, figures referenced, tables filled, failures explained."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from report_fixtures import make_scene

from monoplane.datamodel import Reconstruction
from monoplane.report import write_eval_report, write_frame_report, write_scene_report


def _assert_links_resolve(page: Path) -> str:
    text = page.read_text()
    srcs = re.findall(r'src="([^"]+)"', text)
    assert srcs, "report has no figures"
    for src in srcs:
        if src.startswith("data:"):  # the 3D view's embedded .glb
            continue
        assert (page.parent / src).is_file(), src
    return text


def test_frame_report_without_3d(room, tmp_path: Path) -> None:
    page = write_frame_report(room, tmp_path / "rep", render_3d=False)
    assert page == tmp_path / "rep" / "report.html"
    text = _assert_links_resolve(page)
    for name in ("input.png", "depth.png", "normals.png", "labels_overlay.png",
                 "depth_compare.png", "summary.png"):
        assert (page.parent / name).is_file()
    assert "3D views were not requested" in text
    assert 'src="summary.png"' in text  # shown, not only mentioned
    assert (page.parent / "planes.glb").is_file() and 'id="view3d"' in text
    assert "synthetic test room" in text  # frame notes
    assert text.count("class=\"swatch\"") == room.num_planes
    # Floor normal (0, -cos 6°, -sin 6°) in the plane table.
    assert "(+0.000, -0.995, -0.105)" in text


def test_frame_report_degrades_when_rendering_raises(room, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    import monoplane.report.frame

    def broken(*args, **kwargs):
        raise RuntimeError("no pictures today\nsecond line of the message")

    monkeypatch.setattr(monoplane.report.frame, "render", broken)
    page = write_frame_report(room, tmp_path)
    text = _assert_links_resolve(page)
    assert "3D rendering failed (RuntimeError: no pictures today)" in text
    assert "second line" not in text
    for name in ("labels_overlay.png", "depth_compare.png", "summary.png"):
        assert (tmp_path / name).is_file()
    assert not list(tmp_path.glob("3d_*.png"))


def test_frame_report_with_3d(room, tmp_path: Path) -> None:
    page = write_frame_report(room, tmp_path)
    text = _assert_links_resolve(page)
    for view in ("frontal", "birdseye", "oblique"):
        for kind in ("planes", "texture"):
            assert f'src="3d_{view}_{kind}.png"' in text
    assert "missing or incomplete" not in text


def test_scene_report_without_3d(tmp_path: Path) -> None:
    scene = make_scene(2)
    page = write_scene_report(scene, tmp_path, render_3d=False)
    text = _assert_links_resolve(page)
    assert "view2_labels.png" in text
    assert 'src="summary.png"' in text and (tmp_path / "scene.glb").is_file()
    assert text.count("class=\"swatch\"") == scene.planes.shape[0]
    assert "3D views were not requested" in text


def test_scene_label_maps_use_global_ids() -> None:
    from monoplane.report.scene import global_label_maps

    scene = make_scene(2)
    maps = global_label_maps(scene)
    G = scene.planes.shape[0]
    for rec, links, lab in zip(scene.views, scene.links, maps, strict=True):
        for local, g in links.items():
            assert np.all(lab[rec.labels == local] == g + 1)
        unlinked = [lo for lo in range(1, rec.num_planes + 1) if lo not in links]
        for lo in unlinked:
            assert np.all(lab[rec.labels == lo] > G)


def test_scene_report_with_3d(tmp_path: Path) -> None:
    page = write_scene_report(make_scene(3), tmp_path)
    text = _assert_links_resolve(page)
    assert text.count("scene3d_") >= 6 and "missing or incomplete" not in text


def test_eval_report(tmp_path: Path) -> None:
    from monoplane.evaluation.runner import Method, evaluate

    def everything_one_plane(frame, seed):
        from monoplane.geometry.planes import fit_plane

        plane, rmse = fit_plane(frame.points()[frame.valid])
        return Reconstruction(frame=frame, labels=frame.valid.astype(np.int32),
                              planes=plane[None], rmse=np.array([rmse]))

    methods = [Method("one-plane", "baseline", everything_one_plane)]
    results = evaluate(methods, n=3, level="mild", size=(64, 48), progress=False)
    page = write_eval_report(results, tmp_path, methods=methods)
    text = _assert_links_resolve(page)
    assert "case_one-plane_best.png" in text and "case_one-plane_worst.png" in text
    assert "one-plane" in text and "SC ↑" in text
    sc = sorted(f.sc for f in results.methods[0].frames)
    assert f"SC {sc[-1]:.3f}" in text and f"SC {sc[0]:.3f}" in text
    # Without the methods the report still works and says what is missing.
    page = write_eval_report(results, tmp_path / "bare")
    assert "ground truth only" in page.read_text()


def test_frame_report_without_planes_or_colour(room, tmp_path: Path) -> None:
    frame = room.frame.with_(rgb=None)
    empty = Reconstruction(frame=frame, labels=np.zeros(frame.shape, np.int32),
                           planes=np.zeros((0, 4)))
    text = _assert_links_resolve(write_frame_report(empty, tmp_path))
    assert "no planar surface to render in 3D" in text
    assert "0 planes" in text


def test_batch_reports_share_one_viewer_and_the_index_links_the_3d_views(
        sample_dir: Path, tmp_path: Path) -> None:
    import shutil

    from monoplane.batch import run_batch
    from monoplane.report.viewer import VIEWER_SCRIPT

    frames = tmp_path / "frames"
    shutil.copytree(sample_dir, frames / "a", ignore=shutil.ignore_patterns("frames"))
    out = tmp_path / "out"
    run_batch(frames, out, workers=1, report=True, progress=False)
    page = (out / "a" / "report.html").read_text()
    src = re.search(r'<script src="([^"]+)"', page).group(1)
    assert src == f"../index_files/viewer/{VIEWER_SCRIPT}"
    assert (out / "a" / src).resolve().is_file() and not (out / "a" / "viewer").exists()
    index = (out / "index.html").read_text()
    assert 'href="a/report.html#view3d"' in index
    assert (out / "a" / "planes.glb").is_file()
