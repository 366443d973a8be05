"""Binary inlier labelers for one plane hypothesis.

* ``threshold``: vanilla RANSAC, inliers are the points with φ < ε; energy = −|inliers|.
* ``graph-cut``: GC-RANSAC with the paper's truncated-L2 data term and a constant Potts
  pairwise term (cut cost 1, both-outliers cost ½(f(0,p) + f(0,q))), E = (1-λ)E_d + λE_s;
  by default E_s is divided by the mean degree k̄ of the kNN graph
  (:func:`~monoplane.algorithm.graphcut.degree_normalisation`): unnormalised, on a dense graph the
  smoothness term outweighs the data term k̄ times more than λ says and a plane absorbs strips
  of its neighbours.
* ``proximity-graph-cut``: MonoPlane's labeler (§III-B2): the data term adds the normal energy
  E_n and the cut cost of an edge is 0.5 + k_p + k_c + k_n (eqs. kp, kc, kn), so
  E = (1-λ)E_d + (1-λ)E_n + λE_s. The colour term is dropped when the cloud has no colour.

The graph cuts run only on the kNN subgraph of the points still in the pool.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from monoplane.algorithm.graphcut import (
    data_costs,
    degree_normalisation,
    gc_ransac_cut_energy,
    minimize_gc_ransac,
    pool_payback,
    proximity_weights,
)
from monoplane.contracts import (
    Labeler,
    Labeling,
    LabelingContext,
    ProximityAffinities,
    RansacParams,
    Stage,
    param,
)
from monoplane.errors import check_config
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.graph import NeighbourGraph
from monoplane.hookspecs import hookimpl


def _pool_distances(cloud: PlaneCloud, pool: np.ndarray, plane: np.ndarray) -> np.ndarray:
    """(M,) distances of the pool's points to ``plane`` (normalised frame)."""
    return np.abs(cloud.points[pool] @ plane[:3] + plane[3])


class ThresholdLabeler(Labeler):
    """Vanilla RANSAC labelling: inlier iff the point-to-plane distance is below ε."""

    name = "threshold"

    def label(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
              plane: np.ndarray, model_normal: np.ndarray, params: RansacParams,
              context: LabelingContext | None = None) -> Labeling:
        """See :meth:`monoplane.contracts.Labeler.label`; energy is −(inlier count)."""
        inliers = _pool_distances(cloud, pool, plane) < params.epsilon
        return Labeling(inliers=inliers, energy=-float(inliers.sum()))


@dataclass
class GraphCutConfig:
    """Parameters of the GC-RANSAC labeler."""

    lambda_: float = param(0.95, "smoothness weight λ in E = (1-λ)E_d + λE_s")
    normalise: bool = param(
        True, "divide E_s by the graph's mean degree, so λ does not depend on knn")


@dataclass
class _PoolTerms:
    """What a graph-cut labeler keeps of the pool it labels, whatever the hypothesis."""

    graph: NeighbourGraph
    """The frame's graph."""
    pool: np.ndarray
    """(M,) int64 the pool's points, ascending (a copy: identifies the pool)."""
    edges: np.ndarray
    """(E', 2) the pool's subgraph, in pool positions."""
    edge_ids: np.ndarray
    """(E',) rows of the graph's edges it comes from."""
    cut: np.ndarray | float
    """(E',) cut cost of each subgraph edge (or one for all)."""
    scale: float
    """Pairwise scale s of the frame's graph."""
    payback: np.ndarray
    """(M,) :func:`~monoplane.algorithm.graphcut.pool_payback` of the pool's points."""


class GraphCutContext(LabelingContext):
    """What a graph-cut labeler keeps of one frame.

    Attributes
    ----------
    pool : _PoolTerms or None
        The terms of the pool labelled last (or prepared for the next labelling).
    weights : numpy.ndarray or None
        (E,) cut cost of every edge of the frame's graph, for labelers whose cut costs
        depend on the points only (computed on first use).
    """

    def __init__(self) -> None:
        self.pool: _PoolTerms | None = None
        self.weights: np.ndarray | None = None


def _own(context: LabelingContext) -> GraphCutContext:
    """``context`` as the graph-cut labelers' own: the driver passes back what
    :meth:`_PoolGraphCut.new_context` made."""
    if not isinstance(context, GraphCutContext):
        raise TypeError(f"a graph-cut labeler needs the context its new_context() makes, got "
                        f"{type(context).__name__}")
    return context


class _PoolGraphCut(Labeler):
    """A graph-cut labeler whose per-pool terms are built once per pool.

    The local optimisation labels a pool for a hypothesis, then for its refit, and the driver
    has the pool's terms built beforehand (:meth:`prepare_pool`, on a background thread while
    it searches): the subgraph, its cut costs and each point's payback. They are kept in the
    frame's :class:`GraphCutContext`.
    """

    def new_context(self) -> GraphCutContext:
        """A fresh :class:`GraphCutContext` for one frame."""
        return GraphCutContext()

    def _cut(self, cloud: PlaneCloud, graph: NeighbourGraph, edge_ids: np.ndarray,
             context: GraphCutContext) -> np.ndarray | float:
        """Cut costs of the pool's subgraph edges (``edge_ids`` rows of the graph's)."""
        raise NotImplementedError

    def _terms(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
               context: GraphCutContext) -> _PoolTerms:
        """The terms of ``pool``, built when it is not the pool of the last call. The
        subgraph comes from the graph's cache (a pool within the last one from the last
        one's subgraph, :meth:`~monoplane.geometry.graph.NeighbourGraph.subgraph`), which
        the driver's component split then finds filled."""
        scale = degree_normalisation(graph.mean_degree) if self.config.normalise else 1.0
        last = context.pool
        if (last is not None and last.graph is graph and last.scale == scale
                and np.array_equal(last.pool, pool)):
            return last
        edges, edge_ids = graph.subgraph(pool)
        cut = self._cut(cloud, graph, edge_ids, context)
        payback = pool_payback(pool.size, edges, cut, self.config.lambda_, scale)
        last = context.pool = _PoolTerms(graph, np.array(pool, dtype=np.int64), edges, edge_ids,
                                         cut, scale, payback)
        return last

    def prepare_pool(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
                     context: LabelingContext) -> None:
        """The pool's terms (see :meth:`monoplane.contracts.Labeler.prepare_pool`)."""
        self._terms(cloud, graph, pool, _own(context))

    def _pool_terms(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
                    context: LabelingContext | None) -> _PoolTerms:
        """:meth:`_terms` of the driver's context, or of a fresh one without it."""
        return self._terms(cloud, graph, pool,
                           GraphCutContext() if context is None else _own(context))

    def _minimize(self, terms: _PoolTerms, f0: np.ndarray, data1: np.ndarray) -> Labeling:
        """Minimise the pool's energy for the data costs of one hypothesis."""
        inliers, _ = minimize_gc_ransac(f0, data1, terms.edges, terms.cut, self.config.lambda_,
                                        terms.scale, payback=terms.payback, with_energy=False)
        # Summed when the driver first reads it (local optimisation only).
        return Labeling(inliers, partial(gc_ransac_cut_energy, f0, data1, terms.edges,
                                         terms.cut, self.config.lambda_, inliers, terms.scale))


class GraphCutLabeler(_PoolGraphCut):
    """GC-RANSAC: truncated-L2 data term, constant Potts pairwise term, exact graph cut."""

    name = "graph-cut"
    Config = GraphCutConfig

    def _cut(self, cloud: PlaneCloud, graph: NeighbourGraph, edge_ids: np.ndarray,
             context: GraphCutContext) -> float:
        return 1.0

    def label(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
              plane: np.ndarray, model_normal: np.ndarray, params: RansacParams,
              context: LabelingContext | None = None) -> Labeling:
        """See :meth:`monoplane.contracts.Labeler.label`."""
        terms = self._pool_terms(cloud, graph, pool, context)
        f0, f1 = data_costs(cloud.points, cloud.normals, pool, plane, None, params.epsilon)
        return self._minimize(terms, f0, f1)


@dataclass
class ProximityGraphCutConfig(ProximityAffinities):
    """Parameters of MonoPlane's proximity-guided graph-cut labeler: the paper's §IV-A values,
    plus a normal gate on normals estimated from a sensor's depth (``normal_gate_deg``; 180
    turns it off, as the ``monoplane-paper`` preset does)."""

    lambda_: float = param(0.95, "smoothness weight λ in E = (1-λ)(E_d + E_n) + λE_s")
    normal_term: bool = param(True, "add the normal data energy E_n to the data term")
    normal_gate_deg: float = param(
        20.0, "a point whose normal, and every graph neighbour's, lies more than this angle "
        "in degrees from the hypothesis' model normal cannot be its inlier, whatever the "
        "smoothness (with normal_term, on normals estimated from a sensor's depth; 180: no "
        "gate). An absolute angle: it does not follow ransac.epsilon_n_deg (20 is twice its "
        "default)")
    gate_given_normals: bool = param(
        False, "apply normal_gate_deg also to normals not estimated from a sensor's depth "
        "(given with the input, a network's, or estimated from a network's depth)")
    normalise: bool = param(
        False, "divide E_s by the graph's mean degree (off: the paper's weights as given)")

    def __post_init__(self) -> None:
        check_config([(0 < self.normal_gate_deg <= 180,
                       f"normal_gate_deg must lie in (0, 180], got {self.normal_gate_deg}")])


class ProximityGraphCutLabeler(_PoolGraphCut):
    """MonoPlane labeler: E_d + E_n data terms and proximity-weighted pairwise cut costs."""

    name = "proximity-graph-cut"
    Config = ProximityGraphCutConfig

    def _cut(self, cloud: PlaneCloud, graph: NeighbourGraph, edge_ids: np.ndarray,
             context: GraphCutContext) -> np.ndarray:
        weights = context.weights
        if weights is None:  # they depend on the frame only: once per frame
            # The lattice graph took the angles between its ends' normals (the cloud's, as the
            # driver builds it) for its turn weights: k_n reads them.
            affinities: tuple[float, float, float, float, float, float] = (
                self.config.affinities())
            weights = proximity_weights(cloud.points, graph.edges, cloud.normals, cloud.colors,
                                        *affinities, scale=graph.affinity_scale,
                                        angles=graph.normal_angle)
            weights.flags.writeable = False  # shared by every pool of the frame
            context.weights = weights
        # Ascending distinct edge rows as many as the graph's are all of them, in order.
        return weights if edge_ids.size == weights.size else weights[edge_ids]

    def _gate(self, cloud: PlaneCloud) -> float:
        """The normal gate in radians for ``cloud`` (π: none). Normals estimated from a
        sensor's depth (:attr:`PlaneCloud.normals_from_sensor_depth`) measure the surface the
        distances measure, and a curved surface beside a plane turns them away from it. A
        network's normals, and normals estimated from a network's depth, are smoothed
        predictions, on which the gate trims planes on curved surfaces into bands that pass
        the planarity test (docs/evaluation.md, "The normal gate, eighth round")."""
        c = self.config
        if c.normal_gate_deg >= 180 or not (cloud.normals_from_sensor_depth
                                            or c.gate_given_normals):
            return np.pi
        return float(np.deg2rad(c.normal_gate_deg))

    def label(self, cloud: PlaneCloud, graph: NeighbourGraph, pool: np.ndarray,
              plane: np.ndarray, model_normal: np.ndarray, params: RansacParams,
              context: LabelingContext | None = None) -> Labeling:
        """See :meth:`monoplane.contracts.Labeler.label`."""
        terms = self._pool_terms(cloud, graph, pool, context)
        # The cut's own payback bound: the normal terms of points it fixes as outliers by
        # their distance alone are not computed.
        f0, data1 = data_costs(cloud.points, cloud.normals, pool, plane,
                               model_normal if self.config.normal_term else None,
                               params.epsilon, params.epsilon_n, terms.payback,
                               1.0 - self.config.lambda_, self._gate(cloud), terms.edges)
        return self._minimize(terms, f0, data1)


@hookimpl
def monoplane_register_labelers() -> list[type[Stage]]:
    """Built-in labelers."""
    return [ThresholdLabeler, GraphCutLabeler, ProximityGraphCutLabeler]
