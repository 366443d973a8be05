"""Binary inlier labelers for one plane hypothesis.

* ``threshold``: vanilla RANSAC, inliers are the points with φ < ε; energy = −|inliers|.
* ``graph-cut``: GC-RANSAC with the paper's truncated-L2 data term and a constant Potts
  pairwise term (cut cost 1, both-outliers cost ½(f(0,p) + f(0,q))), E = (1-λ)E_d + λE_s;
  by default E_s is divided by the mean degree k̄ of the kNN graph
  (:func:`~monoplane.graphcut.degree_normalisation`): unnormalised, on a dense graph the
  smoothness term outweighs the data term k̄ times more than λ says and a plane absorbs strips
  of its neighbours.
* ``proximity-graph-cut``: MonoPlane's labeler (§III-B2): the data term adds the normal energy
  E_n and the cut cost of an edge is 0.5 + k_p + k_c + k_n (eqs. kp, kc, kn), so
  E = (1-λ)E_d + (1-λ)E_n + λE_s. The colour term is dropped when the cloud has no colour.

The graph cuts run only on the kNN subgraph of the points still in the pool.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.graph import NeighbourGraph
from monoplane.graphcut import (
    data_costs,
    degree_normalisation,
    minimize_gc_ransac,
    proximity_weights,
)
from monoplane.hookspecs import hookimpl
from monoplane.stages.base import (
    Labeler,
    Labeling,
    ProximityAffinities,
    RansacParams,
    Stage,
    param,
)


def _pool_distances(cloud: PlaneCloud, pool: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """(M,) distances of the pool's points to ``plane`` (normalised frame)."""
    return np.abs(cloud.points[pool] @ plane[:3] + plane[3])


class ThresholdLabeler(Labeler):
    """Vanilla RANSAC labelling: inlier iff the point-to-plane distance is below ε."""

    name = "threshold"

    def label(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
              plane: np.ndarray, model_normal: np.ndarray, params: RansacParams) -> Labeling:
        """See :meth:`monoplane.stages.base.Labeler.label`; energy is −(inlier count)."""
        inliers = _pool_distances(cloud, pool, plane) < params.epsilon
        return Labeling(inliers=inliers, energy=-float(inliers.sum()))


@dataclass
class GraphCutConfig:
    """Parameters of the GC-RANSAC labeler."""

    lambda_: float = param(0.95, "smoothness weight λ in E = (1-λ)E_d + λE_s")
    normalise: bool = param(
        True, "divide E_s by the graph's mean degree, so λ does not depend on knn")


class _WarmStarts:
    """The max-flow of a pool's last labelling, to start the next one on the same pool from.

    The local optimisation labels a pool for a hypothesis, then for its refit: the two
    problems differ a little, and the first one's flow is a good start for the second
    (:func:`~monoplane.graphcut.minimize_gc_ransac`; the result does not depend on it).
    """

    _last: tuple[np.ndarray, np.ndarray] | None = None

    def prepare_pool(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray) -> None:
        """The pool's subgraph and an empty flow buffer for it (see
        :meth:`monoplane.stages.base.Labeler.prepare_pool`)."""
        _, edge_ids = graph.subgraph(pool)
        self._flow(edge_ids)

    def _flow(self, edge_ids: np.ndarray) -> np.ndarray:
        """(E',) flow buffer of the pool whose subgraph edges are ``edge_ids`` (kept while
        the pool is, zeros for a new one)."""
        last = self._last
        if last is None or last[0] is not edge_ids:
            last = self._last = (edge_ids, np.zeros(edge_ids.size))
        return last[1]


class GraphCutLabeler(_WarmStarts, Labeler):
    """GC-RANSAC: truncated-L2 data term, constant Potts pairwise term, exact graph cut."""

    name = "graph-cut"
    Config = GraphCutConfig

    def label(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
              plane: np.ndarray, model_normal: np.ndarray, params: RansacParams) -> Labeling:
        """See :meth:`monoplane.stages.base.Labeler.label`."""
        f0, f1 = data_costs(cloud.points, cloud.normals, pool, plane, None, params.epsilon)
        edges, edge_ids = graph.subgraph(pool)
        scale = degree_normalisation(graph.mean_degree) if self.config.normalise else 1.0
        inliers, energy = minimize_gc_ransac(f0, f1, edges, 1.0, self.config.lambda_, scale,
                                             flow=self._flow(edge_ids))
        return Labeling(inliers=inliers, energy=energy)


@dataclass
class ProximityGraphCutConfig(ProximityAffinities):
    """Parameters of MonoPlane's proximity-guided graph-cut labeler (paper §IV-A values)."""

    lambda_: float = param(0.95, "smoothness weight λ in E = (1-λ)(E_d + E_n) + λE_s")
    normal_term: bool = param(True, "add the normal data energy E_n to the data term")
    normalise: bool = param(
        False, "divide E_s by the graph's mean degree (off: the paper's weights as given)")


class ProximityGraphCutLabeler(_WarmStarts, Labeler):
    """MonoPlane labeler: E_d + E_n data terms and proximity-weighted pairwise cut costs."""

    name = "proximity-graph-cut"
    Config = ProximityGraphCutConfig
    _last_pool_weights: tuple[np.ndarray, np.ndarray] | None = None

    def _edge_weights(self, cloud: PlaneCloud, graph: NeighbourGraph) -> np.ndarray:
        """(E,) cut costs of every graph edge; they depend on the frame only, so cached."""
        c = self.config
        key = ("proximity-graph-cut", id(cloud), *c.affinities())
        w = graph.cache.get(key)
        if w is None:
            w = proximity_weights(cloud.points, graph.edges, cloud.normals, cloud.colors,
                                  *c.affinities())
            w.flags.writeable = False  # shared by every pool of the frame
            graph.cache[key] = w
        return w

    def _pool_weights(self, cloud: PlaneCloud, graph: NeighbourGraph,
                      edge_ids: np.ndarray) -> np.ndarray:
        """Cut costs of a pool's subgraph edges; kept while the pool (its ``edge_ids``) is."""
        last = self._last_pool_weights
        if last is None or last[0] is not edge_ids:
            weights = self._edge_weights(cloud, graph)
            # Ascending distinct edge rows as many as the graph's are all of them, in order.
            pooled = weights if edge_ids.size == weights.size else weights[edge_ids]
            last = self._last_pool_weights = (edge_ids, pooled)
        return last[1]

    def prepare_pool(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray) -> None:
        """The pool's subgraph, its edges' cut costs and an empty flow buffer (see
        :meth:`monoplane.stages.base.Labeler.prepare_pool`)."""
        _, edge_ids = graph.subgraph(pool)
        self._pool_weights(cloud, graph, edge_ids)
        self._flow(edge_ids)

    def label(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
              plane: np.ndarray, model_normal: np.ndarray, params: RansacParams) -> Labeling:
        """See :meth:`monoplane.stages.base.Labeler.label`."""
        f0, data1 = data_costs(cloud.points, cloud.normals, pool, plane,
                               model_normal if self.config.normal_term else None,
                               params.epsilon, params.epsilon_n)
        edges, edge_ids = graph.subgraph(pool)
        cut = self._pool_weights(cloud, graph, edge_ids)
        scale = degree_normalisation(graph.mean_degree) if self.config.normalise else 1.0
        inliers, energy = minimize_gc_ransac(f0, data1, edges, cut, self.config.lambda_, scale,
                                             flow=self._flow(edge_ids))
        return Labeling(inliers=inliers, energy=energy)


@hookimpl
def monoplane_register_labelers() -> list[type[Stage]]:
    """Built-in labelers."""
    return [ThresholdLabeler, GraphCutLabeler, ProximityGraphCutLabeler]
