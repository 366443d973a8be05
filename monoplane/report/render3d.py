"""The reports' 3D pictures, drawn in this process by a software rasterizer.

The meshes of a report arrive shaded and are drawn unlit (see :class:`Mesh`), so a z-buffer
and interpolated vertex colours are all it takes to draw the pictures an OpenGL renderer
would, with no GL driver, no child process and no Open3D. For each :class:`Shot`:

1. numpy moves the shot's triangles and segments into the camera frame, clips them against
   the near plane ``z = near`` there (before the perspective divide: a point behind the camera
   has no image) and projects them with ``K`` scaled to :data:`SUPERSAMPLE` times the
   picture's size;
2. two numba kernels draw them into a white image with a z-buffer: triangles from both sides
   with perspective-correct colours, segments :data:`LINE_WIDTH` pixels wide;
3. ``cv2.resize(..., interpolation=cv2.INTER_AREA)`` averages each block of samples into one
   pixel (the anti-aliasing), and ``cv2.imwrite`` writes the PNG.

Cameras use OpenCV conventions throughout: a shot has intrinsics ``K`` (3, 3) in pixels of
its picture, pixel centres at integer coordinates, and a world-to-camera matrix (4, 4) with
x right, y down, z forward.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from monoplane.jit import kernel, run_threaded

#: Samples per pixel along each axis; each pixel is the mean of ``SUPERSAMPLE**2`` samples.
SUPERSAMPLE = 2
#: Width of line segments in pixels of the picture.
LINE_WIDTH = 2.0
#: A sample keeps what was drawn first unless a later surface is nearer by more than this
#: fraction of its depth. Coplanar surfaces (two views' pieces of one fused plane) then show
#: the first one drawn, not a noise of both decided by rounding.
DEPTH_TOLERANCE = 1e-6
#: The near plane's depth, as a fraction of the farthest vertex a shot draws: close enough to
#: the camera to cut off nothing a report shows, far enough that vertices cut there keep image
#: coordinates of moderate size (the kernels' edge tests take differences of them).
NEAR_FRACTION = 1e-3


@dataclass
class Primitives:
    """Indexed primitives: world points and rows of indices into them.

    Attributes
    ----------
    points : numpy.ndarray
        (N, 3) float world points.
    indices : numpy.ndarray
        (M, k) int point indices, one row per primitive.
    colors : numpy.ndarray
        (., 3) float colours in [0, 1]; per point or per primitive, as the subclass says.
    """

    points: np.ndarray
    indices: np.ndarray
    colors: np.ndarray


class Mesh(Primitives):
    """A triangle mesh to render: ``indices`` (T, 3) are its triangles, ``colors`` (N, 3) its
    vertex colours.

    The colours are drawn as they are, interpolated over each triangle (no lighting is applied,
    so shade them beforehand, e.g. with :func:`~monoplane.report.colors.shade`, where shape
    should read). Triangles are drawn from both sides.
    """


class Lines(Primitives):
    """Line segments to render (camera frusta, axes): ``indices`` (E, 2) are the segments,
    ``colors`` (E, 3) one colour per segment."""


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
        ``{shot name: PNG path}`` of the shots written.
    reason : str or None
        Why some shots have no picture (their PNG could not be written); None on full success.
    seconds : float
        Wall time of :func:`render`.
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
) -> RenderResult:
    """Render every shot to ``out_dir / f"{shot.name}.png"``.

    Parameters
    ----------
    meshes : list of Mesh
        Meshes the shots refer to by index (world frame).
    lines : list of Lines
        Line sets the shots refer to by index (world frame).
    shots : list of Shot
        Pictures to take.
    out_dir : pathlib.Path
        Existing folder for the PNGs.
    width, height : int
        Picture size in pixels (every shot's ``K`` is for this size).

    Returns
    -------
    RenderResult
        A PNG that cannot be written comes back as ``reason``, not as an exception.
    """
    t0 = time.perf_counter()
    out_dir = Path(out_dir)

    def take(shot: Shot) -> bool:
        return _write_png(out_dir / f"{shot.name}.png",
                          render_image(meshes, lines, shot, width, height))

    # The kernels, the resize and the PNG encoder release the GIL: shots render in parallel.
    written = run_threaded([functools.partial(take, shot) for shot in shots])
    paths = {s.name: out_dir / f"{s.name}.png" for s, ok in zip(shots, written, strict=True) if ok}
    # File names only: the report's folder is still a temporary one while it is written.
    unwritten = [f"{s.name}.png" for s, ok in zip(shots, written, strict=True) if not ok]
    reason = f"could not write {', '.join(unwritten)}" if unwritten else None
    return RenderResult(paths, reason, time.perf_counter() - t0)


def render_image(meshes: list[Mesh], lines: list[Lines], shot: Shot, width: int, height: int
                 ) -> np.ndarray:
    """One shot's picture.

    Parameters
    ----------
    meshes, lines, shot, width, height
        As for :func:`render`.

    Returns
    -------
    numpy.ndarray
        (height, width, 3) uint8 RGB; white where nothing is drawn.
    """
    s = SUPERSAMPLE
    # Sample (i, j) of the s-times larger grid has its centre at pixel (i + 0.5) / s - 0.5:
    # the s x s samples of a pixel sit symmetrically around its centre.
    K = np.array([[s, 0, (s - 1) / 2], [0, s, (s - 1) / 2], [0, 0, 1]]) @ np.asarray(shot.K, float)
    T = np.asarray(shot.world_to_cam, dtype=np.float64)
    # The shot's meshes as one: camera-frame vertices, their colours, triangles indexing them.
    verts, colors, tris = [np.zeros((0, 3))], [np.zeros((0, 3))], [np.zeros((0, 3), np.int64)]
    offset = 0
    for j, keep in shot.meshes.items():
        mesh = meshes[j]
        indices = np.asarray(mesh.indices, dtype=np.int64)
        tris.append((indices if keep is None else indices[keep]) + offset)
        verts.append(_to_camera(mesh.points, T))
        colors.append(np.clip(np.asarray(mesh.colors, dtype=np.float64), 0.0, 1.0))
        offset += len(verts[-1])
    seg_cam, seg_rgb = [np.zeros((0, 2, 3))], [np.zeros((0, 3))]
    for j in shot.lines:
        seg_cam.append(_to_camera(lines[j].points, T)[np.asarray(lines[j].indices)])
        seg_rgb.append(np.clip(np.asarray(lines[j].colors, dtype=np.float64), 0.0, 1.0))
    cam, segments = np.concatenate(verts), np.concatenate(seg_cam)

    image = np.ones((s * height, s * width, 3), dtype=np.float32)
    zbuf = np.zeros((s * height, s * width))  # 1/z of what each sample shows; 0 is the background
    depth = max(cam[:, 2].max(initial=0.0), segments[..., 2].max(initial=0.0))
    if depth > 0.0:
        near = NEAR_FRACTION * depth
        cam, rgb, triangles = clip_triangles(cam, np.concatenate(colors), np.concatenate(tris),
                                             near)
        _draw_triangles(*_project(cam, K, near), rgb, triangles, image, zbuf)
        segments, kept = clip_segments(segments, near)
        _draw_segments(*_project(segments, K, near), np.concatenate(seg_rgb)[kept],
                       s * LINE_WIDTH / 2.0, image, zbuf)
    small = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    return np.clip(np.rint(small * 255.0), 0, 255).astype(np.uint8)


def _to_camera(points: np.ndarray, world_to_cam: np.ndarray) -> np.ndarray:
    """(N, 3) world points -> (N, 3) float64 camera-frame points."""
    return np.asarray(points, dtype=np.float64) @ world_to_cam[:3, :3].T + world_to_cam[:3, 3]


def _project(cam: np.ndarray, K: np.ndarray, near: float) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (..., 2) and inverse depths 1/z (...) of camera points (..., 3), as
    C-contiguous float64 (the dtypes the kernels are compiled for). Points nearer than
    ``near``, which no clipped primitive uses, are projected as if at ``near``, to stay finite.
    """
    inv_z = 1.0 / np.maximum(cam[..., 2], near)
    xy = (cam @ K[:2].T) * inv_z[..., None]  # K's last row is (0, 0, 1): the divisor is z
    return np.ascontiguousarray(xy), np.ascontiguousarray(inv_z)


def _cut(p: np.ndarray, q: np.ndarray, near: float) -> np.ndarray:
    """Where the segments p -> q cross ``z = near``: (M, D) rows whose first three entries are
    camera points (z in column 2) and the rest attributes, interpolated alike (an attribute
    linear along a 3D segment stays linear). Each p, q pair must straddle the plane."""
    t = (near - p[:, 2]) / (q[:, 2] - p[:, 2])
    return p + t[:, None] * (q - p)


def _first(corners: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three corners of each triangle (M, 3, D), rotated so that corner ``k`` (M,) comes
    first (the winding is kept)."""
    order = (k[:, None] + np.arange(3)) % 3
    rows = np.take_along_axis(corners, order[:, :, None], axis=1)
    return rows[:, 0], rows[:, 1], rows[:, 2]


def clip_triangles(cam: np.ndarray, rgb: np.ndarray, triangles: np.ndarray, near: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cut triangles to the part in front of the plane ``z = near`` (camera frame).

    A triangle with one corner behind the plane becomes two triangles, one with two corners
    behind becomes one, both on new vertices (with colours cut along with the positions); a
    triangle entirely behind is dropped.

    Parameters
    ----------
    cam : numpy.ndarray
        (V, 3) float64 vertices, camera frame.
    rgb : numpy.ndarray
        (V, 3) float64 vertex colours.
    triangles : numpy.ndarray
        (T, 3) int64 vertex indices.
    near : float
        Depth of the near plane, > 0, camera units.

    Returns
    -------
    cam, rgb : numpy.ndarray
        (V', 3) float64 vertices and colours: the given ones, then the new ones.
    triangles : numpy.ndarray
        (T', 3) int64 indices of triangles whose corners all have z >= near.
    """
    behind = (cam[:, 2] < near)[triangles]
    count = behind.sum(axis=1)
    kept = triangles[count == 0]
    if len(kept) + np.count_nonzero(count == 3) == len(triangles):  # none crosses the plane
        return cam, rgb, kept
    vertices = np.concatenate([cam, rgb], axis=1)  # (V, 6): positions and colours, cut together
    one, two = count == 1, count == 2
    a, b, c = _first(vertices[triangles[one]], np.argmax(behind[one], axis=1))  # a is behind
    ab, ac = _cut(a, b, near), _cut(a, c, near)
    parts = [np.stack([ab, b, c], axis=1), np.stack([ab, c, ac], axis=1)]
    a, b, c = _first(vertices[triangles[two]], np.argmin(behind[two], axis=1))  # a is in front
    parts.append(np.stack([a, _cut(a, b, near), _cut(a, c, near)], axis=1))
    new = np.concatenate(parts).reshape(-1, 6)  # each new triangle on three new vertices
    vertices = np.concatenate([vertices, new])
    new_triangles = len(cam) + np.arange(len(new), dtype=np.int64).reshape(-1, 3)
    return (np.ascontiguousarray(vertices[:, :3]), np.ascontiguousarray(vertices[:, 3:]),
            np.concatenate([kept, new_triangles]))


def clip_segments(cam: np.ndarray, near: float) -> tuple[np.ndarray, np.ndarray]:
    """Cut segments to the part in front of the plane ``z = near`` (camera frame).

    Parameters
    ----------
    cam : numpy.ndarray
        (E, 2, 3) float segment ends, camera frame.
    near : float
        Depth of the near plane, > 0, camera units.

    Returns
    -------
    cam : numpy.ndarray
        (E', 2, 3) float64 segment ends, all with z >= near.
    kept : numpy.ndarray
        (E,) bool: which segments are left (those not entirely behind the plane).
    """
    behind = cam[..., 2] < near
    kept = np.count_nonzero(behind, axis=1) < 2
    out = np.array(cam[kept], dtype=np.float64)
    behind = behind[kept]
    crossing = np.flatnonzero(behind.any(axis=1))
    out[crossing, np.argmax(behind[crossing], axis=1)] = _cut(
        out[crossing, 0], out[crossing, 1], near)
    return out, kept


@kernel
def _draw_triangles(xy: np.ndarray, inv_z: np.ndarray, rgb: np.ndarray, triangles: np.ndarray,
                    image: np.ndarray, zbuf: np.ndarray) -> None:
    """Draw triangles where they are nearer than what ``zbuf`` holds.

    ``xy`` (V, 2) float64 vertices in sample coordinates (centres at integers), ``inv_z`` (V,)
    float64 their 1/z (camera depth, > 0), ``rgb`` (V, 3) float64 their colours, ``triangles``
    (T, 3) int64 vertex indices; ``image`` (H, W, 3) float32 and ``zbuf`` (H, W) float64 (1/z,
    larger is nearer) are updated in place (ties within :data:`DEPTH_TOLERANCE` keep what is
    there). A sample is covered when its centre is inside the
    triangle or on its edge, for either winding (both sides are drawn; a shared edge is drawn
    by both triangles, so no gap opens between them). 1/z and colour/z are affine in the
    image, so they are interpolated with the image's barycentric coordinates, and
    (colour/z) / (1/z) is the perspective-correct colour.
    """
    height, width = zbuf.shape
    weighted = np.empty((3, 3))
    depth = np.empty(3)
    for i in range(triangles.shape[0]):
        v0, v1, v2 = triangles[i, 0], triangles[i, 1], triangles[i, 2]
        x0, y0 = xy[v0, 0], xy[v0, 1]
        x1, y1 = xy[v1, 0], xy[v1, 1]
        x2, y2 = xy[v2, 0], xy[v2, 1]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if area == 0.0:  # seen edge-on
            continue
        inv_area = 1.0 / area
        lo_x, hi_x = max(min(x0, x1, x2), 0.0), min(max(x0, x1, x2), width - 1.0)
        lo_y, hi_y = max(min(y0, y1, y2), 0.0), min(max(y0, y1, y2), height - 1.0)
        if lo_x > hi_x or lo_y > hi_y:
            continue
        for k in range(3):
            v = triangles[i, k]
            depth[k] = inv_z[v]
            for c in range(3):
                weighted[k, c] = rgb[v, c] * inv_z[v]
        for py in range(int(np.ceil(lo_y)), int(np.floor(hi_y)) + 1):
            for px in range(int(np.ceil(lo_x)), int(np.floor(hi_x)) + 1):
                # Relative to the corners, not expanded into a px + b py + c: a corner moved
                # far out by the near-plane cut would make c cancel catastrophically.
                b0 = ((x1 - px) * (y2 - py) - (x2 - px) * (y1 - py)) * inv_area
                b1 = ((x2 - px) * (y0 - py) - (x0 - px) * (y2 - py)) * inv_area
                b2 = ((x0 - px) * (y1 - py) - (x1 - px) * (y0 - py)) * inv_area
                if b0 < 0.0 or b1 < 0.0 or b2 < 0.0:
                    continue
                z = b0 * depth[0] + b1 * depth[1] + b2 * depth[2]
                if z <= zbuf[py, px] * (1.0 + DEPTH_TOLERANCE):
                    continue
                zbuf[py, px] = z
                for c in range(3):
                    image[py, px, c] = (b0 * weighted[0, c] + b1 * weighted[1, c]
                                        + b2 * weighted[2, c]) / z


@kernel
def _draw_segments(xy: np.ndarray, inv_z: np.ndarray, rgb: np.ndarray, half_width: float,
                   image: np.ndarray, zbuf: np.ndarray) -> None:
    """Draw line segments ``2 * half_width`` samples wide where they are nearer than ``zbuf``.

    ``xy`` (E, 2, 2) float64 ends in sample coordinates, ``inv_z`` (E, 2) float64 their 1/z,
    ``rgb`` (E, 3) float64 one colour per segment; ``image`` and ``zbuf`` as for
    :func:`_draw_triangles`, updated in place. Each segment is walked along its major image
    axis, one sample at a time, lighting a run of samples across it whose length keeps the
    width measured perpendicular to the segment; the ends are cut square. 1/z is affine along
    the projected segment, so it is interpolated linearly there.
    """
    height, width = zbuf.shape
    for e in range(xy.shape[0]):
        x0, y0, x1, y1 = xy[e, 0, 0], xy[e, 0, 1], xy[e, 1, 0], xy[e, 1, 1]
        steep = abs(y1 - y0) > abs(x1 - x0)
        # (a, b): the major and minor axes; na, nb: the image's extent along them.
        if steep:
            a0, a1, b0, b1, na, nb = y0, y1, x0, x1, height, width
        else:
            a0, a1, b0, b1, na, nb = x0, x1, y0, y1, width, height
        if a1 == a0:  # seen end-on
            continue
        slope = (b1 - b0) / (a1 - a0)
        reach = half_width * np.sqrt(1.0 + slope * slope)
        lo, hi = max(min(a0, a1), 0.0), min(max(a0, a1), na - 1.0)
        if lo > hi:
            continue
        for a in range(int(np.ceil(lo)), int(np.floor(hi)) + 1):
            t = (a - a0) / (a1 - a0)
            mid = b0 + t * (b1 - b0)
            z = inv_z[e, 0] + t * (inv_z[e, 1] - inv_z[e, 0])
            # The half-open run [mid - reach, mid + reach) holds exactly 2 * reach samples
            # when that is an integer, wherever the segment passes.
            first = int(np.ceil(max(mid - reach, 0.0)))
            last = int(np.ceil(min(mid + reach, float(nb)))) - 1
            for b in range(first, last + 1):
                px, py = (b, a) if steep else (a, b)
                if z <= zbuf[py, px] * (1.0 + DEPTH_TOLERANCE):
                    continue
                zbuf[py, px] = z
                for c in range(3):
                    image[py, px, c] = rgb[e, c]


def _write_png(path: Path, rgb: np.ndarray) -> bool:
    """Write (H, W, 3) uint8 RGB as a PNG; False when it cannot be written (OpenCV returns
    False for a missing folder and raises for some other failures)."""
    try:
        return bool(cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1])))
    except cv2.error:
        return False
