"""Shared thresholds are declared once ([ransac]) and reach every stage that uses them."""

from __future__ import annotations

import numpy as np
import pytest

from monoplane import detect_planes
from monoplane.host.pipeline import Pipeline
from monoplane.host.registry import get_plugin_manager
from monoplane.stages.graph_refiner import GraphCrfRefiner
from monoplane.stages.labelers import ProximityGraphCutLabeler
from monoplane.stages.samplers import NormalConsistentSampler
from monoplane.stages.scorers import MsacNormalScorer
from monoplane.testing import box_frame, stage_plugin

#: kind -> the thresholds each of its calls received.
SEEN: dict[str, set[tuple[float, float]]] = {}


def _record(kind: str, params: object) -> None:
    SEEN.setdefault(kind, set()).add((params.epsilon, params.epsilon_n_deg))


class SpySampler(NormalConsistentSampler):
    name = "spy-sampler"

    def sample(self, cloud, pool, count, rng, params):
        _record("sampler", params)
        return super().sample(cloud, pool, count, rng, params)


class SpyScorer(MsacNormalScorer):
    name = "spy-scorer"

    def score(self, cloud, pool, planes, model_normals, params):
        _record("scorer", params)
        return super().score(cloud, pool, planes, model_normals, params)


class SpyLabeler(ProximityGraphCutLabeler):
    name = "spy-labeler"

    def label(self, cloud, graph, pool, plane, model_normal, params, context=None):
        _record("labeler", params)
        return super().label(cloud, graph, pool, plane, model_normal, params, context)


class SpyRefiner(GraphCrfRefiner):
    name = "spy-refiner"

    def refine_cloud(self, cloud, graph, labels, planes, params):
        _record("refiner", params)
        return super().refine_cloud(cloud, graph, labels, planes, params)


# The range preset lowers ε to the measured depth noise (ransac.noise_factor), which the
# exact box frame has none of: off here, tested on its own below.
SPY_OVERRIDES = ["sampler.plugin=spy-sampler", "scorer.plugin=spy-scorer",
                 "labeler.plugin=spy-labeler", "refiner.plugin=spy-refiner",
                 "ransac.epsilon=0.03", "ransac.epsilon_n_deg=12.5", "ransac.noise_factor=0"]


@pytest.fixture
def spies():
    SEEN.clear()
    yield get_plugin_manager(autoload=False, extra_plugins=(stage_plugin(
        monoplane_register_samplers=[SpySampler], monoplane_register_scorers=[SpyScorer],
        monoplane_register_labelers=[SpyLabeler], monoplane_register_refiners=[SpyRefiner]),))
    SEEN.clear()


@pytest.mark.parametrize("preset", ["range", "cloud"])
def test_set_ransac_epsilon_reaches_every_stage_on_frames(spies, preset: str) -> None:
    frame, _ = box_frame()
    Pipeline.from_preset(preset, overrides=SPY_OVERRIDES, pm=spies).run(frame)
    assert SEEN == {kind: {(0.03, 12.5)}
                    for kind in ("sampler", "scorer", "labeler", "refiner")}


def test_the_noise_limited_epsilon_reaches_every_stage_after_the_first_search(spies) -> None:
    # Exact depth: the first search's planes show no noise, so the search runs again with ε at
    # its floor (a tenth), and the refiner gets the thresholds of that second search.
    frame, _ = box_frame()
    Pipeline.from_preset("range", overrides=[*SPY_OVERRIDES, "ransac.noise_factor=3"],
                         pm=spies).run(frame)
    rounded = {kind: {(round(e, 6), n) for e, n in seen} for kind, seen in SEEN.items()}
    for kind in ("sampler", "scorer", "labeler"):
        assert rounded[kind] == {(0.03, 12.5), (0.003, 12.5)}
    assert rounded["refiner"] == {(0.003, 12.5)}


def test_set_ransac_epsilon_reaches_every_stage_on_clouds(spies) -> None:
    frame, _ = box_frame()
    points = frame.points()[frame.depth > 0]
    detect_planes(points, overrides=SPY_OVERRIDES, pm=spies)
    assert SEEN == {kind: {(0.03, 12.5)}
                    for kind in ("sampler", "scorer", "labeler", "refiner")}


def test_the_refiner_has_no_thresholds_of_its_own() -> None:
    keys = {key for key, *_ in GraphCrfRefiner.parameters()}
    assert not keys & {"epsilon", "epsilon_n_deg"}


def test_the_graph_refiner_follows_the_shared_epsilon() -> None:
    """A point 0.025 from a plane is non-planar at ε = 0.02 and on the plane at ε = 0.03."""
    from monoplane.contracts import RansacParams
    from monoplane.testing import cloud_from_arrays

    points = np.array([[0.0, 0.0, 0.025]])
    cloud = cloud_from_arrays(points, np.array([[0.0, 0.0, 1.0]]))
    planes = np.array([[0.0, 0.0, 1.0, 0.0]])
    refiner = GraphCrfRefiner(GraphCrfRefiner.Config(normal_weight=0.0))
    tight = refiner.unary(cloud, planes, RansacParams(epsilon=0.02))
    loose = refiner.unary(cloud, planes, RansacParams(epsilon=0.03))
    assert tight[0].argmin() == 0 and loose[0].argmin() == 1
