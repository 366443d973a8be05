"""Mean-field inference for a fully connected CRF with Gaussian edge potentials.

Split out of :mod:`monoplane.algorithm.densecrf`, which builds the image CRF on top of it.
Mean-field inference (Krähenbühl & Koltun, NeurIPS 2011) filters the current marginals with each
Gaussian kernel every iteration; the high-dimensional Gaussian filtering is done on a
permutohedral lattice (Adams, Baek & Davis, Eurographics 2010), linear in the point count,
instead of the O(N²) dense sum. The lattice's construction and its splat, blur and slice steps
are numba kernels (:mod:`monoplane.algorithm.lattice_kernels`); the rest is numpy.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.algorithm import lattice_kernels as lk
from monoplane.errors import InvalidInput
from monoplane.jit import run_threaded


class PermutohedralLattice:
    """Approximate Gaussian filtering in feature space: ``out_i ≈ Σ_j exp(-½|f_i-f_j|²) v_j``.

    Each point is splatted with barycentric weights onto the d+1 vertices of the enclosing
    simplex of the permutohedral lattice A*_d, the lattice values are blurred with a [1, 2, 1]
    kernel along each of the d+1 lattice directions, and the result is sliced back with the same
    weights. The operator is linear, and symmetric up to the blurs along different directions
    not quite commuting where the sparse lattice ends (about 1 % here); its overall scale
    differs from the exact sum by a roughly constant factor, which normalisation (see
    :class:`GaussianKernel`) removes.

    The lattice is built once (a hash table of the vertices in use and each vertex's two
    neighbours along every direction) and reused by every :meth:`filter` call, i.e. by every
    mean-field iteration. Construction and filtering are numba kernels
    (:mod:`monoplane.algorithm.lattice_kernels`), compiled on first use and cached on disk.

    Parameters
    ----------
    features : numpy.ndarray
        (N, d) float feature vectors, already divided by the kernel's standard deviations, so
        that the Gaussian has unit deviation in every coordinate. ``1 <= d <= 8`` (the CRF
        kernels use at most 5).

    Raises
    ------
    InvalidInput
        If the features are not finite, or span so many lattice cells that the vertex keys do
        not fit in 62 bits (a deviation θ absurdly small for the data).
    """

    def __init__(self, features: np.ndarray) -> None:
        f = np.ascontiguousarray(features, dtype=np.float64)
        if f.ndim != 2 or not 1 <= f.shape[1] <= 8:
            raise InvalidInput(f"lattice features must be (N, d) with 1 <= d <= 8, got {f.shape}")
        if not np.all(np.isfinite(f)):
            raise InvalidInput("lattice features contain NaN or inf")
        n, d = f.shape
        self.num_points = n
        self.dim = d
        key0, rank, self._weights = lk.enclosing_simplices(f)
        # Vertex keys (first d elevated coordinates) packed into one int64 with a mixed radix,
        # with room for the neighbour offsets (±1 and ±(d+1) per coordinate) around the data.
        d1 = d + 1
        lo = key0.min(axis=0) - 2 * d1 if n else np.zeros(d, np.int64)
        hi = key0.max(axis=0) + 2 * d1 if n else np.zeros(d, np.int64)
        self._lo = lo
        self._radix = radix = hi - lo + 1
        if float(np.prod(radix.astype(np.float64))) >= 2.0**62:
            raise InvalidInput(
                "dense CRF features span too many lattice cells; a kernel deviation θ is too "
                "small for the range of its feature"
            )
        self._place = place = np.concatenate([[1], np.cumprod(radix[:-1])]).astype(np.int64)
        self._vertex_of, codes, self._table, self._index = lk.insert_vertices(key0 - lo, rank,
                                                                                place)
        self.num_vertices = int(codes.size)
        self._neighbours = lk.lattice_neighbours(codes, place, self._table, self._index)

    def filter(self, values: np.ndarray) -> np.ndarray:
        """Apply the lattice Gaussian to per-point values.

        Parameters
        ----------
        values : numpy.ndarray
            (N, C) float values (e.g. label marginals).

        Returns
        -------
        numpy.ndarray
            (N, C) float32 filtered values, ``≈ c · Σ_j exp(-½|f_i-f_j|²) values_j`` for a
            constant ``c > 0``.
        """
        return lk.slice_values(self._vertex_of, self._weights, self.blurred(values))

    def blurred(self, values: np.ndarray) -> np.ndarray:
        """(M, C) float32 lattice values: (N, C) ``values`` splatted and blurred, to be sliced
        at these points (:meth:`filter`) or at others (:meth:`GaussianKernel.add_message_at`)."""
        v = np.ascontiguousarray(values, dtype=np.float32)
        if v.ndim != 2 or v.shape[0] != self.num_points:
            raise InvalidInput(f"values must be ({self.num_points}, C), got {v.shape}")
        return lk.splat_blur(self._vertex_of, self._weights, self._neighbours, v,
                             self.num_vertices)


@dataclass
class GaussianKernel:
    """One Potts-weighted Gaussian kernel ``w · exp(-½|f_i - f_j|²)`` with symmetric normalisation.

    The message passed in mean-field is ``w · D^-½ K D^-½ Q`` with ``K`` the lattice Gaussian and
    ``D = diag(K 1)``: the kernel-weighted average of the neighbours' marginals, as in
    Krähenbühl & Koltun's reference implementation (``NORMALIZE_SYMMETRIC``). It keeps ``w``
    comparable to the unary energies (nats) whatever the kernel's width, and the pairwise
    energy symmetric.

    Parameters
    ----------
    features : numpy.ndarray
        (N, d) features divided by their deviations θ.
    weight : float
        Kernel weight ``w^(m)`` (> 0).
    """

    features: np.ndarray
    weight: float

    def __post_init__(self) -> None:
        if not self.weight > 0:
            raise InvalidInput(f"kernel weight must be positive, got {self.weight}")
        self.lattice = PermutohedralLattice(self.features)
        self._ones = self.lattice.blurred(np.ones((self.lattice.num_points, 1), np.float32))
        norm = lk.slice_values(self.lattice._vertex_of, self.lattice._weights, self._ones)
        self._norm = (1.0 / np.sqrt(np.maximum(norm, 1e-20))).astype(np.float32)

    def message(self, q: np.ndarray) -> np.ndarray:
        """(N, L) float32 weighted, normalised kernel response to marginals ``q`` (N, L)."""
        return self.weight * self._norm * self.lattice.filter(self._norm * q)

    def blur(self, q: np.ndarray) -> np.ndarray:
        """(M, L) float32 lattice values of marginals ``q`` (N, L): normalised, splatted and
        blurred, for :meth:`message_from` and :meth:`add_message_at`."""
        return self.lattice.blurred(self._norm * q)

    def message_from(self, blurred: np.ndarray) -> np.ndarray:
        """(N, L) float32 :meth:`message` of the marginals :meth:`blur` gave ``blurred``."""
        lat = self.lattice
        return self.weight * self._norm * lk.slice_values(lat._vertex_of, lat._weights, blurred)

    def add_message_at(self, blurred: np.ndarray, head: np.ndarray, tail: np.ndarray,
                       divisors: tuple[float, float], rows: tuple[int, int],
                       out: np.ndarray) -> None:
        """Add the message of the marginals :meth:`blur` gave ``blurred`` at other points
        (full-resolution pixels of a CRF run on a coarser grid) to rows ``rows`` of ``out``.

        It is the same normalised kernel evaluated at points that are not in the lattice:
        ``w · D_k^-½ Σ_j k(g_k, f_j) D_j^-½ q_j`` with ``D_k = Σ_j k(g_k, f_j)``, where point
        k's features are ``g_k = [head[k], tail[k] / divisors[0] / divisors[1]]``.

        Parameters
        ----------
        blurred : numpy.ndarray
            (M, L) float32 from :meth:`blur`.
        head, tail : numpy.ndarray
            (K, a) and (K, b) float64 feature columns, ``a + b`` the kernel's dimension.
        divisors : tuple of float
            What ``tail`` is divided by, in turn.
        rows : tuple of int
            ``(start, stop)``: the points done by this call (threads share one ``out``).
        out : numpy.ndarray
            (K, L) float32, added to in place.
        """
        lat = self.lattice
        if head.shape[1] + tail.shape[1] != lat.dim:
            raise InvalidInput(f"features of {head.shape[1] + tail.shape[1]} columns for a "
                               f"{lat.dim}-d kernel")
        lk.add_messages_at(head, tail, float(divisors[0]), float(divisors[1]), lat._lo,
                           lat._radix, lat._place, lat._table, lat._index, blurred, self._ones,
                           np.float32(self.weight), rows[0], rows[1], out)


def unary_from_labels(labels: np.ndarray, num_labels: int, confidence: float,
                      uniform_label: int | None = None) -> np.ndarray:
    """Unary energies ψ_u from a hard label map ("difference to the original labels").

    The observed label gets probability ``confidence``, the other ``num_labels - 1`` labels
    share ``1 - confidence`` evenly; the energy is the negative log-probability. This is the
    usual way to run a dense CRF on top of a hard segmentation (e.g. pydensecrf's
    ``unary_from_labels`` with ``gt_prob``).

    Parameters
    ----------
    labels : numpy.ndarray
        (N,) int labels in ``0 .. num_labels-1``.
    num_labels : int
        L >= 2.
    confidence : float
        Probability of the observed label, in ``(1/L, 1)``.
    uniform_label : int, optional
        Pixels observed with this label get the uniform distribution (energy ``log L`` for
        every label) instead: the observation carries no evidence. The refiner passes 0, the
        RANSAC's "no plane explains this point", which says nothing about which plane the pixel
        belongs to, so the pairwise kernels decide.

    Returns
    -------
    numpy.ndarray
        (N, L) float32 energies in nats.
    """
    if num_labels < 2:
        raise InvalidInput(f"a CRF needs at least 2 labels, got {num_labels}")
    if not 1.0 / num_labels < confidence < 1.0:
        raise InvalidInput(
            f"confidence must lie in (1/{num_labels}, 1) for {num_labels} labels, got {confidence}"
        )
    lab = np.asarray(labels).ravel()
    other = -np.log((1.0 - confidence) / (num_labels - 1))
    unary = np.full((lab.size, num_labels), other, dtype=np.float32)
    unary[np.arange(lab.size), lab] = -np.log(confidence)
    if uniform_label is not None:
        unary[lab == uniform_label] = np.log(num_labels)
    return unary


def mean_field(unary: np.ndarray, kernels: list[GaussianKernel], iterations: int) -> np.ndarray:
    """Mean-field inference for a fully connected Potts CRF (Krähenbühl & Koltun, Alg. 1).

    ``Q_i(l) ∝ exp(-ψ_u(i, l) - Σ_m w_m Σ_j k_m(i, j) [Q_j(·) ≠ l])``; the Potts sum equals the
    kernel response to ``1 - Q_j(l)``, which up to a per-pixel constant (irrelevant to the
    softmax) is ``-`` the response to ``Q_j(l)``.

    Parameters
    ----------
    unary : numpy.ndarray
        (N, L) energies.
    kernels : list of GaussianKernel
        Pairwise kernels over the same N points; may be empty (then Q is the unary softmax).
    iterations : int
        Number of parallel updates (>= 0).

    Returns
    -------
    numpy.ndarray
        (N, L) float32 approximate marginals.
    """
    u = np.asarray(unary, dtype=np.float32)
    q = _softmax(-u)
    for _ in range(iterations):
        q = _softmax(pairwise(kernels, q) - u)
    return q


def pairwise(kernels: list[GaussianKernel], q: np.ndarray) -> np.ndarray:
    """(N, L) float32 sum of every kernel's :meth:`~GaussianKernel.message` to marginals q.

    The kernels' lattice filters are numba kernels that release the GIL, so they run in
    parallel threads (:func:`monoplane.jit.run_threaded`), dearest first; the messages are
    summed in kernel order whatever the threads, so results do not depend on them.
    """
    order = dearest_first(kernels)
    messages = run_threaded([lambda k=kernels[i]: k.message(q) for i in order])
    by_kernel = dict(zip(order, messages, strict=True))
    return sum((by_kernel[i] for i in range(len(kernels))), np.zeros(q.shape, np.float32))


def dearest_first(kernels: list[GaussianKernel]) -> list[int]:
    """Kernel positions by decreasing lattice cost (feature dimension, then vertices), so that
    two threads finish together: the 5-d kernels first, the 2-d smoothness one last."""
    return sorted(range(len(kernels)), key=lambda i: (-kernels[i].lattice.dim,
                                                      -kernels[i].lattice.num_vertices, i))


def _softmax(x: np.ndarray) -> np.ndarray:
    """Row-wise softmax of the (N, L) float32 ``x``, computed in place of one copy.

    The rows' maximum is taken column after column (a maximum does not depend on the order,
    and numpy's reduction along a short last axis costs four times as much): the same bits
    as ``exp(x - x.max(axis=1))`` over its sum.
    """
    top = x[:, 0].copy()
    for j in range(1, x.shape[1]):
        np.maximum(top, x[:, j], out=top)
    e = x - top[:, None]
    np.exp(e, out=e)
    e /= e.sum(axis=1, keepdims=True)
    return e
