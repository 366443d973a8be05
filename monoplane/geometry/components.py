"""Connected regions of a label image, and connected components of a graph's nodes.

Both the region clean-up after refinement (every plane label split into its connected regions)
and the depth-edge segmentation of normal estimation need the connected regions of an image
whose pixels carry integer labels; RANSAC keeps the largest connected part of each plane's
inliers in the neighbourhood graph (on a pixel lattice also across thin occluders,
:func:`lattice_largest_component`). Both are union-find passes sharing :func:`_union`. One
pass over the pixels finds the regions of all labels at once, where labelling each label's mask
separately would scan the image once per label.

Numbering: regions are numbered from 1 by their label, then by the raster position (row-major)
of their first pixel. For a binary mask this is the numbering of ``scipy.ndimage.label`` with
the matching structure; the tests hold the two to each other.
"""

from __future__ import annotations

import numpy as np

from monoplane.errors import InvalidInput
from monoplane.jit import inline, kernel


def label_regions(labels: np.ndarray, connectivity: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Give every connected region of every non-zero label its own number.

    Parameters
    ----------
    labels : numpy.ndarray
        (H, W) integer or bool label image; 0 (False) is background and forms no region.
    connectivity : {4, 8}
        4: pixels sharing an edge connect; 8: corners connect too.

    Returns
    -------
    regions : numpy.ndarray
        (H, W) int32 region numbers 1..R (0 on the background), by label then by the raster
        position of each region's first pixel.
    origin : numpy.ndarray
        (R,) int64 label of each region (``origin[r - 1]`` for region ``r``).

    Raises
    ------
    InvalidInput
        If the image is not 2-D, has negative labels, or ``connectivity`` is not 4 or 8.
    """
    lab = np.asarray(labels)
    if lab.ndim != 2:
        raise InvalidInput(f"labels must be (H, W), got {lab.shape}")
    if connectivity not in (4, 8):
        raise InvalidInput(f"connectivity must be 4 or 8, got {connectivity}")
    lab = np.ascontiguousarray(lab, dtype=np.int64)
    if lab.size and lab.min() < 0:
        raise InvalidInput("labels must be >= 0")
    return _label_regions(lab, connectivity == 8)


def largest_component(members: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Largest connected component among some nodes of a graph.

    Parameters
    ----------
    members : numpy.ndarray
        (M,) bool selection of the graph's M nodes.
    edges : numpy.ndarray
        (E, 2) int node pairs; only those between two members count.

    Returns
    -------
    numpy.ndarray
        (K,) bool over the K members in order, True on the largest component; among equally
        large ones, the one holding the lowest-numbered member.
    """
    return _largest_component(np.ascontiguousarray(members, dtype=np.bool_),
                              np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2))


def graph_components(num_nodes: int, edges: np.ndarray) -> np.ndarray:
    """Connected component of every node of an undirected graph.

    Parameters
    ----------
    num_nodes : int
        Number N of nodes.
    edges : numpy.ndarray
        (E, 2) int node pairs in ``0 .. N-1``.

    Returns
    -------
    numpy.ndarray
        (N,) int64 component ids ``0 .. C-1``, numbered by each component's smallest node
        (the numbering of ``scipy.sparse.csgraph.connected_components``).
    """
    pairs = np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2)
    if pairs.size and (pairs.min() < 0 or pairs.max() >= num_nodes):
        raise InvalidInput(f"edge ends must lie in 0..{num_nodes - 1}")
    return _graph_components(int(num_nodes), pairs)


def same_label_components(labels: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """:func:`graph_components` of the edges that join two nodes of the same positive label.

    Parameters
    ----------
    labels : numpy.ndarray
        (N,) int labels; nodes of label 0 or below join nothing.
    edges : numpy.ndarray
        (E, 2) int node pairs in ``0 .. N-1``.

    Returns
    -------
    numpy.ndarray
        (N,) int64 component ids, numbered as :func:`graph_components` numbers them: the
        same as ``graph_components(N, edges[same])`` without building ``edges[same]``.
    """
    lab = np.ascontiguousarray(labels, dtype=np.int64).ravel()
    pairs = np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2)
    if pairs.size and (pairs.min() < 0 or pairs.max() >= lab.size):
        raise InvalidInput(f"edge ends must lie in 0..{lab.size - 1}")
    return _graph_components_within(lab, pairs)


@kernel
def _graph_components_within(labels: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """:func:`same_label_components` of (N,) int64 ``labels`` and (E, 2) int64 ``edges``."""
    n = labels.shape[0]
    parent = np.arange(n)
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        if labels[a] > 0 and labels[a] == labels[b]:
            _union(parent, a, b)
    return _numbered(parent)


@inline
def _numbered(parent: np.ndarray) -> np.ndarray:
    """Component ids of a union-find forest whose roots are their sets' smallest nodes,
    numbered in the order of those nodes."""
    n = parent.shape[0]
    comp = np.empty(n, dtype=np.int64)
    count = 0
    for p in range(n):  # a root is its set's smallest node, met before the rest of its set
        r = p
        while parent[r] != r:
            r = parent[r]
        if r == p:
            comp[p] = count
            count += 1
        else:
            comp[p] = comp[r]
    return comp


@kernel
def _graph_components(n: int, edges: np.ndarray) -> np.ndarray:
    """:func:`graph_components` of ``n`` nodes and (E, 2) int64 ``edges``."""
    parent = np.arange(n)
    for e in range(edges.shape[0]):
        _union(parent, edges[e, 0], edges[e, 1])
    return _numbered(parent)


@inline
def _union(parent: np.ndarray, a: int, b: int) -> None:
    """Join the sets of ``a`` and ``b`` in the union-find forest ``parent``, keeping the
    smaller root (so a root is always its set's smallest index); paths are halved."""
    while parent[a] != a:
        parent[a] = parent[parent[a]]
        a = parent[a]
    while parent[b] != b:
        parent[b] = parent[parent[b]]
        b = parent[b]
    if a < b:
        parent[b] = a
    elif b < a:
        parent[a] = b


@kernel
def _largest_component(members: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """:func:`largest_component` of (M,) bool ``members`` and (E, 2) int64 ``edges``."""
    parent = np.arange(members.shape[0])
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        if members[a] and members[b]:
            _union(parent, a, b)
    return _largest_root_members(np.flatnonzero(members), parent)


@kernel
def _label_regions(lab: np.ndarray, corners: bool) -> tuple[np.ndarray, np.ndarray]:
    """:func:`label_regions` of a (H, W) int64 image (``corners``: 8-connectivity).

    Works on runs (maximal row segments of one label) rather than pixels: a run joins the
    runs of its label in the row above that it touches, so the union-find has one node per
    run, a small fraction of the pixels on label maps made of regions.
    """
    h, w = lab.shape
    n = h * w
    # Runs in raster order: start column, end column (exclusive), row, label.
    start = np.empty(n, dtype=np.int64)
    end = np.empty(n, dtype=np.int64)
    row = np.empty(n, dtype=np.int64)
    value = np.empty(n, dtype=np.int64)
    first = np.zeros(h + 1, dtype=np.int64)  # runs of row y: first[y]:first[y + 1]
    count = 0
    for y in range(h):
        x = 0
        while x < w:
            v = lab[y, x]
            x0 = x
            while x < w and lab[y, x] == v:
                x += 1
            if v != 0:
                start[count], end[count], row[count], value[count] = x0, x, y, v
                count += 1
        first[y + 1] = count
    # Union-find over runs whose root is always the smallest run index of its set, i.e. the
    # run holding the region's first pixel in raster order.
    parent = np.arange(count)
    reach = 1 if corners else 0  # 8-connectivity also joins runs that touch at a corner
    for y in range(1, h):
        j = first[y - 1]
        for i in range(first[y], first[y + 1]):
            # Runs above that end left of this one end left of the next ones too.
            while j < first[y] and end[j] + reach <= start[i]:
                j += 1
            k = j
            while k < first[y] and start[k] < end[i] + reach:
                if value[k] == value[i]:
                    _union(parent, i, k)
                k += 1
    top = 0
    for r in range(count):
        top = max(top, value[r])
    per_label = np.zeros(top + 2, dtype=np.int64)
    for r in range(count):
        if parent[r] == r:
            per_label[value[r] + 1] += 1
    for v in range(top + 1):
        per_label[v + 1] += per_label[v]
    origin = np.empty(per_label[top + 1], dtype=np.int64)
    number = np.zeros(count, dtype=np.int32)
    nxt = per_label[:-1].copy()
    out = np.zeros((h, w), dtype=np.int32)
    for r in range(count):
        root = r
        while parent[root] != root:
            root = parent[root]
        if root == r:
            nxt[value[r]] += 1
            number[r] = nxt[value[r]]
            origin[nxt[value[r]] - 1] = value[r]
        for x in range(start[r], end[r]):
            out[row[r], x] = number[root]
    return out, origin


def lattice_largest_component(members: np.ndarray, lattice: np.ndarray, points: np.ndarray,
                              shift: np.ndarray, max_jump: float, reach: int) -> np.ndarray:
    """Largest connected part of some points sampled on a pixel lattice, linked across thin
    occluders.

    Two members are linked when they are the nearest members along one of the lattice's four
    line directions (row, column, both diagonals), at most ``reach`` steps apart, every node
    between them has no point or a point nearer to the camera than the first member by more
    than its jump limit (an occluder in front), and their 3D distance is within ``max_jump``
    times the first member's distance from the camera (the jump test of
    :func:`monoplane.geometry.lattice.pixel_grid_edges`). With ``reach`` 1 these are the
    lattice graph's own links; with more, a plane seen on both sides of a table leg stays one
    part, as the kNN graph, which links in 3D, keeps it. A node between them that lies as far
    as the members or farther (the rest of a curved surface, a floor seen through a ring)
    ends the line: inliers scattered over one surface stay apart.

    Parameters
    ----------
    members : numpy.ndarray
        (N,) bool selection of the points.
    lattice : numpy.ndarray
        (R, C) int64 point at each lattice node, -1 where there is none
        (:attr:`monoplane.geometry.cloud.PlaneCloud.lattice`).
    points : numpy.ndarray
        (N, 3) float64 normalised points.
    shift : numpy.ndarray
        (3,) float64 camera centre's offset in the normalised frame (``center / scale``).
    max_jump : float
        Jump limit as a fraction of a point's distance from the camera.
    reach : int
        Most lattice steps between two linked members, >= 1.

    Returns
    -------
    numpy.ndarray
        (K,) bool over the K members in ascending point order, True on the largest part;
        among equally large ones, the one holding the lowest-numbered member.
    """
    if reach < 1:
        raise InvalidInput(f"reach must be at least 1, got {reach}")
    return _lattice_largest_component(np.ascontiguousarray(members, dtype=np.bool_),
                                      np.ascontiguousarray(lattice, dtype=np.int64),
                                      np.ascontiguousarray(points, dtype=np.float64),
                                      np.ascontiguousarray(shift, dtype=np.float64),
                                      float(max_jump), int(reach))


@kernel
def _lattice_largest_component(members: np.ndarray, lattice: np.ndarray, points: np.ndarray,
                               shift: np.ndarray, max_jump: float, reach: int) -> np.ndarray:
    """:func:`lattice_largest_component`.

    It runs once per plane the search finds, on a cloud of 40 000 points of which a plane
    holds a few per cent: past the raster scan of the lattice (one membership test a node)
    and the list of the members, the work is at the members and the nodes a line from them
    visits (distances from the camera as they are needed, the union-find forest and the
    set sizes only at the members).
    """
    n = members.shape[0]
    ids = np.flatnonzero(members)  # ascending: the order of the result
    parent = np.empty(n, dtype=np.int64)  # read and written at members only
    for p in ids:
        parent[p] = p
    rows, cols = lattice.shape
    for v in range(rows):
        for u in range(cols):
            a = lattice[v, u]
            if a < 0 or not members[a]:
                continue
            distance = _camera_distance(points, shift, a)
            limit = max_jump * distance
            for dv, du in ((0, 1), (1, -1), (1, 0), (1, 1)):
                vv, uu = v, u
                for _ in range(reach):
                    vv += dv
                    uu += du
                    if vv >= rows or uu < 0 or uu >= cols:
                        break
                    b = lattice[vv, uu]
                    if b < 0:
                        continue  # no depth here: it may hide the plane
                    if members[b]:
                        dx = points[a, 0] - points[b, 0]
                        dy = points[a, 1] - points[b, 1]
                        dz = points[a, 2] - points[b, 2]
                        if dx * dx + dy * dy + dz * dz <= limit * limit:
                            _union(parent, a, b)
                        break
                    if _camera_distance(points, shift, b) > distance - limit:
                        break  # not an occluder in front of the plane: its part ends here
    return _largest_root_members(ids, parent)


@inline
def _camera_distance(points: np.ndarray, shift: np.ndarray, p: int) -> float:
    """Distance from the camera of normalised point ``p`` of (N, 3) ``points``, whose frame
    has the camera at ``-shift``."""
    x = points[p, 0] + shift[0]
    y = points[p, 1] + shift[1]
    z = points[p, 2] + shift[2]
    return np.sqrt(x * x + y * y + z * z)


@inline
def _largest_root_members(ids: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """(K,) bool over the K members ``ids`` (ascending int64 nodes): in the union-find forest
    ``parent`` (read at the members and their ancestors only), True on the largest set of
    members (the one of the lowest member on ties)."""
    size = np.empty(parent.shape[0], dtype=np.int64)  # used at the roots, which are members
    for p in ids:
        size[p] = 0
    root = np.empty(ids.shape[0], dtype=np.int64)
    for k in range(ids.shape[0]):
        r = ids[k]
        while parent[r] != r:
            r = parent[r]
        root[k] = r
        size[r] += 1
    best = -1
    for k in range(ids.shape[0]):  # ascending, so ties go to the lowest member's set
        if best < 0 or size[root[k]] > size[best]:
            best = root[k]
    return root == best
