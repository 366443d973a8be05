"""Descriptor matching: mutual nearest neighbours, with a similarity floor or a ratio test."""

from __future__ import annotations

import numpy as np


def mutual_nearest(desc_i: np.ndarray, desc_j: np.ndarray, min_similarity: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Mutual nearest neighbours of unit descriptors by cosine similarity.

    A pair ``(a, b)`` is kept when ``b`` is ``a``'s most similar descriptor in ``j``, ``a`` is
    ``b``'s most similar in ``i``, and their similarity is at least ``min_similarity``.

    Parameters
    ----------
    desc_i, desc_j : numpy.ndarray
        (n_i, D) and (n_j, D) float32 unit-length descriptors.
    min_similarity : float
        Smallest cosine similarity accepted, in [-1, 1].

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        (m, 2) int64 index pairs ``(a, b)``, ascending in ``a``, and (m,) float32 similarities.
    """
    if len(desc_i) == 0 or len(desc_j) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.float32)
    sim = np.asarray(desc_i, np.float32) @ np.asarray(desc_j, np.float32).T
    best_j = sim.argmax(axis=1)
    best_i = sim.argmax(axis=0)
    a = np.arange(len(desc_i))
    values = sim[a, best_j]
    keep = (best_i[best_j] == a) & (values >= min_similarity)
    return np.c_[a[keep], best_j[keep]].astype(np.int64), values[keep].astype(np.float32)


def mutual_ratio(desc_i: np.ndarray, desc_j: np.ndarray, ratio: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Mutual nearest neighbours by Euclidean distance that pass Lowe's ratio test.

    Parameters
    ----------
    desc_i, desc_j : numpy.ndarray
        (n_i, D) and (n_j, D) float32 descriptors (SIFT's 128 bins).
    ratio : float
        Largest ratio of the nearest to the second-nearest distance in ``j``.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        (m, 2) int64 index pairs ``(a, b)``, ascending in ``a``, and (m,) float32 scores
        ``1 - distance ratio`` (higher is more distinctive).
    """
    if len(desc_i) < 2 or len(desc_j) < 2:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.float32)
    a32, b32 = np.asarray(desc_i, np.float32), np.asarray(desc_j, np.float32)
    # Squared distances through one product: |a|^2 + |b|^2 - 2 a.b.
    d2 = (np.einsum("ij,ij->i", a32, a32)[:, None] + np.einsum("ij,ij->i", b32, b32)[None, :]
          - 2.0 * (a32 @ b32.T))
    np.maximum(d2, 0.0, out=d2)
    two = np.argpartition(d2, 1, axis=1)[:, :2]
    rows = np.arange(len(a32))
    d_two = d2[rows[:, None], two]
    order = np.argsort(d_two, axis=1)
    first = two[rows, order[:, 0]]
    d1, d2nd = np.sqrt(d_two[rows, order[:, 0]]), np.sqrt(d_two[rows, order[:, 1]])
    back = d2.argmin(axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(d2nd > 0, d1 / d2nd, 1.0)
    keep = (r < ratio) & (back[first] == rows)
    return np.c_[rows[keep], first[keep]].astype(np.int64), (1.0 - r[keep]).astype(np.float32)
