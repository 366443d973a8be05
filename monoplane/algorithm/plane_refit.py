"""Least-squares planes of a finished labelling: the last step of a frame's or a cloud's
search (:meth:`monoplane.algorithm.ransac.SequentialRansac.run`,
:class:`monoplane.host.cloud_input.CloudInput`), which refits every label on all its points."""

from __future__ import annotations

import numpy as np

from monoplane.geometry.planes import fit_planes_per_label


def refit_and_renumber(points: np.ndarray, labels: np.ndarray, count: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Least-squares plane of each label on all its points; labels too small to fit a plane
    become non-planar and the others are renumbered 1..P in their order.

    Parameters
    ----------
    points : numpy.ndarray
        (V, 3) float64 points, any frame and unit.
    labels : numpy.ndarray
        (V,) int label of each point, 0 = none, at most ``count``.
    count : int
        Number of labels.

    Returns
    -------
    renumber : numpy.ndarray
        (count + 1,) int32 new label of each old one (0 for the dropped ones).
    planes : numpy.ndarray
        (P, 4) float64 unit-normal planes in the points' frame, not oriented.
    rmse : numpy.ndarray
        (P,) RMS point-to-plane distance, the points' unit.
    support : numpy.ndarray
        (P,) int64 points per plane.
    """
    planes, rmse, support = fit_planes_per_label(points, labels, count)
    kept = ~np.isnan(rmse)
    renumber = np.zeros(count + 1, dtype=np.int32)
    renumber[1:][kept] = np.arange(1, int(kept.sum()) + 1)
    return renumber, planes[kept], rmse[kept], support[kept]
