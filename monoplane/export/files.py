"""Output folders and PLY files: what every exporter writes with.

An output folder is written atomically (:func:`atomic_output_dir`): into a temporary sibling
folder that is renamed into place once complete. PLY files are ASCII, points or triangle
meshes whose faces carry a plane id (:func:`write_plane_mesh_ply`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.geometry.polygons import PlaneMesh


def check_output_dir(out_dir: str | Path, overwrite: bool = False) -> Path:
    """Fail early if ``out_dir`` cannot become an output folder; returns it as a Path.

    Raises
    ------
    InvalidInput
        If ``out_dir`` is an existing file, an existing non-empty folder without ``overwrite``,
        or a file stands where one of its parent folders should be.
    """
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InvalidInput(f"output path {out} is an existing file, not a folder")
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise InvalidInput(f"output folder {out} exists and is not empty; pass --overwrite")
    parent = next((p for p in out.parents if p.exists()), Path("."))
    if not parent.is_dir():
        raise InvalidInput(f"cannot write to {out}: {parent} is a file, not a folder")
    return out


@contextlib.contextmanager
def atomic_output_dir(out_dir: str | Path, overwrite: bool = False) -> Iterator[Path]:
    """Yield a temporary folder that becomes ``out_dir`` only if the block succeeds.

    Missing parent folders are created. The temporary folder is a sibling of ``out_dir``
    (same file system, so the final rename is atomic). On any exception it is removed and
    ``out_dir`` is left untouched.

    Raises
    ------
    InvalidInput
        As :func:`check_output_dir`.
    """
    out = check_output_dir(out_dir, overwrite)
    parent = out.parent
    parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".partial", dir=parent))
    # mkdtemp creates the folder 0700; the result is an ordinary output folder, so give it the
    # permissions the user's umask gives any new folder.
    umask = os.umask(0)
    os.umask(umask)
    tmp.chmod(0o777 & ~umask)
    try:
        yield tmp
        if out.exists():
            trash = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=parent))
            os.replace(out, trash / out.name)
            os.replace(tmp, out)
            shutil.rmtree(trash, ignore_errors=True)
        else:
            os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def write_ascii_ply(path: Path, vertices: np.ndarray, vertex_rgb: np.ndarray,
                    faces: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
                    comment: str | None = None) -> None:
    """Write coloured points, or a triangle mesh whose faces carry a colour and a plane id, as
    an ASCII PLY (the one PLY writer of the package's outputs).

    Parameters
    ----------
    path : Path
        Output file.
    vertices : numpy.ndarray
        (N, 3) coordinates, written as ``float`` with 7 significant digits.
    vertex_rgb : numpy.ndarray
        (N, 3) uint8 RGB.
    faces : tuple of numpy.ndarray, optional
        ``(triangles, face_rgb, plane_ids)``: (F, 3) vertex indices, (F, 3) uint8 RGB and (F,)
        int plane id of each triangle; without them the file holds points only.
    comment : str, optional
        One header comment line.
    """
    header = ["ply", "format ascii 1.0", *([f"comment {comment}"] if comment else []),
              f"element vertex {len(vertices)}",
              "property float x", "property float y", "property float z",
              "property uchar red", "property uchar green", "property uchar blue"]
    lines = [f"{x:.7g} {y:.7g} {z:.7g} {r} {g} {b}"
             for (x, y, z), (r, g, b) in zip(np.asarray(vertices).tolist(),
                                             np.asarray(vertex_rgb).tolist(), strict=True)]
    if faces is not None:
        triangles, face_rgb, plane_ids = faces
        header += [f"element face {len(triangles)}", "property list uchar int vertex_indices",
                   "property uchar red", "property uchar green", "property uchar blue",
                   "property int plane_id"]
        lines += [f"3 {a} {b} {c} {r} {g} {bl} {pid}"
                  for (a, b, c), (r, g, bl), pid in zip(
                      np.asarray(triangles).tolist(), np.asarray(face_rgb).tolist(),
                      np.asarray(plane_ids).tolist(), strict=True)]
    path.write_text("\n".join([*header, "end_header", *lines]) + "\n")


def write_points_ply(path: Path, points: np.ndarray, colors: np.ndarray | None = None) -> None:
    """Write a coloured point cloud as an ASCII PLY.

    Parameters
    ----------
    path : Path
        Output file.
    points : numpy.ndarray
        (M, 3) points.
    colors : numpy.ndarray, optional
        (M, 3) uint8 RGB; grey when omitted.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    col = (np.full((len(pts), 3), 200, np.uint8) if colors is None
           else np.asarray(colors, dtype=np.uint8).reshape(-1, 3))
    write_ascii_ply(path, pts, col)


def write_plane_mesh_ply(path: Path, mesh: PlaneMesh, colors: np.ndarray,
                         first_id: int = 1) -> None:
    """Write plane regions as an ASCII PLY triangle mesh, each face tagged with its plane id.

    Parameters
    ----------
    path : Path
        Output file.
    mesh : PlaneMesh
        Triangles with their ``plane_ids``.
    colors : numpy.ndarray
        (P, 3) uint8 RGB of plane id ``p`` at row ``p - first_id``.
    first_id : int
        Id of the first plane: 1 for label values, 0 for a scene's global planes.

    Notes
    -----
    Elements: ``vertex`` (float x, y, z; uchar red, green, blue) and ``face`` (uchar-counted
    int list ``vertex_indices`` of 3 entries; uchar red, green, blue; int ``plane_id``). No
    vertex is shared between planes, so the vertex colour is the plane colour too (Open3D reads
    vertex colours, not face colours).
    """
    colors = np.asarray(colors, dtype=np.uint8).reshape(-1, 3)
    face_rgb = colors[mesh.plane_ids - first_id].reshape(-1, 3)
    vertex_rgb = np.zeros((len(mesh.vertices), 3), np.uint8)
    vertex_rgb[mesh.triangles.reshape(-1)] = np.repeat(face_rgb, 3, axis=0)
    write_ascii_ply(path, mesh.vertices, vertex_rgb, (mesh.triangles, face_rgb, mesh.plane_ids),
                    comment="monoplane plane regions; face plane_id = plane id in the "
                            "accompanying JSON")
