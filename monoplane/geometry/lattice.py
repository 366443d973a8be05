"""Regular pixel lattices of an organised frame: which rows and columns a frame's cloud keeps
when it is sampled on a lattice (:meth:`monoplane.geometry.cloud.PlaneCloud.from_frame` with
``grid``), for at most a given number of valid pixels.

A lattice of step ``s`` keeps the rows and columns ``⌊(i + ½) s⌋``: for a whole ``s`` every
``s``-th line from ``s // 2``, for a fractional one lines ``⌊s⌋`` and ``⌈s⌉`` apart.

The lattice's 8-neighbourhood graph (:func:`pixel_grid_edges`) and its turn weights
(:func:`turn_scale`), from which
:meth:`~monoplane.geometry.graph.NeighbourGraph.from_lattice` and the ``graph-crf`` refiner's
pixel graph are built.
"""

from __future__ import annotations

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.jit import kernel


def lattice_lines(size: int, step: float) -> np.ndarray:
    """Pixel rows (or columns) ``⌊(i + ½) step⌋`` of a lattice across ``size`` pixels.

    A whole ``step`` gives every ``step``-th line from ``step // 2``; a fractional one spaces
    the lines ``⌊step⌋`` and ``⌈step⌉`` apart, so that the lattice can hold as many points
    as asked for at any resolution.

    Parameters
    ----------
    size : int
        Image height (or width) in pixels.
    step : float
        Lattice step in pixels, >= 1.

    Returns
    -------
    numpy.ndarray
        (L,) int64 ascending distinct lines in ``[0, size)``.
    """
    lines = np.floor((np.arange(int(np.ceil(size / step)) + 1) + 0.5) * step).astype(np.int64)
    return lines[lines < size]


def lattice_step(valid: np.ndarray, max_points: int, *, whole: bool = False) -> float:
    """Smallest lattice step (to 0.1 %, or a whole one) that keeps at most ``max_points`` valid
    pixels.

    Parameters
    ----------
    valid : numpy.ndarray
        (H, W) bool valid pixels.
    max_points : int
        Most lattice pixels to keep, >= 3.
    whole : bool
        Only whole steps: every ``s``-th pixel of every ``s``-th row from ``s // 2``.

    Returns
    -------
    float
        Step ``s >= 1`` in pixels (a whole number with ``whole``) such that the valid pixels on
        the rows and columns :func:`lattice_lines` ``(·, s)`` number at most ``max_points``.
    """
    if max_points < 3:
        raise InvalidInput(f"max_points must be at least 3, got {max_points}")
    h, w = valid.shape

    def kept(step: float) -> int:
        return int(np.count_nonzero(valid[np.ix_(lattice_lines(h, step), lattice_lines(w, step))]))

    # The valid fraction is about the same on every lattice: start from the step it gives and
    # grow it by the excess (or by one pixel) until the lattice fits.
    step = max(1.0, float(np.sqrt(np.count_nonzero(valid) / max_points)))
    if whole:
        step = float(np.ceil(step))
    while (count := kept(step)) > max_points:
        step = step + 1.0 if whole else step * max(1.001, float(np.sqrt(count / max_points)))
    return step


def lattice_stride(valid: np.ndarray, max_points: int) -> int:
    """:func:`lattice_step` with ``whole``, as an int."""
    return int(lattice_step(valid, max_points, whole=True))


@kernel
def turn_scale(edges: np.ndarray, normals: np.ndarray, sigma_deg: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """(E,) ``exp(-t² / 2σ²)`` of the (E, 2) edges, t the angle in degrees between the unit
    ``normals`` (N, 3) of their ends, and (E,) those angles in radians (the proximity cut
    costs take them, :func:`monoplane.algorithm.graph_costs.proximity_weights`)."""
    out = np.empty(edges.shape[0])
    angle = np.empty(edges.shape[0])
    to_deg = 180.0 / np.pi
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        cos = (normals[a, 0] * normals[b, 0] + normals[a, 1] * normals[b, 1]
               + normals[a, 2] * normals[b, 2])
        angle[e] = np.arccos(min(max(cos, -1.0), 1.0))
        t = angle[e] * to_deg / sigma_deg
        out[e] = np.exp(-0.5 * t * t)
    return out, angle


@kernel
def pixel_grid_edges(index: np.ndarray, points: np.ndarray, shift: np.ndarray, max_jump: float,
                     normals: np.ndarray, cos_min: float
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The 8-connected graph of :func:`monoplane.stages.graph_refiner.pixel_graph`, of the
    (H, W) int64 node ``index`` of each pixel (-1: none).

    A pair is cut when its 3D distance exceeds ``max_jump`` times the first point's distance
    from the camera, or when the cosine between its ``normals`` ((N, 3) unit) is below
    ``cos_min`` (-2 keeps every pair whatever its normals).

    Nodes number the valid pixels in raster order, so the four forward neighbours of a
    pixel, taken in raster order (right, below left, below, below right), are larger nodes
    in ascending order: scanning the pixels gives the edges sorted by ``(i, j)``.

    Returns
    -------
    edges : numpy.ndarray
        (E, 2) int64 kept edges, ``i < j``, sorted.
    gap : numpy.ndarray
        (M,) float64 3D distance of every candidate pair, kept or not.
    indptr, indices : numpy.ndarray
        Adjacency: the neighbours of node ``i`` are its larger ones, ascending, then its
        smaller ones, ascending.
    """
    h, w = index.shape
    n = points.shape[0]
    edges = np.empty((4 * n, 2), dtype=np.int64)
    gap = np.empty(4 * n, dtype=np.float64)
    kept = pairs = 0
    for v in range(h):
        for u in range(w):
            a = index[v, u]
            if a < 0:
                continue
            # sqrt of the squares summed in order, as numpy's norm over an axis of 3.
            x = points[a, 0] + shift[0]
            y = points[a, 1] + shift[1]
            z = points[a, 2] + shift[2]
            reach = max_jump * max(np.sqrt(x * x + y * y + z * z), 1e-12)
            for dv, du in ((0, 1), (1, -1), (1, 0), (1, 1)):
                vv, uu = v + dv, u + du
                if vv >= h or not 0 <= uu < w:
                    continue
                b = index[vv, uu]
                if b < 0:
                    continue
                dx = points[a, 0] - points[b, 0]
                dy = points[a, 1] - points[b, 1]
                dz = points[a, 2] - points[b, 2]
                g = np.sqrt(dx * dx + dy * dy + dz * dz)
                gap[pairs] = g
                pairs += 1
                agree = (normals[a, 0] * normals[b, 0] + normals[a, 1] * normals[b, 1]
                         + normals[a, 2] * normals[b, 2])
                if g <= reach and agree >= cos_min:
                    edges[kept, 0] = a
                    edges[kept, 1] = b
                    kept += 1
    edges = edges[:kept].copy()
    larger = np.zeros(n, dtype=np.int64)
    degree = np.zeros(n, dtype=np.int64)
    for e in range(kept):
        larger[edges[e, 0]] += 1
        degree[edges[e, 0]] += 1
        degree[edges[e, 1]] += 1
    indptr = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        indptr[i + 1] = indptr[i] + degree[i]
    first = indptr[:-1].copy()  # next free slot of each node's larger neighbours
    second = indptr[:-1] + larger  # ... and of its smaller ones
    indices = np.empty(2 * kept, dtype=np.int64)
    for e in range(kept):
        a, b = edges[e, 0], edges[e, 1]
        indices[first[a]] = b
        first[a] += 1
        indices[second[b]] = a
        second[b] += 1
    return edges, gap[:pairs].copy(), indptr, indices
