"""The single-view pipeline: cue provider → sequential RANSAC (sampler, scorer, labeler) → refiner
→ planarity test (:mod:`monoplane.algorithm.planarity`).

Python API first::

    import monoplane
    from monoplane.export import save
    pipe = monoplane.Pipeline.from_preset("monoplane", overrides={"labeler.lambda": 0.9})
    rec = pipe.run(monoplane.load_frame("rgb.png", depth="depth.npy", intrinsics="K.json"))
    save(rec, "out/")

A point cloud goes through the same stages without the pixel grid (:meth:`Pipeline.run_cloud`,
which :func:`monoplane.detect_planes` calls); frames and clouds share the RANSAC driver's
construction and call (:meth:`Pipeline._ransac`).

A stage that raises is reported as a :class:`~monoplane.errors.StageError` naming its kind and
plugin. Per-stage wall times land in ``rec.timings`` and are announced through the
``monoplane_stage_finished`` hook.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import pluggy

from monoplane.algorithm.planarity import check_cloud, check_image
from monoplane.algorithm.ransac import SequentialRansac
from monoplane.contracts import (
    CueProvider,
    Labeler,
    RansacParams,
    Refiner,
    Sampler,
    Scorer,
    Stage,
    run_stage,
)
from monoplane.cues.given import use_given_cues
from monoplane.datamodel import CloudResult, Frame, Reconstruction
from monoplane.errors import ConfigError
from monoplane.geometry.cloud import PlaneCloud
from monoplane.geometry.graph import NeighbourGraph
from monoplane.host import config as config_mod
from monoplane.host.cloud_input import prepare_cloud
from monoplane.host.registry import get_plugin_manager, get_registry

T = TypeVar("T")
S = TypeVar("S", bound=Stage)


class Pipeline:
    """A configured chain of stages.

    Parameters
    ----------
    config : ResolvedConfig
        Validated configuration (see :mod:`monoplane.host.config`).
    pm : pluggy.PluginManager, optional
        Plugin manager the stages come from; a fresh default one if omitted.
    """

    def __init__(self, config: config_mod.ResolvedConfig,
                 pm: pluggy.PluginManager | None = None) -> None:
        self.pm = pm if pm is not None else get_plugin_manager()
        self.registry = get_registry(self.pm)
        self.config = config
        self._stages: dict[str, Stage] = {}

    @classmethod
    def from_preset(cls, name: str = config_mod.DEFAULT_PRESET,
                    overrides: dict[str, Any] | list[str] | None = None,
                    pm: pluggy.PluginManager | None = None) -> Pipeline:
        """Pipeline from a shipped preset plus ``table.key`` overrides."""
        return cls.from_config(None, preset=name, overrides=overrides, pm=pm)

    @classmethod
    def from_config(cls, source: str | Path | dict[str, Any] | None,
                    preset: str | None = None,
                    overrides: dict[str, Any] | list[str] | None = None,
                    pm: pluggy.PluginManager | None = None) -> Pipeline:
        """Pipeline from a TOML file or dict, an optional preset and overrides."""
        pm = pm if pm is not None else get_plugin_manager()
        resolved = config_mod.load(preset=preset, config=source, overrides=overrides,
                                   registry=get_registry(pm))
        return cls(resolved, pm)

    def stage(self, kind: str, base: type[S] = Stage) -> S:  # type: ignore[assignment]
        """The configured stage instance of ``kind`` (built on first use).

        Parameters
        ----------
        kind : str
            Stage kind, e.g. ``"labeler"``.
        base : type
            The kind's base class (e.g. :class:`~monoplane.contracts.Labeler`), which types
            the result.
        """
        if kind not in self._stages:
            name, cfg = self.config.stages[kind]
            self._stages[kind] = self.registry.get(kind, name).cls(cfg)
        stage = self._stages[kind]
        if not isinstance(stage, base):
            raise TypeError(f"{kind} stage {stage.name!r} is not a {base.__name__}")
        return stage

    def call(self, kind: str, label: str, fn: Callable[[], T], frame_name: str,
             timings: dict[str, float]) -> T:
        """Run one stage call, timing it and wrapping any failure in a :class:`StageError`
        (:func:`~monoplane.contracts.run_stage`)."""
        start = time.perf_counter()
        result = run_stage(kind, label, fn)
        seconds = time.perf_counter() - start
        timings[kind] = timings.get(kind, 0.0) + seconds
        self.pm.hook.monoplane_stage_finished(kind=kind, name=label, seconds=seconds,
                                              frame_name=frame_name)
        return result

    def prepare(self, frame: Frame, timings: dict[str, float] | None = None) -> Frame:
        """Give the frame its cues: the returned frame has depth and normals.

        The configured cue provider runs only when it :meth:`~CueProvider.needs_cues`; a frame
        that already carries depth and normals is accepted as given (normals oriented towards
        the camera), so the provider and its model files are never touched for it.
        """
        cues = self.stage("cues", CueProvider)
        timings = {} if timings is None else timings
        if cues.needs_cues(frame):
            return self.call("cues", cues.name, lambda: cues.provide(frame), frame.name,
                             timings)
        return self.call("cues", "given with the input", lambda: use_given_cues(frame),
                         frame.name, timings)

    def segment(self, frame: Frame, timings: dict[str, float] | None = None) -> Reconstruction:
        """Sequential RANSAC then the refiner, on a frame that already has its cues."""
        timings = {} if timings is None else timings
        refiner = self.stage("refiner", Refiner)
        # The refiner's label-independent work runs in the background during the RANSAC.
        rec, params = self._ransac(
            frame.name, timings,
            lambda driver: driver.run(frame, meanwhile=lambda: refiner.prepare(frame)))
        # params: the thresholds the RANSAC used (ε may have been lowered to the sensor's
        # noise).
        rec = self.call("refiner", refiner.name, lambda: refiner.refine(rec, params),
                        frame.name, timings)
        planarity = self.config.host["planarity"]
        rec = self.call("planarity", "planarity test",
                        lambda: check_image(rec, planarity, params.epsilon), frame.name, timings)
        rec.config = self.config.to_dict()
        rec.timings = {**rec.timings, **timings}
        return rec

    def _ransac(self, name: str, timings: dict[str, float],
                search: Callable[[SequentialRansac], T]) -> tuple[T, RansacParams]:
        """The RANSAC stages' driver, built here for frames and clouds alike, run by
        ``search`` as the ``ransac`` stage (timed, hooked, failures wrapped).

        Returns what ``search`` returns and the thresholds the driver labelled with.
        """
        sampler = self.stage("sampler", Sampler)
        scorer = self.stage("scorer", Scorer)
        labeler = self.stage("labeler", Labeler)
        driver = SequentialRansac(sampler, scorer, labeler, self.config.host["ransac"])
        found = self.call("ransac", f"{sampler.name} + {scorer.name} + {labeler.name}",
                          lambda: search(driver), name, timings)
        return found, driver.params_used

    def cloud_refiner(self) -> Refiner:
        """The configured refiner, checked to work without pixels (:meth:`segment_cloud`).

        Raises
        ------
        ConfigError
            When the refiner works on the image grid only (e.g. ``dense-crf``).
        """
        refiner = self.stage("refiner", Refiner)
        if refiner.needs_pixels:
            raise ConfigError(f"refiner '{refiner.name}' works on images only and cannot refine "
                              "a point cloud; use refiner.plugin=graph-crf or none")
        return refiner

    def run_cloud(self, cloud: Any) -> CloudResult:
        """Planes of a point cloud: :func:`~monoplane.host.cloud_input.prepare_cloud`, the
        RANSAC, refiner and planarity test on its subsample (:meth:`segment_cloud`), the labels
        carried to every point (:meth:`PlaneCloud.propagate
        <monoplane.geometry.cloud.PlaneCloud.propagate>`) and the planes refit on them
        (:meth:`~monoplane.host.cloud_input.CloudInput.fit`).

        Parameters
        ----------
        cloud : open3d.geometry.PointCloud, open3d.t.geometry.PointCloud or array_like
            (N, 3) points in any frame and unit, with optional normals and colours.

        Returns
        -------
        CloudResult
            Labels in the input order, planes in the cloud's frame and units, the resolved
            configuration.
        """
        start = time.perf_counter()
        self.cloud_refiner()  # a refiner that needs pixels fails before any work
        rcfg = self.config.host["ransac"]
        rng = np.random.default_rng(rcfg.seed)
        timings: dict[str, float] = {}
        prepared = prepare_cloud(cloud, self.config.host["cloud"], rcfg.max_points, rng, timings)
        t = time.perf_counter()
        graph = self.neighbour_graph(prepared.cloud)
        timings["graph"] = time.perf_counter() - t
        labels, planes = self.segment_cloud(prepared.cloud, graph, rng, "cloud", timings,
                                            own_normals=prepared.own_normals)
        t = time.perf_counter()
        fit = prepared.fit(prepared.cloud.propagate(labels, planes, graph=graph), timings)
        timings["finalize"] = time.perf_counter() - t
        timings["total"] = time.perf_counter() - start
        fit.config = self.config.to_dict()
        return fit

    def neighbour_graph(self, cloud: PlaneCloud) -> NeighbourGraph:
        """The kNN graph (``ransac.knn`` neighbours) over a cloud's points that the RANSAC's
        labeler and a cloud refiner work on (:meth:`PlaneCloud.neighbour_graph
        <monoplane.geometry.cloud.PlaneCloud.neighbour_graph>`)."""
        return cloud.neighbour_graph(self.config.host["ransac"].knn)

    def segment_cloud(self, cloud: PlaneCloud, graph: NeighbourGraph, rng: np.random.Generator,
                      name: str = "cloud", timings: dict[str, float] | None = None,
                      own_normals: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Sequential RANSAC, the refiner and the planarity test on a cloud without pixels
        (:meth:`run_cloud`).

        The same driver (:meth:`_ransac`), hooks and :class:`StageError` wrapping as
        :meth:`segment`: the RANSAC's
        :meth:`~monoplane.algorithm.ransac.SequentialRansac.run_cloud` and the refiner's
        :meth:`~monoplane.contracts.Refiner.refine_cloud`.

        Parameters
        ----------
        cloud : PlaneCloud
            Normalised oriented cloud (unit sphere); only its points, normals and colours are
            used.
        graph : NeighbourGraph
            kNN graph over ``cloud.points`` (:meth:`neighbour_graph`).
        rng : numpy.random.Generator
            Source of the RANSAC's randomness.
        name : str
            Name of the run in the hooks and errors (the ``frame_name`` of a frame).
        timings : dict, optional
            Seconds per stage kind are added to it (``ransac``, ``refiner``, ``planarity``).
        own_normals : bool
            The cloud's normals came with it; False when they were estimated from its points,
            which tells the planarity test nothing the points do not
            (:func:`monoplane.algorithm.planarity.check_cloud`).

        Returns
        -------
        labels : numpy.ndarray
            (N,) int32 plane of each point, 0 = none.
        planes : numpy.ndarray
            (P, 4) float64 planes ``n . x + d = 0`` in the normalised frame.
        """
        timings = {} if timings is None else timings
        refiner = self.cloud_refiner()
        found, params = self._ransac(name, timings,
                                     lambda driver: driver.run_cloud(cloud, graph, rng))
        labels, planes = self.call(
            "refiner", refiner.name,
            lambda: refiner.refine_cloud(cloud, graph, found.labels, found.planes, params),
            name, timings)
        planes = np.asarray(planes, dtype=np.float64).reshape(-1, 4)
        labels, kept = self.call(
            "planarity", "planarity test",
            lambda: check_cloud(cloud.points, cloud.normals if own_normals else None, labels,
                                graph.edges, planes, params.epsilon,
                                self.config.host["planarity"]), name, timings)
        planes = planes[kept]
        return (np.asarray(labels, dtype=np.int32),
                np.asarray(planes, dtype=np.float64).reshape(-1, 4))

    def run(self, frame: Frame) -> Reconstruction:
        """Cues, RANSAC and refinement on one frame.

        Parameters
        ----------
        frame : Frame
            Image (and any given cues) with intrinsics ``K``; see :func:`monoplane.load_frame`.

        Returns
        -------
        Reconstruction
            Label map and planes in the camera frame (OpenCV axes) and the depth's units.
        """
        timings: dict[str, float] = {}
        start = time.perf_counter()
        prepared = self.prepare(frame, timings)
        rec = self.segment(prepared, timings)
        rec.timings["total"] = time.perf_counter() - start
        return rec
