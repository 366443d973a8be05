"""Views segmented while SfM runs: the single-view stages are free of the depth's scale, the
rescaled result equals segmenting the scale-aligned depth, and the view pool's host helps."""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np
import pytest

from monoplane.contracts import Matcher
from monoplane.evaluation.twoview import ground_truth_sfm
from monoplane.hookspecs import hookimpl
from monoplane.host.pipeline import Pipeline
from monoplane.host.registry import get_plugin_manager
from monoplane.host.view_pool import ViewPool
from monoplane.multiview import (
    matcher_keeps_intrinsics,
    reconstruct_multiview,
    rescale_reconstruction,
)
from monoplane.synth.sequence import generate_sequence

#: The fuser may add planes recovered from other views to a view's labels; these tests compare
#: the labels as the single-view stages left them.
AS_SEGMENTED = ["fuser.recover_planes=false"]


@pytest.fixture(scope="module")
def walk():
    return generate_sequence(4, 3, "walk", level="mild")


def _oracle_pipeline(synth, changed_k: dict[int, np.ndarray] | None = None) -> Pipeline:
    """A pipeline whose matcher returns the true cameras (``changed_k``: a new K per view)
    and claims to keep the frames' K, so that the driver segments the views early."""

    class Oracle(Matcher):
        name = "oracle"
        calls = 0

        @classmethod
        def fixed_intrinsics_config(cls, config):
            return config

        def match(self, frames):
            Oracle.calls += 1
            sfm = ground_truth_sfm(synth)
            cams = [replace(c, K=changed_k[v]) if changed_k and v in changed_k else c
                    for v, c in enumerate(sfm.cameras)]
            return replace(sfm, cameras=cams)

    class Plugin:
        @hookimpl
        def monoplane_register_matchers(self):
            return [Oracle]

    pm = get_plugin_manager(autoload=False, extra_plugins=(Plugin(),))
    return Pipeline.from_preset("monoplane", overrides=["matcher.plugin=oracle", *AS_SEGMENTED],
                                pm=pm)


def test_single_view_stages_are_free_of_the_depth_scale(walk) -> None:
    pipe = Pipeline.from_preset("monoplane")
    for view in walk.views[:2]:
        frame = pipe.prepare(view.frame)
        base = pipe.segment(frame)
        assert base.num_planes >= 3
        for s in (0.37, 13.3):
            scaled = frame.with_(depth=(frame.depth * s).astype(np.float32))
            direct = pipe.segment(scaled)
            np.testing.assert_array_equal(direct.labels, base.labels)
            rescaled = rescale_reconstruction(base, scaled, s)
            assert rescaled.frame is scaled
            np.testing.assert_array_equal(rescaled.labels, direct.labels)
            np.testing.assert_allclose(rescaled.planes, direct.planes, rtol=1e-5, atol=1e-4)
            np.testing.assert_allclose(rescaled.rmse, direct.rmse, rtol=1e-4, atol=1e-9)


def test_early_views_equal_segmenting_the_aligned_depth(walk) -> None:
    pipe = _oracle_pipeline(walk)
    assert matcher_keeps_intrinsics(pipe)
    out = reconstruct_multiview([v.frame for v in walk.views], pipe, workers=1)
    assert len(out.scene.views) == 3 and out.timings["per_view"] > 0
    for rec, s in zip(out.fused.views, out.scene.scales, strict=True):
        assert rec.frame.depth_units == out.units
        # The aligned frame, segmented from scratch, gives exactly the same labels.
        direct = pipe.segment(rec.frame)
        np.testing.assert_array_equal(rec.labels, direct.labels)
        np.testing.assert_allclose(rec.planes, direct.planes, rtol=1e-5, atol=1e-4)
        assert s != pytest.approx(1.0, abs=1e-3)  # mild cues: the scale really changed


def test_a_view_whose_k_changed_is_segmented_again(walk) -> None:
    K = walk.views[1].frame.K.copy()
    K[0, 0] *= 1.08
    K[1, 1] *= 1.08
    pipe = _oracle_pipeline(walk, changed_k={1: K})
    out = reconstruct_multiview([v.frame for v in walk.views], pipe, workers=1)
    rec = out.fused.views[1]
    np.testing.assert_allclose(rec.frame.K, K)
    direct = pipe.segment(pipe.prepare(rec.frame))
    np.testing.assert_array_equal(rec.labels, direct.labels)
    np.testing.assert_allclose(rec.planes, direct.planes, rtol=1e-5, atol=1e-4)


def test_matcher_keeps_intrinsics_follows_its_config() -> None:
    from monoplane.multiview import hold_intrinsics_fixed

    pipe = Pipeline.from_preset("monoplane")
    assert not matcher_keeps_intrinsics(pipe)
    assert hold_intrinsics_fixed(pipe)
    assert matcher_keeps_intrinsics(pipe)


def pid_of(frame) -> tuple[str, int]:
    """A view task that says where it ran (module level: workers import it)."""
    if frame.name == "fail":
        raise ValueError("no such view")
    return frame.name, os.getpid()


def test_view_pool_workers_host_and_errors(walk) -> None:
    pipe = Pipeline.from_preset("monoplane")
    frames = [v.frame for v in walk.views]
    with ViewPool(pipe, 2, len(frames)) as pool:
        assert pool.pool is not None and pool.pool.workers == 1  # the host is the other one
        tasks = pool.submit(pid_of, frames)
        tasks._thread.join()  # the worker alone takes every view while the host is away
        done = tasks.result()
        assert [name for name, _ in done] == [f.name for f in frames]
        assert all(pid != os.getpid() for _, pid in done)
        bad = [frames[0], frames[1].with_(name="fail"), frames[2]]
        with pytest.raises(ValueError, match="no such view"):
            pool.map(pid_of, bad)
    with ViewPool(pipe, 1, len(frames)) as alone:
        assert alone.pool is None
        assert {pid for _, pid in alone.map(pid_of, frames)} == {os.getpid()}


def test_view_pool_falls_back_to_this_process_when_workers_cannot_start(walk, capsys) -> None:
    pipe = _oracle_pipeline(walk)  # its matcher plugin is unknown to a fresh worker
    frames = [v.frame for v in walk.views]
    with ViewPool(pipe, 2, len(frames)) as pool:
        done = pool.map(pid_of, frames)
        assert pool.pool is None
    assert {pid for _, pid in done} == {os.getpid()}
    assert "per-view workers could not start" in capsys.readouterr().err


def test_workers_and_sfm_overlap_give_the_in_process_labels(walk) -> None:
    from monoplane.multiview import hold_intrinsics_fixed

    pipe = Pipeline.from_preset("monoplane", overrides=AS_SEGMENTED)
    hold_intrinsics_fixed(pipe)
    frames = [v.frame for v in walk.views]
    alone = reconstruct_multiview(frames, pipe, workers=1)
    shared = reconstruct_multiview(frames, pipe, workers=2)
    assert alone.frame_indices == shared.frame_indices == [0, 1, 2]
    for a, b in zip(alone.fused.views, shared.fused.views, strict=True):
        np.testing.assert_array_equal(a.labels, b.labels)  # SfM does not touch the labels
