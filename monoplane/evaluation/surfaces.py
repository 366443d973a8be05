"""What the field's protocol cannot see: planes on curved surfaces and impure planes.

VOI, RI and SC (:mod:`monoplane.evaluation.segmentation`) score only ground-truth planar
pixels, so a plane painted onto a sphere, or a wall mask running over the object in front of
the wall, costs nothing there. These counts use exact surface truth (every planar face's id,
small ones included, and a mask of curved surfaces; :class:`monoplane.synth.SynthView`
``gt_faces`` and ``gt_curved``):

* **curved pixels labelled planar**: of the pixels on curved surfaces, those the prediction
  gives a plane;
* **false planes**: predicted planes more of whose pixels lie on curved surfaces than on any
  single planar face (a plane made up, not a face found);
* **purity**: of the pixels the prediction labels planar, those on their plane's dominant true
  face (the planar face holding most of the plane's pixels); curved pixels and pixels of other
  faces count as wrong.

Counts, not ratios, are returned per frame, so that a run pools them over its frames
(:class:`SurfaceCounts`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from monoplane.evaluation.segmentation import check_label_pair


@dataclass(frozen=True)
class SurfaceCounts:
    """Surface-truth counts of one prediction on one frame.

    Attributes
    ----------
    curved_px : int
        Pixels on curved surfaces.
    curved_planar_px : int
        Of those, pixels the prediction labels planar.
    false_planes : int
        Predicted planes lying mostly on curved surfaces (see the module docstring).
    planar_px : int
        Pixels the prediction labels planar.
    pure_px : int
        Of those, pixels on their plane's dominant true planar face.
    """

    curved_px: int
    curved_planar_px: int
    false_planes: int
    planar_px: int
    pure_px: int


def surface_counts(pred: np.ndarray, gt_faces: np.ndarray, gt_curved: np.ndarray
                   ) -> SurfaceCounts:
    """Count curved pixels labelled planar, false planes and pure pixels of one frame.

    Parameters
    ----------
    pred : numpy.ndarray
        (H, W) int predicted labels, 0 = non-planar, 1..P planes.
    gt_faces : numpy.ndarray
        (H, W) int true planar face ids, 0 where no planar face is (curved surfaces).
    gt_curved : numpy.ndarray
        (H, W) bool, True on curved surfaces.

    Returns
    -------
    SurfaceCounts
    """
    pred, faces = check_label_pair(pred, gt_faces)
    curved = np.asarray(gt_curved, dtype=bool)
    if curved.shape != pred.shape:
        raise ValueError(f"curved mask shape {curved.shape} differs from {pred.shape}")
    p = pred.ravel().astype(np.int64)
    on = p > 0
    n_pred, n_face = int(p.max(initial=0)) + 1, int(faces.max(initial=0)) + 1
    # Contingency of predicted planes (rows) and true faces (columns; column 0 = no face).
    table = np.bincount(p[on] * n_face + faces.ravel()[on].astype(np.int64),
                        minlength=n_pred * n_face).reshape(n_pred, n_face)[1:]
    on_curved = np.bincount(p[on & curved.ravel()], minlength=n_pred)[1:]
    best_face = table[:, 1:].max(axis=1, initial=0)
    present = table.sum(axis=1) > 0
    return SurfaceCounts(
        curved_px=int(curved.sum()),
        curved_planar_px=int(np.count_nonzero(on & curved.ravel())),
        false_planes=int(np.count_nonzero(present & (on_curved > best_face))),
        planar_px=int(np.count_nonzero(on)),
        pure_px=int(best_face.sum()),
    )


def pooled(counts: list[SurfaceCounts]) -> dict[str, float]:
    """Pool per-frame counts: curved share labelled planar, false planes per frame, purity.

    Returns
    -------
    dict
        ``curved_planar`` (share of all curved pixels; NaN without any), ``false_planes``
        (mean per frame), ``purity`` (share of all planar-labelled pixels; NaN without any).
    """
    if not counts:
        return {"curved_planar": float("nan"), "false_planes": float("nan"),
                "purity": float("nan")}
    curved = sum(c.curved_px for c in counts)
    planar = sum(c.planar_px for c in counts)
    return {
        "curved_planar": sum(c.curved_planar_px for c in counts) / curved if curved
        else float("nan"),
        "false_planes": sum(c.false_planes for c in counts) / len(counts),
        "purity": sum(c.pure_px for c in counts) / planar if planar else float("nan"),
    }
