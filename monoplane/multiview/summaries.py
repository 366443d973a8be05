"""One-line summaries of multi-view results, as ``monoplane match`` and ``monoplane multiview``
print them (and a log or notebook may)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from monoplane.datamodel import SfmResult

if TYPE_CHECKING:
    from monoplane.multiview.driver import MultiviewResult


def unregistered_names(sfm: SfmResult) -> list[str]:
    """Names of the views the matcher could not place, in input order."""
    return [c.name for c, ok in zip(sfm.cameras, sfm.registered, strict=True) if not ok]


def sfm_summary(sfm: SfmResult, seconds: float) -> str:
    """``"N cameras, P points, verified matches a-b: m, ... in S s"``: the placed cameras, the
    sparse points and the verified matches of every pair (by view name), and the matcher's
    wall time ``seconds``."""
    pairs = ", ".join(f"{sfm.cameras[i].name}-{sfm.cameras[j].name}: {len(m)}"
                      for (i, j), m in sorted(sfm.matches.items()))
    placed = sfm.num_views - len(unregistered_names(sfm))
    return (f"{placed} cameras, {len(sfm.points)} points, verified matches {pairs} "
            f"in {seconds:.2f} s")


def scene_summary(result: MultiviewResult) -> str:
    """``"G global planes from a, b view planes, P SfM points, S s"``: the fused planes, each
    registered view's planes, the sparse points and the whole run's wall time."""
    scene = result.scene
    per_view = ", ".join(str(v.num_planes) for v in scene.views)
    return (f"{scene.planes.shape[0]} global planes from {per_view} view planes, "
            f"{len(result.sfm.points)} SfM points, {result.timings['total']:.2f} s")
