"""Off-screen 3D renders with Open3D, isolated in a child process with a timeout.

Why a child process
-------------------
Open3D 0.19's ``OffscreenRenderer`` (Filament on OpenGL) runs headless on a CPU-only machine
through EGL's surfaceless platform and Mesa's llvmpipe driver. It needs ``EGL_PLATFORM=
surfaceless`` in the environment before Open3D is imported, and the Debian packages ``libegl1
libegl-mesa0 libgl1-mesa-dri``. When EGL cannot start, Open3D does not raise: it prints
"eglInitialize failed" and the process dies of a segmentation fault. Rendering therefore runs in
``python -m monoplane.report.render3d JOB.npz`` under a timeout, and the parent turns a crash,
a hang or a missing picture into a reason string, so that a report degrades to 2D figures
instead of crashing or hanging the caller.

The parent side is :func:`render`: it writes the geometry and the camera of every shot to one
``.npz`` file, runs the child once (Open3D's start-up, 3-5 s on 2 cores, is paid once per
report), and returns the PNG paths that the child produced.

Cameras use OpenCV conventions throughout: a shot has intrinsics ``K`` (3, 3) in pixels for
its image size and a world-to-camera matrix (4, 4) with x right, y down, z forward.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: Environment the child renders in. ``surfaceless`` makes Mesa's EGL start without X or
#: Wayland; with it unset, eglInitialize fails and Open3D 0.19 segfaults.
RENDER_ENV = {"EGL_PLATFORM": "surfaceless"}

#: Seconds the whole child process may take (start-up included) before it is killed.
DEFAULT_TIMEOUT = 120.0


@dataclass
class Mesh:
    """A triangle mesh to render.

    Attributes
    ----------
    vertices : numpy.ndarray
        (V, 3) float world points.
    triangles : numpy.ndarray
        (T, 3) int vertex indices.
    colors : numpy.ndarray
        (V, 3) float vertex colours in [0, 1], drawn as they are (no lighting is applied, so
        shade them beforehand, e.g. with :func:`shade`, where shape should read).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    colors: np.ndarray


@dataclass
class Lines:
    """Line segments to render (camera frusta, axes).

    Attributes
    ----------
    points : numpy.ndarray
        (N, 3) float world points.
    edges : numpy.ndarray
        (E, 2) int point indices.
    colors : numpy.ndarray
        (E, 3) float colours in [0, 1].
    """

    points: np.ndarray
    edges: np.ndarray
    colors: np.ndarray


@dataclass
class Shot:
    """One picture: a camera and what it sees.

    Attributes
    ----------
    name : str
        File stem of the PNG.
    K : numpy.ndarray
        (3, 3) intrinsics in pixels of the render size.
    world_to_cam : numpy.ndarray
        (4, 4) extrinsics, OpenCV axes.
    meshes : dict
        ``{mesh index: triangle indices to draw or None for all}``; selecting triangles per shot
        lets a view leave out planes it sees from behind.
    lines : list of int
        Indices of :class:`Lines` to draw.
    """

    name: str
    K: np.ndarray
    world_to_cam: np.ndarray
    meshes: dict[int, np.ndarray | None] = field(default_factory=dict)
    lines: list[int] = field(default_factory=list)


@dataclass
class RenderResult:
    """What :func:`render` produced.

    Attributes
    ----------
    paths : dict
        ``{shot name: PNG path}`` of the shots rendered.
    reason : str or None
        Why nothing (or not everything) was rendered; None on full success.
    seconds : float
        Wall time of the child process.
    """

    paths: dict[str, Path]
    reason: str | None
    seconds: float


def render(
    meshes: list[Mesh],
    lines: list[Lines],
    shots: list[Shot],
    out_dir: Path,
    width: int,
    height: int,
    timeout: float = DEFAULT_TIMEOUT,
) -> RenderResult:
    """Render shots to ``out_dir/<shot.name>.png`` in a child process.

    Parameters
    ----------
    meshes, lines : list
        Geometry shared by the shots.
    shots : list of Shot
        Pictures to take; all have size ``width`` x ``height``.
    out_dir : pathlib.Path
        Existing folder for the PNGs.
    width, height : int
        Render size in pixels.
    timeout : float
        Seconds before the child is killed.

    Returns
    -------
    RenderResult
        Never raises for rendering failures: they come back as ``reason``.
    """
    out_dir = Path(out_dir)
    arrays: dict[str, np.ndarray] = {}
    for j, m in enumerate(meshes):
        arrays[f"m{j}_v"] = np.asarray(m.vertices, dtype=np.float64)
        arrays[f"m{j}_t"] = np.asarray(m.triangles, dtype=np.int32)
        arrays[f"m{j}_c"] = np.clip(np.asarray(m.colors, dtype=np.float64), 0.0, 1.0)
    for j, ln in enumerate(lines):
        arrays[f"l{j}_v"] = np.asarray(ln.points, dtype=np.float64)
        arrays[f"l{j}_e"] = np.asarray(ln.edges, dtype=np.int32)
        arrays[f"l{j}_c"] = np.clip(np.asarray(ln.colors, dtype=np.float64), 0.0, 1.0)
    spec_shots = []
    for i, s in enumerate(shots):
        arrays[f"s{i}_K"] = np.asarray(s.K, dtype=np.float64)
        arrays[f"s{i}_T"] = np.asarray(s.world_to_cam, dtype=np.float64)
        mesh_specs = []
        for j, keep in s.meshes.items():
            key = None
            if keep is not None:
                key = f"s{i}_m{j}_keep"
                arrays[key] = np.asarray(keep, dtype=np.int64)
            mesh_specs.append({"id": j, "keep": key})
        spec_shots.append({"path": str(out_dir / f"{s.name}.png"), "meshes": mesh_specs,
                           "lines": list(s.lines)})
    spec = {"width": int(width), "height": int(height), "shots": spec_shots}
    arrays["spec"] = np.array(json.dumps(spec))

    env = dict(os.environ)
    env.update(RENDER_ENV)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="monoplane-render-") as tmp:
        job = Path(tmp) / "job.npz"
        np.savez(job, **arrays)  # type: ignore[arg-type]
        try:
            proc = subprocess.run(
                [sys.executable, "-m", "monoplane.report.render3d", str(job)],
                env=env, capture_output=True, text=True, timeout=timeout,
            )
        except subprocess.TimeoutExpired:
            return RenderResult({}, f"3D rendering timed out after {timeout:g} s and was "
                                    "stopped (the OpenGL driver hung)",
                                time.perf_counter() - t0)
    seconds = time.perf_counter() - t0
    paths = {s.name: out_dir / f"{s.name}.png" for s in shots}
    paths = {k: p for k, p in paths.items() if p.is_file()}
    if proc.returncode != 0:
        return RenderResult(paths, _failure_reason(proc.returncode, proc.stderr), seconds)
    missing = [s.name for s in shots if s.name not in paths]
    reason = f"3D renderer produced no picture for: {', '.join(missing)}" if missing else None
    return RenderResult(paths, reason, seconds)


def _failure_reason(returncode: int, stderr: str) -> str:
    """One sentence on why the child failed, with the last informative line of its stderr."""
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    egl = any("eglInitialize failed" in ln or ("EGL" in ln and "fail" in ln) for ln in lines)
    if returncode < 0:
        try:
            sig = signal.Signals(-returncode).name
        except ValueError:
            sig = f"signal {-returncode}"
        what = f"the 3D renderer crashed ({sig})"
    else:
        what = f"the 3D renderer exited with status {returncode}"
    if egl:
        return (f"{what}: OpenGL/EGL is unavailable (eglInitialize failed). Headless rendering "
                "needs the Debian packages libegl1 libegl-mesa0 libgl1-mesa-dri; see "
                "docs/reports.md")
    detail = lines[-1] if lines else "no error output"
    return f"{what}: {detail}"


def _child(job: Path) -> int:
    """Render every shot of a job file (runs in the child process)."""
    data = np.load(job)
    spec = json.loads(str(data["spec"]))
    import open3d as o3d  # imported here: the parent never loads Open3D's renderer

    rendering = o3d.visualization.rendering
    width, height = spec["width"], spec["height"]
    renderer = rendering.OffscreenRenderer(width, height)
    scene = renderer.scene
    scene.set_background([1.0, 1.0, 1.0, 1.0])
    # Colours arrive already shaded (see Mesh); tone mapping and Filament's lights would only
    # wash them out and tint the background.
    scene.view.set_post_processing(False)
    scene.view.set_shadowing(False)
    mesh_mat = rendering.MaterialRecord()
    mesh_mat.shader = "defaultUnlit"
    line_mat = rendering.MaterialRecord()
    line_mat.shader = "unlitLine"
    line_mat.line_width = 2.0

    for i, shot in enumerate(spec["shots"]):
        scene.clear_geometry()
        for m in shot["meshes"]:
            j = m["id"]
            tris = data[f"m{j}_t"]
            if m["keep"] is not None:
                tris = tris[data[m["keep"]]]
            if len(tris) == 0:
                continue
            mesh = o3d.geometry.TriangleMesh(
                o3d.utility.Vector3dVector(data[f"m{j}_v"]),
                o3d.utility.Vector3iVector(tris),
            )
            mesh.vertex_colors = o3d.utility.Vector3dVector(data[f"m{j}_c"])
            scene.add_geometry(f"mesh{j}", mesh, mesh_mat)
        for j in shot["lines"]:
            ls = o3d.geometry.LineSet(
                o3d.utility.Vector3dVector(data[f"l{j}_v"]),
                o3d.utility.Vector2iVector(data[f"l{j}_e"]),
            )
            ls.colors = o3d.utility.Vector3dVector(data[f"l{j}_c"])
            scene.add_geometry(f"lines{j}", ls, line_mat)
        renderer.setup_camera(data[f"s{i}_K"], data[f"s{i}_T"], width, height)
        img = np.asarray(renderer.render_to_image())
        o3d.io.write_image(shot["path"], o3d.geometry.Image(np.ascontiguousarray(img)))
        print(f"rendered {shot['path']}", flush=True)
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        print("usage: python -m monoplane.report.render3d JOB.npz", file=sys.stderr)
        sys.exit(2)
    status = _child(Path(sys.argv[1]))
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)
