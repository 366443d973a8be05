"""Time ``monoplane.algorithm.mincut`` against PyMaxflow's vectorised API on the pipeline's own
graphs.

Runs the ``monoplane`` preset on synthetic frames (``monoplane.synth.generate(seed, "mild")``)
at 256x192 and 640x480, records every graph the graph-cut labeler solves (by wrapping the
solvers that :mod:`monoplane.algorithm.graphcut` calls), then solves each recorded graph with both:

* ``monoplane.algorithm.mincut.min_cut_flows``: the arrays as they are, one compiled call;
* PyMaxflow (``maxflow.Graph[float]``): ``add_nodes``, ``add_edges`` with arrays,
  ``add_grid_tedges``, ``maxflow``, ``get_grid_segments``; graph building timed apart.

Both solve exactly the same graphs (those of a warm-started solve are given as their
residual), interleaved, best of ``--repeat`` rounds; the cuts are compared too. PyMaxflow is in
the ``dev`` extra. Usage::

    python3 benchmarks/mincut_vs_pymaxflow.py --frames 5
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import maxflow
import numpy as np

import monoplane.algorithm.graphcut as graphcut
from monoplane.algorithm.mincut import min_cut_flows
from monoplane.host.pipeline import Pipeline
from monoplane.synth import generate

#: (nodes, tails, heads, caps, rev_caps, terminal) of every solve, in call order.
Graph = tuple[int, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def record_graphs(captured: list[Graph]) -> None:
    """Make :mod:`monoplane.algorithm.graphcut`'s solver calls append their graph to ``captured``
    (a network given as arcs, :func:`~monoplane.algorithm.mincut.min_cut_arcs`, as the edge list
    of its arc pairs)."""
    arcs, cut = graphcut.min_cut_arcs, graphcut.min_cut

    def copy(n: int, *arrays: Any) -> Graph:
        t, h, c, r, term = (np.array(a) for a in arrays)
        return int(n), t, h, c.astype(np.float64), r.astype(np.float64), term.astype(np.float64)

    def arcs_spy(first: Any, head: Any, sister: Any, rcap: Any, term: Any) -> Any:
        n = term.shape[0]
        owner = np.repeat(np.arange(n), np.diff(first))
        pair = np.flatnonzero(np.arange(head.size) < sister)
        captured.append(copy(n, owner[pair], head[pair], rcap[pair], rcap[sister[pair]], term))
        return arcs(first, head, sister, rcap, term)

    def cut_spy(n: int, t: Any, h: Any, c: Any, r: Any, term: Any, *a: Any, **k: Any) -> Any:
        captured.append(copy(n, t, h, c, r, term))
        return cut(n, t, h, c, r, term, *a, **k)

    graphcut.min_cut_arcs, graphcut.min_cut = arcs_spy, cut_spy


def pymaxflow_cut(graph: Graph) -> tuple[np.ndarray, float]:
    """Sink side (N,) bool of ``graph`` by PyMaxflow, and the seconds spent building it."""
    n, t, h, c, r, term = graph
    start = time.perf_counter()
    g = maxflow.Graph[float](n, max(len(t), 1))
    nodes = g.add_nodes(n)
    g.add_edges(nodes[t], nodes[h], c, r)
    g.add_grid_tedges(nodes, np.maximum(term, 0.0), np.maximum(-term, 0.0))
    built = time.perf_counter() - start
    g.maxflow()
    return np.asarray(g.get_grid_segments(nodes), dtype=bool), built


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=5, help="frames per size (seeds 0..)")
    parser.add_argument("--repeat", type=int, default=5, help="timed rounds; the best counts")
    args = parser.parse_args()
    captured: list[Graph] = []
    record_graphs(captured)
    pipe = Pipeline.from_preset("monoplane")
    for width, height in ((256, 192), (640, 480)):
        frames = [generate(s, "mild", width=width, height=height).views[0].frame
                  for s in range(args.frames)]
        pipe.run(frames[0])  # compiles the kernels
        captured.clear()
        for frame in frames:
            pipe.run(frame)
        graphs = list(captured)
        min_cut_flows(*graphs[0])
        pymaxflow_cut(graphs[0])
        ours = theirs = build = np.inf
        same = True
        for _ in range(args.repeat):
            start = time.perf_counter()
            cuts = [min_cut_flows(*g)[0] for g in graphs]
            middle = time.perf_counter()
            results = [pymaxflow_cut(g) for g in graphs]
            end = time.perf_counter()
            ours = min(ours, middle - start)
            if end - middle < theirs:
                theirs, build = end - middle, sum(b for _, b in results)
            same &= all(np.array_equal(a, b) for a, (b, _) in zip(cuts, results, strict=True))
        nodes = np.array([g[0] for g in graphs])
        edges = np.array([g[1].size for g in graphs])
        per_frame = 1000.0 / len(frames)
        print(f"{width}x{height}: {len(frames)} frames, {len(graphs)} graphs; nodes median "
              f"{int(np.median(nodes))} max {nodes.max()}, edges median {int(np.median(edges))} "
              f"max {edges.max()}")
        print(f"  monoplane.algorithm.mincut        {ours * per_frame:6.2f} ms per frame")
        print(f"  PyMaxflow (vectorised)  {theirs * per_frame:6.2f} ms per frame, of which "
              f"{build * per_frame:.2f} ms building the graph")
        print(f"  same cuts: {same}")


if __name__ == "__main__":
    main()
