"""Fully connected CRF over a label map with Gaussian edge potentials (paper appendix, eq. 13).

The energy is ``E(x) = Σ_i ψ_u(x_i) + Σ_{i<j} ψ_p(x_i, x_j)`` with a Potts pairwise term
``ψ_p = [x_i ≠ x_j] Σ_m w_m k_m(f_i, f_j)`` and Gaussian kernels
``k_m = exp(-½ |f_i^m - f_j^m|²)`` over per-pixel feature vectors ``f^m`` that are already
divided by their deviations θ (see :func:`crf_features`). It is minimised approximately by
mean-field inference (Krähenbühl & Koltun, NeurIPS 2011): every iteration filters the current
marginals with each kernel, and the high-dimensional Gaussian filtering is done on a
permutohedral lattice (Adams, Baek & Davis, Eurographics 2010), linear in the pixel count,
instead of the O(N²) dense sum.

The lattice and the mean-field iterations live in :mod:`monoplane.algorithm.mean_field`; this
module builds the image CRF on them (features, coarse grid, final labels).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import cv2
import numpy as np

# PermutohedralLattice and pairwise are not used here: they stay importable from this module, where
# they lived until the split into mean_field.py.
from monoplane.algorithm.crf_labels import (
    RESIZED_LABEL_COUNTS,
    bilinear_taps,
    certified_cells,
    exact_labels,
    upsampled_labels,
)
from monoplane.algorithm.mean_field import (  # noqa: F401
    GaussianKernel,
    PermutohedralLattice,
    dearest_first,
    mean_field,
    pairwise,
    unary_from_labels,
)
from monoplane.errors import InvalidInput
from monoplane.jit import chunks, kernel, run_threaded

#: Image area (256 x 192) at which the paper's pixel-valued parameters (θ_s = 10 px, minimum
#: region 300 px) are stated; other resolutions scale them.
REFERENCE_AREA = 256 * 192

#: Rows per threaded piece of the final full-resolution labelling, below which one thread
#: labels the whole image.
_THREADED_ROWS = 64

#: Band pixels per threaded piece of the messages at full resolution, below which one thread
#: does them all.
_THREADED_PIXELS = 4096


@dataclass(frozen=True)
class CrfParams:
    """Parameters of the image-level dense CRF (paper appendix).

    There are no defaults here: they live once, in the image refiner's config
    (:class:`monoplane.stages.refiners.DenseCrfRefiner.Config`), which builds this object.

    Feature scaling (what each θ divides)
    -------------------------------------
    * position ``p``: pixel coordinates (u, v). ``theta_position`` is in pixels at the paper's
      256 x 192 resolution and is scaled by ``sqrt(H W / (256 · 192))`` so that the kernels
      cover the same part of the image at any resolution. All four kernels use it, as in the
      paper's equations.
    * colour ``I``: RGB in 8-bit levels (0-255), so ``theta_color = 10`` is 10 grey levels.
    * depth ``D``: z-depth divided by the frame's largest valid depth, i.e. in (0, 1] and free
      of the depth's unit and scale (metric and relative depth behave the same). Invalid
      pixels have D = 0.
    * normal ``N``: the unit normal vector (camera frame); ``|N_i - N_j| = 2 sin(angle/2)``, so
      0.1 corresponds to about 5.7°. Invalid normals are (0, 0, 0).

    The paper lists θ = [θ_s, θ_a, θ_d, θ_n] = [10, 10, 0.1, 0.01] but its equations pair θ_d
    with the normals and θ_n with the depth. We follow the equations: 0.1 for the normal
    kernel and 0.01 for the depth kernel. A deviation of 0.01 (0.6°) on unit normals would only
    link pixels whose predicted normals agree almost exactly, which monocular normals never do
    across a plane; 0.1 (≈ 6°, under the RANSAC's ε_n = 10°) groups pixels of the same
    orientation. On depth normalised to (0, 1], 0.01 (1 % of the depth range) is a sharp,
    edge-preserving kernel that does not cross depth discontinuities.

    ``uniform_nonplanar`` (not in the paper): pixels observed with label 0 (non-planar) get a
    uniform unary (see :func:`unary_from_labels`), so the kernels alone decide their label.

    ``max_pixels`` (not in the paper; 0 = no cap): above this many pixels, mean-field inference
    runs on a grid coarsened by an integer factor (see :func:`dense_crf`), since building the
    lattices costs time linear in the pixel count while the kernels (θ_s scales with the image)
    are many pixels wide anyway.

    ``band_margin`` (not in the paper; inf = off), with the coarse grid: of the band of
    pixels next to a coarse label change, only those whose upsampled messages leave the two
    best labels less than this many nats apart get exact messages (see :func:`dense_crf`).
    """

    theta_position: float
    theta_color: float
    theta_depth: float
    theta_normal: float
    w_smoothness: float
    w_appearance: float
    w_depth: float
    w_normal: float
    confidence: float
    iterations: int
    uniform_nonplanar: bool
    max_pixels: int
    band_margin: float

    def __post_init__(self) -> None:
        for name in ("theta_position", "theta_color", "theta_depth", "theta_normal"):
            if not getattr(self, name) > 0:
                raise InvalidInput(f"{name} must be positive, got {getattr(self, name)}")
        for name in ("w_smoothness", "w_appearance", "w_depth", "w_normal"):
            if not getattr(self, name) >= 0:
                raise InvalidInput(f"{name} must be >= 0 (0 disables the kernel)")
        if self.iterations < 0:
            raise InvalidInput(f"iterations must be >= 0, got {self.iterations}")
        if self.max_pixels < 0:
            raise InvalidInput(f"max_pixels must be >= 0 (0: no cap), got {self.max_pixels}")
        if not self.band_margin > 0:
            raise InvalidInput(f"band_margin must be positive (inf: whole band), got "
                               f"{self.band_margin}")


def crf_features(
    shape: tuple[int, int],
    params: CrfParams,
    rgb: np.ndarray | None = None,
    depth: np.ndarray | None = None,
    normals: np.ndarray | None = None,
) -> list[GaussianKernel]:
    """Build the enabled kernels of the paper's four (smoothness, appearance, depth, normal).

    A kernel is dropped when its weight is 0 or its cue is missing: no ``rgb`` (or a grey one,
    all channels equal) drops appearance, no ``depth`` drops depth, no ``normals`` drops normal.

    Parameters
    ----------
    shape : tuple of int
        ``(H, W)``.
    params : CrfParams
        Deviations and weights (see :class:`CrfParams` for the feature units).
    rgb : numpy.ndarray, optional
        (H, W, 3) uint8 RGB.
    depth : numpy.ndarray, optional
        (H, W) z-depth, any unit, 0 = invalid.
    normals : numpy.ndarray, optional
        (H, W, 3) unit normals in the camera frame (OpenCV axes), zero where invalid.

    Returns
    -------
    list of GaussianKernel
        Kernels in the order smoothness, appearance, depth, normal (those enabled).
    """
    h, w = shape
    v, u = np.mgrid[0:h, 0:w]
    cues = _Cues.of(params, rgb, depth, normals)
    return _kernels(cues.features(params, u.ravel(), v.ravel(), h * w, np.arange(h * w)))


def _kernels(specs: list[tuple[np.ndarray, float]], threaded: bool = True
             ) -> list[GaussianKernel]:
    """Build kernels from (features, weight) pairs, in parallel threads (numba, no GIL), the
    highest-dimensional first; one after the other on this thread unless ``threaded``."""
    order = sorted(range(len(specs)), key=lambda i: (-specs[i][0].shape[1], i))
    tasks = [lambda s=specs[i]: GaussianKernel(*s) for i in order]
    built = run_threaded(tasks) if threaded else [task() for task in tasks]
    by_spec = dict(zip(order, built, strict=True))
    return [by_spec[i] for i in range(len(specs))]


@dataclass
class _Cues:
    """A frame's cues, flattened, with what decides which kernels exist (see crf_features).

    Each array is the frame's own (a flat view, not converted): features are scaled only at
    the pixels asked for (block centres, the band), which gives the values scaling every
    pixel first would (elementwise float64 arithmetic) without converting whole images.
    """

    rgb: np.ndarray | None
    """(H W, 3) RGB, or None when absent, grey or weighted 0."""
    depth: np.ndarray | None
    """(H W,) depth, or None when absent, all invalid or weighted 0."""
    depth_top: float
    """Largest depth, which depth is divided by (with θ_d)."""
    normals: np.ndarray | None
    """(H W, 3) normals, or None when absent or weighted 0."""

    @classmethod
    def of(cls, params: CrfParams, rgb: np.ndarray | None, depth: np.ndarray | None,
           normals: np.ndarray | None) -> _Cues:
        grey = rgb is None or not (np.any(rgb[..., 0] != rgb[..., 1])
                                   or np.any(rgb[..., 1] != rgb[..., 2]))
        col = None if grey or not params.w_appearance > 0 else np.asarray(rgb).reshape(-1, 3)
        dep, top = None, 0.0
        if depth is not None and params.w_depth > 0:
            flat = np.asarray(depth).ravel()
            top = float(flat.max()) if flat.size else 0.0
            if top > 0:
                dep = flat
        nor = None if normals is None or not params.w_normal > 0 else (
            np.asarray(normals).reshape(-1, 3))
        return cls(col, dep, top, nor)

    def features(self, params: CrfParams, u: np.ndarray, v: np.ndarray, grid_area: int,
                 pixels: np.ndarray) -> list[tuple[np.ndarray, float]]:
        """(features, weight) of each enabled kernel at positions (u, v) of a grid of
        ``grid_area`` cells (θ_s scales with it), with the cues of flat pixel indices
        ``pixels``: RGB / θ_a (8-bit levels), depth / largest depth / θ_d, normals / θ_n."""
        pos, columns = self.columns(params, u, v, grid_area, pixels)
        return [(pos if tail is None else np.hstack([pos, tail / div[0] / div[1]]), weight)
                for tail, div, weight in columns]

    def columns(self, params: CrfParams, u: np.ndarray, v: np.ndarray, grid_area: int,
                pixels: np.ndarray
                ) -> tuple[np.ndarray, list[tuple[np.ndarray | None, tuple[float, float], float]]]:
        """:meth:`features` before they are put together: the (K, 2) float64 scaled
        positions, and per enabled kernel its cue (K, c) float64 as read (None for the
        smoothness kernel), the two numbers the cue is divided by in turn, and the weight."""
        theta_p = params.theta_position * np.sqrt(grid_area / REFERENCE_AREA)
        pos = np.stack([u, v], axis=1).astype(np.float64) / theta_p
        columns: list[tuple[np.ndarray | None, tuple[float, float], float]] = []
        if params.w_smoothness > 0:
            columns.append((None, (1.0, 1.0), params.w_smoothness))
        if self.rgb is not None:
            columns.append((self.rgb[pixels].astype(np.float64), (params.theta_color, 1.0),
                            params.w_appearance))
        if self.depth is not None:
            columns.append((self.depth[pixels].astype(np.float64)[:, None],
                            (self.depth_top, params.theta_depth), params.w_depth))
        if self.normals is not None:
            columns.append((self.normals[pixels].astype(np.float64), (params.theta_normal, 1.0),
                            params.w_normal))
        return pos, columns


def _block_mean_probabilities(labels: np.ndarray, step: int, num_labels: int,
                              params: CrfParams) -> np.ndarray:
    """(B, L) float64 mean over each ``step`` x ``step`` block's pixels of ``exp(-unary)``
    (the unary of :func:`unary_from_labels`) of the (H, W) int32 ``labels``, blocks in
    raster order, from label counts instead of an (N, L) exponential.

    A pixel's probabilities take only three values (its label's, another label's, or uniform
    for a non-planar pixel when ``uniform_nonplanar``), so a block's sum is counts times those
    values. They are the float32 values ``exp(-unary)`` gives, and the float64 sums of at most a
    few hundred of them are exact either way, so the result equals the per-pixel sum bit for
    bit.
    """
    # The three values, computed as dense_crf's unary computes them (float32), exponentiated.
    row = np.exp(-unary_from_labels(np.array([1, 0]), num_labels, params.confidence,
                                    uniform_label=0))
    p_own, p_other, p_uniform = float(row[0, 1]), float(row[0, 0]), float(row[1, 0])
    h, w = labels.shape
    counts = np.zeros((-(-h // step) * -(-w // step), 2), dtype=np.int64)
    own = np.zeros((counts.shape[0], num_labels), dtype=np.int64)
    # Rows of blocks on the frame's threads: each counts its own blocks.
    run_threaded([partial(_block_counts, labels, step, bool(params.uniform_nonplanar),
                          a * step, min(h, b * step), counts, own)
                  for a, b in chunks(-(-h // step), _THREADED_ROWS // step + 1)])
    size = counts[:, 0].astype(np.float64)
    n_uniform = counts[:, 1].astype(np.float64)
    total = own * p_own + ((size - n_uniform)[:, None] - own) * p_other \
        + (n_uniform * p_uniform)[:, None]
    return total / size[:, None]


@kernel
def _block_counts(labels: np.ndarray, step: int, uniform_nonplanar: bool, y0: int, y1: int,
                  counts: np.ndarray, own: np.ndarray) -> None:
    """Add rows ``y0:y1`` of the (H, W) int32 ``labels`` to the (B, 2) int64 ``counts`` of
    pixels and uniform pixels (label 0 when ``uniform_nonplanar``) of each ``step`` x
    ``step`` block (raster order) and to the (B, L) int64 ``own`` pixels of each block
    observed with each label, uniform ones left out."""
    w = labels.shape[1]
    ws = -(-w // step)
    for y in range(y0, y1):
        row = (y // step) * ws
        for c in range(ws):
            b = row + c
            for x in range(c * step, min(w, (c + 1) * step)):
                counts[b, 0] += 1
                if uniform_nonplanar and labels[y, x] == 0:
                    counts[b, 1] += 1
                else:
                    own[b, labels[y, x]] += 1


@kernel
def _band_pixels(edge: np.ndarray, step: int, h: int, w: int) -> np.ndarray:
    """(K,) int64 ascending flat pixels of an (H, W) image whose ``step`` x ``step`` block
    is flagged in the (hs, ws) bool ``edge``."""
    ws = edge.shape[1]
    count = 0
    for y in range(h):
        for b in range(ws):
            if edge[y // step, b]:
                count += min(w, (b + 1) * step) - b * step
    out = np.empty(count, np.int64)
    k = 0
    for y in range(h):
        for b in range(ws):
            if edge[y // step, b]:
                for x in range(b * step, min(w, (b + 1) * step)):
                    out[k] = y * w + x
                    k += 1
    return out


def _sum_in_place(arrays: list[np.ndarray]) -> np.ndarray:
    """The sum of same-shape float32 arrays, accumulated into the first, which the caller no
    longer needs (the kernels' fresh messages, (N, L) each).

    Bit for bit ``sum(arrays, np.zeros(...))``, without its full-size temporaries (8 MB each
    for the band of a 640x480 frame): adding 0 first turns a -0 into +0, as starting from
    zeros does, and the float32 additions then run in the same order.
    """
    total = arrays[0]
    total += 0.0
    for other in arrays[1:]:
        total += other
    return total


def _blurred(kernels: list[GaussianKernel], q: np.ndarray) -> list[np.ndarray]:
    """Each kernel's :meth:`~GaussianKernel.blur` of the (N, L) marginals ``q``, in kernel
    order, computed on parallel threads dearest first."""
    order = dearest_first(kernels)
    done = dict(zip(order, run_threaded([lambda k=kernels[i]: k.blur(q) for i in order]),
                    strict=True))
    return [done[i] for i in range(len(kernels))]


def _exact_band_labels(grid: CrfGrid, params: CrfParams, blurred: list[np.ndarray],
                       band: np.ndarray, lab: np.ndarray, unary: tuple, out: np.ndarray) -> None:
    """Label the (K,) ascending flat pixels ``band`` of ``out`` (H, W) int32 from their exact
    pairwise messages: every kernel's lattice values ``blurred`` (M, L) sliced at the pixels'
    own features (:meth:`_Cues.columns` at their positions on the coarse grid), summed in
    kernel order as :func:`_sum_in_place` sums them, then :func:`exact_labels` with the
    observed labels ``lab`` (H, W) int32 and the ``unary`` values.

    Pieces of the band run on parallel threads, each through its features, all kernels in
    order and its labels, so the sums do not depend on the threads.
    """
    (h, w), step = grid.shape, grid.step
    hs, ws = -(-h // step), -(-w // step)

    def piece(rows: tuple[int, int]) -> None:
        pixels = band[rows[0]:rows[1]]
        fu = (pixels % w + 0.5) / step - 0.5
        fv = (pixels // w + 0.5) / step - 0.5
        pos, columns = grid.cues.columns(params, fu, fv, hs * ws, pixels)
        for tail, _, _ in columns:
            if tail is not None and not np.all(np.isfinite(tail)):
                raise InvalidInput("dense CRF cues contain NaN or inf")
        messages = np.zeros((pixels.size, blurred[0].shape[1]), np.float32)
        none = np.zeros((pixels.size, 0))
        for kern, values, (tail, div, _) in zip(grid.kernels, blurred, columns, strict=True):
            kern.add_message_at(values, pos, none if tail is None else tail, div,
                                (0, pixels.size), messages)
        exact_labels(messages, lab, pixels, *unary, out)

    # Four pieces a thread: a thread that the machine holds back leaves its later pieces
    # to the others.
    run_threaded([partial(piece, rows)
                  for rows in chunks(band.size, _THREADED_PIXELS, per_thread=4)])


def _not_constant_3x3(image: np.ndarray) -> np.ndarray:
    """(H, W) bool: the 3 x 3 window around each pixel (clipped at the border) holds two
    different values, i.e. some pixel of it differs from the centre."""
    padded = np.pad(image, 1, mode="edge")
    h, w = image.shape
    out = np.zeros((h, w), dtype=bool)
    for dv in range(3):
        for du in range(3):
            out |= padded[dv:dv + h, du:du + w] != image
    return out



@dataclass
class CrfGrid:
    """What :func:`dense_crf` computes from a frame's cues alone, whatever its labels.

    Mean field runs on this grid with these kernels; only the unary and what follows depend
    on the labels. :func:`crf_grid` builds it, so a caller can build it before the labels
    exist (the dense-crf refiner does, on a background thread while RANSAC runs).

    Attributes
    ----------
    shape : tuple of int
        ``(H, W)`` of the image.
    step : int
        Block size in pixels (1: mean field at full resolution).
    cues : _Cues
        The flattened, scaled cues (pixel features of the band are taken from them).
    kernels : list of GaussianKernel
        The enabled kernels over the grid cells (blocks, or pixels when ``step`` is 1).
    """

    shape: tuple[int, int]
    step: int
    cues: _Cues
    kernels: list[GaussianKernel]


def crf_grid(shape: tuple[int, int], params: CrfParams, rgb: np.ndarray | None = None,
             depth: np.ndarray | None = None, normals: np.ndarray | None = None,
             threaded: bool = True) -> CrfGrid:
    """The label-independent part of :func:`dense_crf`: block grid, cues and lattices.

    Parameters
    ----------
    shape : tuple of int
        ``(H, W)`` of the label map.
    params : CrfParams
        As for :func:`dense_crf`.
    rgb, depth, normals : numpy.ndarray, optional
        Cues as in :func:`crf_features`.
    threaded : bool
        Build the kernels' lattices on parallel threads; False builds them one after the
        other on this thread (a background thread that should take one core only).

    Returns
    -------
    CrfGrid
        To pass to :func:`dense_crf` with the same params and cues.
    """
    h, w = shape
    step = 1
    if params.max_pixels:
        while -(-h // step) * -(-w // step) > params.max_pixels:
            step += 1
    cues = _Cues.of(params, rgb, depth, normals)
    if step == 1:
        v, u = np.mgrid[0:h, 0:w]
        kernels = _kernels(cues.features(params, u.ravel(), v.ravel(), h * w,
                                         np.arange(h * w)), threaded)
        return CrfGrid((h, w), 1, cues, kernels)
    hs, ws = -(-h // step), -(-w // step)
    # Block centres: the pixel at (step//2, step//2) of each block, clipped to the image.
    cv, cu = np.mgrid[0:hs, 0:ws]
    centre = (np.minimum(cv * step + step // 2, h - 1) * w
              + np.minimum(cu * step + step // 2, w - 1)).ravel()
    kernels = _kernels(cues.features(params, cu.ravel(), cv.ravel(), hs * ws, centre),
                       threaded)
    return CrfGrid((h, w), step, cues, kernels)


def dense_crf(
    labels: np.ndarray,
    num_labels: int,
    params: CrfParams,
    rgb: np.ndarray | None = None,
    depth: np.ndarray | None = None,
    normals: np.ndarray | None = None,
    grid: CrfGrid | None = None,
) -> np.ndarray:
    """Refine a multi-plane label map with the dense CRF (paper appendix, eq. 13).

    Parameters
    ----------
    labels : numpy.ndarray
        (H, W) int label map, 0 = non-planar, 1..num_labels-1 = planes.
    num_labels : int
        L = number of planes + 1.
    params : CrfParams
        Kernel deviations, weights, unary confidence and iteration count.
    rgb, depth, normals : numpy.ndarray, optional
        Cues as in :func:`crf_features`.
    grid : CrfGrid, optional
        :func:`crf_grid` of the same shape, params and cues, built beforehand; built here
        when omitted (the result is the same).

    Returns
    -------
    numpy.ndarray
        (H, W) int32 MAP labels of the mean-field marginals. With fewer than 2 labels or 0
        iterations the input is returned unchanged (as int32).

    Notes
    -----
    When ``H W > params.max_pixels > 0`` the image is cut into s x s blocks, with the smallest
    integer ``s`` that brings the block count under the cap. Mean field runs on the block grid:
    a block's unary is the negative log of its pixels' mean label probabilities, and its cues
    are those of its centre pixel (sampling, not averaging, keeps depth and normal edges sharp).
    The final labels are then taken at full resolution from each pixel's own unary plus the
    pairwise energy of the last coarse marginals, i.e. one mean-field update at full
    resolution with coarse messages. Away from label changes of the coarse result those
    messages are bilinearly upsampled; in the band of blocks next to a label change each pixel
    gets them from the coarse lattices sliced at its own features
    (:meth:`GaussianKernel.add_message_at`), so boundaries follow full-resolution edges. With
    a finite ``params.band_margin`` a band pixel gets them only when the upsampled messages
    leave its two best labels closer than that margin: elsewhere its own features would have
    to move the messages by more than the margin to change its label.
    """
    lab = np.asarray(labels)
    if lab.ndim != 2:
        raise InvalidInput(f"labels must be (H, W), got {lab.shape}")
    if lab.size and (lab.min() < 0 or lab.max() >= num_labels):
        raise InvalidInput(f"labels must lie in 0..{num_labels - 1}")
    if num_labels < 2 or params.iterations == 0:
        return lab.astype(np.int32)
    if grid is None:
        grid = crf_grid(lab.shape, params, rgb=rgb, depth=depth, normals=normals)
    elif grid.shape != lab.shape:
        raise InvalidInput(f"the CRF grid is for {grid.shape} images, the labels are "
                           f"{lab.shape}")
    h, w = lab.shape
    step, kernels = grid.step, grid.kernels
    if step == 1:
        unary = unary_from_labels(lab, num_labels, params.confidence,
                                  uniform_label=0 if params.uniform_nonplanar else None)
        q = mean_field(unary, kernels, params.iterations)
        return q.argmax(axis=1).astype(np.int32).reshape(lab.shape)
    hs, ws = -(-h // step), -(-w // step)
    # The kernels below read the labels as int32 (no copy when they are).
    lab = np.ascontiguousarray(lab, dtype=np.int32)
    mean = _block_mean_probabilities(lab, step, num_labels, params)
    q = mean_field(-np.log(mean), kernels, params.iterations)
    # Near a label change of the coarse result, interpolated messages would blur the edge:
    # there each pixel gets its messages from the coarse lattices sliced at its own features,
    # so the boundary follows the full-resolution colour, depth and normal edges.
    coarse = q.argmax(axis=1).reshape(hs, ws)
    edge = _not_constant_3x3(coarse)
    band = _band_pixels(edge, step, h, w)
    blurred = _blurred(kernels, q)
    coarse_pairwise = _sum_in_place([k.message_from(b)
                                     for k, b in zip(kernels, blurred, strict=True)])
    # Bilinear upsampling as cv2 does it (fine pixel u at coarse position (u + 0.5) / step
    # - 0.5): interpolated by the labelling where it needs the messages, or (label counts
    # whose cv2 arithmetic differs) upsampled whole by cv2.
    coarse_messages = coarse_pairwise.reshape(hs, ws, num_labels)
    fine = np.zeros((0, 0, num_labels), np.float32)
    if num_labels in RESIZED_LABEL_COUNTS:
        fine = cv2.resize(coarse_messages, (ws * step, hs * step),
                          interpolation=cv2.INTER_LINEAR).reshape(hs * step, ws * step, -1)
    return _full_resolution_labels(grid, params, lab, band, coarse_messages, fine, blurred)


def _full_resolution_labels(grid: CrfGrid, params: CrfParams, lab: np.ndarray, band: np.ndarray,
                            coarse: np.ndarray, fine: np.ndarray, blurred: list[np.ndarray]
                            ) -> np.ndarray:
    """(H, W) int32 final labels of :func:`dense_crf` on a coarse grid: observed labels
    ``lab`` (H, W) int32, ascending flat pixels of the ``band``, coarse messages ``coarse``
    (hs, ws, L) float32 and, when not empty, their upsampling ``fine`` (≥H, ≥W, L), and each
    kernel's lattice values ``blurred``."""
    (h, w), step = grid.shape, grid.step
    hs, ws = -(-h // step), -(-w // step)
    # The unary takes three values per label map (own label, other label, uniform): the
    # final argmax reads them instead of an (H W, L) unary array.
    values = unary_from_labels(np.array([1, 0]), coarse.shape[2], params.confidence,
                               uniform_label=0)
    unary = (values[0, 1], values[0, 0], values[1, 0], bool(params.uniform_nonplanar))
    out = np.empty((h, w), dtype=np.int32)
    close = np.empty(band.shape[0], dtype=np.bool_)
    # Every pixel is labelled from the upsampled messages first (most of them, away from the
    # band, by their coarse cells alone: certified_cells); where they leave the two best
    # labels of a band pixel within the margin (any band pixel when it is inf), its own
    # features might overturn them: those pixels are labelled again from exact messages.
    cell_label, cell_gap, slack = certified_cells(coarse)
    hard = float(values[0, 0]) - float(values[0, 1]) + slack
    rows, row_w = bilinear_taps(h, hs, step, clamp_weights=False)
    cols, col_w = bilinear_taps(w, ws, step, clamp_weights=True)
    run_threaded([partial(upsampled_labels, coarse, rows, row_w, cols, col_w, fine, lab,
                          band, *unary, float(params.band_margin), cell_label, cell_gap, step,
                          slack, hard, a, b, out, close)
                  for a, b in chunks(h, _THREADED_ROWS, per_thread=4)])
    _exact_band_labels(grid, params, blurred, band[close], lab, unary, out)
    return out
