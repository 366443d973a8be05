"""Compile every numba kernel once, so that the first real run loads them from the disk cache.

monoplane's kernels (:mod:`monoplane.jit`, :mod:`monoplane.algorithm.lattice_kernels`) compile
on their first call and cache the machine code on disk. Without a warm-up, the first
``monoplane run`` on a machine spends 20-30 s compiling; ``setup.sh`` runs this module instead,
so the user's first run costs what every later run does::

    python3 -m monoplane.warmup

It runs every shipped preset on one small synthetic frame (with and without normals and
colour), saves one reconstruction with its report into a temporary folder, renders a
triangle and a line segment with the reports' rasterizer and detects the planes of a point
cloud with and without normals: together these call every kernel with the dtypes the library
uses. It then checks that every kernel of the package was reached and names those that were not
(they would compile on their first use). Running it again only loads the caches.

numba keeps the caches next to the sources (``__pycache__``), or in ``NUMBA_CACHE_DIR`` or
``~/.cache/numba`` when those are read-only; a kernel whose source file changes compiles again
on its next call.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from importlib import resources
from typing import Any

import numpy as np

from monoplane import jit
from monoplane.algorithm.mincut import min_cut
from monoplane.algorithm.region_moments import refit_planes
from monoplane.algorithm.regions import region_adjacency
from monoplane.export.saving import save as save_outputs
from monoplane.geometry.graph import NeighbourGraph
from monoplane.geometry.planes import planes_from_triplets
from monoplane.host import config
from monoplane.host.detect import detect_planes
from monoplane.host.pipeline import Pipeline
from monoplane.report.frame import write_frame_report
from monoplane.report.render3d import Lines, Mesh, Shot, render_image
from monoplane.synth import generate


@dataclass
class WarmupResult:
    """What :func:`warm` did."""

    seconds: float
    #: Fully qualified names of the package's cached kernels reached by the workloads.
    compiled: list[str] = field(default_factory=list)
    #: Kernels no workload called (they compile on their first use).
    missed: list[str] = field(default_factory=list)
    #: Workloads that raised, with their error.
    failed: list[str] = field(default_factory=list)


def kernel_modules() -> list[str]:
    """Modules of the package that define numba kernels (found in their source text)."""
    root = resources.files("monoplane")
    found = []

    def walk(folder: Any, prefix: str) -> None:
        for entry in folder.iterdir():
            if entry.is_dir() and entry.name != "__pycache__":
                walk(entry, f"{prefix}{entry.name}.")
            elif entry.name.endswith(".py"):
                text = entry.read_text(encoding="utf-8")
                if "@kernel" in text or "@numba.njit(" in text:
                    found.append(prefix + entry.name[:-3])

    walk(root, "monoplane.")
    return sorted(found)


def _has_signatures(dispatcher: Any) -> bool:
    return bool(dispatcher.signatures)


def package_kernels() -> dict[str, Callable[[], bool]]:
    """Every kernel of the package: qualified name -> "has it been compiled in this process".

    Imports the modules of :func:`kernel_modules`. Covers :func:`monoplane.jit.kernel`
    wrappers and plain ``numba.njit(cache=True)`` dispatchers.
    """
    from numba.core.registry import CPUDispatcher


    found: dict[str, Callable[[], bool]] = {}
    for name in kernel_modules():
        module = importlib.import_module(name)
        own = {key: value for key, value in vars(module).items()
               if isinstance(value, CPUDispatcher) and value.py_func.__module__ == name}
        # A dispatcher that other kernels of its module call is compiled into them (and not
        # on its own when they are loaded from the cache): only the callers count.
        called = {n for d in own.values() for n in d.py_func.__code__.co_names}
        for key, value in own.items():
            if key not in called:
                found[f"{name}.{value.py_func.__qualname__}"] = functools.partial(
                    _has_signatures, value)
    for k in jit.kernels():
        fn = k.py_func  # type: ignore[attr-defined]
        if fn.__module__.startswith("monoplane."):
            found[f"{fn.__module__}.{fn.__qualname__}"] = k.is_compiled  # type: ignore[attr-defined]
    return found


def _run_preset(preset: str, frame: Any) -> Any:
    return Pipeline.from_preset(preset).run(frame)


def _render_triangle_and_line() -> None:
    """Render one triangle and one line segment (the dtypes of the reports' 3D views)."""

    corners = np.array([[-1.0, -1.0, 4.0], [1.0, -1.0, 4.0], [0.0, 1.0, 4.0]])
    K = np.array([[16.0, 0.0, 7.5], [0.0, 16.0, 7.5], [0.0, 0.0, 1.0]])
    render_image([Mesh(corners, np.array([[0, 1, 2]]), np.eye(3))],
                 [Lines(corners, np.array([[0, 1]]), np.zeros((1, 3)))],
                 Shot("warmup", K, np.eye(4), {0: None}, [0]), 16, 16)


def _workloads(report: bool = True) -> Iterator[tuple[str, Callable[[], Any]]]:
    """Labelled calls that together reach every kernel.

    The frame is 256x192, so that it has more valid pixels than the RANSAC working cloud's
    ``max_points`` (the labels are then propagated to the pixels left out, by kernels of their
    own).
    """

    frame = generate(0, "mild", width=256, height=192, n_views=1).views[0].frame
    for preset in config.list_presets():
        yield f"preset {preset}", functools.partial(_run_preset, preset, frame)
    # The frame's depth is relative (a network's): its normals are fitted by the gated method
    # and searched on the kNN graph. A sensor's metric depth takes box normals, the pixel
    # lattice and the normal gate.
    yield "depth only", lambda: Pipeline.from_preset("monoplane").run(frame.with_(normals=None))
    yield "sensor depth only", lambda: Pipeline.from_preset("monoplane").run(
        frame.with_(normals=None, depth_kind="metric"))
    # range estimates its normals by the box method and samples on the pixel lattice, as
    # rgbd-fast does on the frame's own normals.
    yield "range image", lambda: Pipeline.from_preset("range").run(
        frame.with_(rgb=None, normals=None))

    def save() -> None:
        rec = Pipeline.from_preset("monoplane").run(frame)
        with tempfile.TemporaryDirectory() as tmp:
            save_outputs(rec, f"{tmp}/out",
                         also=functools.partial(write_frame_report, rec) if report else None)

    yield "outputs" + (" and report" if report else ""), save
    # The frame report draws no lines, and --no-report skips it: the rasterizer's kernels get
    # a shot of their own.
    yield "3D rasterizer", _render_triangle_and_line
    # The RANSAC builds its hypotheses without gathering the samples' points, which the public
    # planes_from_triplets takes; and the presets' samplers let it search in one compiled
    # call, so a sampler that does not (napsac) makes it call the scorer batch by batch.
    yield "triplet planes", lambda: planes_from_triplets(np.eye(3)[None])
    # The labelers hand the max-flow a network in its own arc layout; the general binary
    # energies (and plugins) give it edge lists.
    yield "max-flow of an edge list", lambda: min_cut(
        2, np.array([0]), np.array([1]), np.ones(1), np.zeros(1), np.array([1.0, -1.0]))
    # The RANSAC's pools shrink, so each subgraph is cut from the last pool's; a pool that is
    # not within the last one is filtered from the whole graph.
    yield "subgraph of a fresh pool", lambda: NeighbourGraph.build(np.eye(3), 1).subgraph(
        np.array([0, 2]))
    yield "scorer batch by batch", lambda: Pipeline.from_preset(
        "monoplane", overrides=["sampler.plugin=napsac", "refiner.plugin=none"]).run(frame)
    # The cloud finds its valid pixels in its own unprojection pass; the evaluation of
    # labelled frames asks the frame's mask.
    yield "valid mask", lambda: frame.valid
    depth, normals, rgb, K = frame.depth, frame.normals, frame.rgb, frame.K
    assert depth is not None and normals is not None and rgb is not None
    valid = depth > 0
    v, u = np.nonzero(valid)
    z = depth[valid].astype(np.float64)
    points = np.stack([(u - K[0, 2]) * z / K[0, 0], (v - K[1, 2]) * z / K[1, 1], z], axis=1)
    yield "point cloud", lambda: detect_planes(points)
    # The refiner reads its regions in one scan (region_scan); the clean-up's public steps
    # (moments of any label map, adjacency) keep kernels of their own.
    pieces = np.eye(3, dtype=np.int64)
    yield "region moments and adjacency", lambda: (
        refit_planes(np.ones((3, 3, 3)), np.ones((3, 3), bool), pieces, np.zeros((1, 4))),
        region_adjacency(pieces))

    def cloud_with_normals() -> None:
        import open3d as o3d

        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        pcd.normals = o3d.utility.Vector3dVector(normals[valid].astype(np.float64))
        pcd.colors = o3d.utility.Vector3dVector(rgb[valid] / 255.0)
        detect_planes(pcd)

    yield "point cloud with normals", cloud_with_normals


def warm(progress: bool = True, report: bool = True) -> WarmupResult:
    """Call every kernel of the package once (compiling it, or loading it from the cache).

    Parameters
    ----------
    progress : bool
        Print one line per workload.
    report : bool
        Also write one HTML report (which checks that the report runs).

    Returns
    -------
    WarmupResult
        A workload that fails is recorded in ``failed`` and the others go on.
    """
    start = time.perf_counter()
    kernels = package_kernels()
    failed = []
    for label, call in _workloads(report):
        t = time.perf_counter()
        try:
            call()
        except Exception as exc:  # a warm-up must not stop an installation
            failed.append(f"{label}: {type(exc).__name__}: {exc}")
            continue
        if progress:
            print(f"  {label}: {time.perf_counter() - t:.1f} s", flush=True)
    compiled = sorted(name for name, done in kernels.items() if done())
    missed = sorted(name for name, done in kernels.items() if not done())
    return WarmupResult(time.perf_counter() - start, compiled, missed, failed)


def main(argv: list[str] | None = None) -> int:
    """``python3 -m monoplane.warmup [--quiet] [--no-report]``; exit status 1 when a workload
    failed."""
    parser = argparse.ArgumentParser(
        prog="python3 -m monoplane.warmup",
        description="Compile monoplane's numba kernels once (cached on disk), so that the "
                    "first run does not pay for it.")
    parser.add_argument("--quiet", action="store_true",
                        help="no line per workload, only the first and last lines")
    parser.add_argument("--no-report", action="store_true",
                        help="skip the HTML report")
    args = parser.parse_args(argv)
    print("monoplane: compiling the numba kernels once, cached on disk (30-60 s on 2 cores) ...",
          flush=True)
    result = warm(progress=not args.quiet, report=not args.no_report)
    total = len(result.compiled) + len(result.missed)
    print(f"monoplane: {len(result.compiled)} of {total} kernels compiled or loaded in "
          f"{result.seconds:.1f} s")
    if result.missed:
        print(f"monoplane: not reached (they compile on first use): {', '.join(result.missed)}")
    for failure in result.failed:
        print(f"monoplane: warm-up step failed: {failure}", file=sys.stderr)
    return 1 if result.failed else 0


if __name__ == "__main__":
    sys.exit(main())
