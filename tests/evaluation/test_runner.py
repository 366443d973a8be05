"""The evaluation runner end to end on tiny synthetic scenes."""

from __future__ import annotations

import json

import numpy as np
import pytest

from monoplane.datamodel import Frame, Reconstruction
from monoplane.errors import ConfigError, InvalidInput, StageError
from monoplane.evaluation.runner import (
    PAPER_PRESETS,
    Method,
    evaluate,
    format_table,
    parse_size,
    resolve_methods,
)
from monoplane.synth import generate

SIZE = (128, 96)


def oracle(frame: Frame, seed: int) -> Reconstruction:
    """Returns the exact ground truth of the scene the frame came from (seed = scene seed)."""
    view = generate(seed, "mild", width=frame.width, height=frame.height).views[0]
    return Reconstruction(frame=frame, labels=view.gt_labels, params=view.gt_params)


def broken(frame: Frame, seed: int) -> Reconstruction:
    raise StageError("labeler", "broken", RuntimeError("no luck"))


def test_ground_truth_scores_perfectly_and_failures_score_as_empty() -> None:
    methods = [Method("oracle", "baseline", oracle), Method("broken", "baseline", broken)]
    with pytest.warns(UserWarning, match="broken failed"):
        res = evaluate(methods, n=2, level="mild", seed=5, size=SIZE, progress=False)
    best, failed = res.methods
    assert [f.scene_seed for f in best.frames] == [5, 6]
    assert (best.voi, best.ri, best.sc) == pytest.approx((0.0, 1.0, 1.0))
    # The GT planes through exact metric params: every plane recalled at every threshold.
    assert best.recall == pytest.approx([1.0, 1.0, 1.0])
    assert best.n_failed == 0
    assert failed.n_failed == 2 and failed.planes_per_frame == 0
    assert failed.recall == [0.0, 0.0, 0.0]
    assert failed.sc < 1.0 and failed.voi > 0.0
    table = format_table(res)
    assert "oracle" in table and "broken (2 failed)" in table and "R@0.05m" in table


def test_open3d_baseline_end_to_end_and_json_ready() -> None:
    methods = resolve_methods(baselines=["open3d-ransac"])
    res = evaluate(methods, n=2, level="clean", seed=0, size=SIZE, progress=False)
    (m,) = res.methods
    assert len(m.frames) == 2 and m.n_failed == 0
    assert 0.0 <= m.voi < 3.0 and 0.5 < m.ri <= 1.0 and 0.3 < m.sc <= 1.0
    assert m.recall[0] <= m.recall[1] <= m.recall[2]
    assert m.seconds_per_frame > 0
    data = json.loads(json.dumps(res.to_dict()))
    assert data["settings"] == {"level": "clean", "n": 2, "seed": 0, "width": 128,
                                "height": 96, "thresholds": [0.05, 0.1, 0.6]}
    assert data["methods"][0]["name"] == "open3d-ransac"
    assert len(data["methods"][0]["frames"]) == 2


def merge_all(frame: Frame, seed: int) -> Reconstruction:
    """One plane over the whole image: scores depend on the scene only."""
    view = generate(seed, "mild", width=frame.width, height=frame.height).views[0]
    return Reconstruction(frame=frame, labels=np.ones(frame.shape, dtype=np.int32),
                          params=view.gt_params[:1])


def test_same_arguments_give_the_same_scores() -> None:
    methods = [Method("merge-all", "baseline", merge_all)]
    a = evaluate(methods, n=2, level="mild", seed=3, size=SIZE, progress=False).methods[0]
    b = evaluate(methods, n=2, level="mild", seed=3, size=SIZE, progress=False).methods[0]
    c = evaluate(methods, n=2, level="mild", seed=4, size=SIZE, progress=False).methods[0]
    assert (a.voi, a.ri, a.sc, a.recall) == (b.voi, b.ri, b.sc, b.recall)
    assert a.voi != c.voi  # scene 3 is only in the first run
    assert 0.0 < a.sc < 1.0 and a.voi > 0.0


def test_preset_runs_through_the_pipeline() -> None:
    methods = resolve_methods(presets=["monoplane"])
    res = evaluate(methods, n=1, level="mild", seed=0, size=SIZE, progress=False)
    m = res.methods[0]
    assert m.kind == "preset" and m.n_failed == 0 and m.planes_per_frame >= 1
    assert m.sc > 0.3


def test_all_lists_the_paper_rows_then_the_baselines() -> None:
    names = [m.name for m in resolve_methods(all_methods=True)]
    assert names[:6] == list(PAPER_PRESETS)
    assert "open3d-ransac" in names[6:]


def test_bad_requests_are_user_errors() -> None:
    with pytest.raises(InvalidInput, match="nothing to evaluate"):
        resolve_methods()
    with pytest.raises(ConfigError):
        resolve_methods(baselines=["nope"])
    methods = [Method("oracle", "baseline", oracle)]
    with pytest.raises(InvalidInput):
        evaluate(methods, n=0, progress=False)
    with pytest.raises(InvalidInput, match="level"):
        evaluate(methods, n=1, level="extreme", progress=False)


@pytest.mark.parametrize("text, expected", [("256x192", (256, 192)), ("640X480", (640, 480))])
def test_parse_size(text: str, expected: tuple[int, int]) -> None:
    assert parse_size(text) == expected


@pytest.mark.parametrize("text", ["256", "axb", "8x8", "256x192x3"])
def test_parse_size_rejects(text: str) -> None:
    with pytest.raises(InvalidInput):
        parse_size(text)


def test_each_method_warms_up_once_untimed_before_the_timed_runs() -> None:
    calls: list[int] = []

    def counting(frame: Frame, seed: int) -> Reconstruction:
        calls.append(seed)
        return oracle(frame, seed)

    res = evaluate([Method("counting", "baseline", counting)], n=2, level="mild", seed=7,
                   size=SIZE, progress=False)
    assert calls == [7, 7, 8]  # the warm-up on the first scene, then one timed run per scene
    assert len(res.methods[0].frames) == 2


def test_the_old_name_of_frame_scores_still_works_with_a_warning() -> None:
    import monoplane.evaluation.runner as runner

    with pytest.warns(DeprecationWarning, match="FrameScores"):
        assert runner.FrameResult is runner.FrameScores
