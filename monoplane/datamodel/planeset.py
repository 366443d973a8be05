"""The vocabulary every result shares: a set of planes with ids and support.

A frame's :class:`~monoplane.datamodel.Reconstruction`, a point cloud's
:class:`~monoplane.datamodel.CloudResult` and a multi-view :class:`~monoplane.datamodel.Scene`
all are a :class:`PlaneSet`:

* ``planes``: (P, 4) float64 rows ``(n_x, n_y, n_z, d)`` with ``n · X + d = 0`` and ``|n| = 1``,
  in the result's frame (camera, cloud or world) and units;
* ``ids``: (P,) int64, the id each row goes by in the result's label maps and files;
* ``support``: (P,) int64 evidence of each plane (points or pixels, see each result);
* ``result_kind``: which result it is (``"frame"``, ``"cloud"``, ``"scene"``), so that writers
  and loggers tell results apart by what they say they are, not by their type.
"""

from __future__ import annotations

import warnings
from typing import ClassVar

import numpy as np

from monoplane.errors import InvalidInput

#: The kinds of result, as :attr:`PlaneSet.result_kind` states them. ``"multiview"`` is a
#: scene with what produced it (:class:`monoplane.multiview.MultiviewResult`).
RESULT_KINDS: tuple[str, ...] = ("frame", "cloud", "scene", "multiview")


def as_planes(planes: object, what: str = "planes") -> np.ndarray:
    """Check and convert plane rows.

    Parameters
    ----------
    planes : array_like
        P planes ``(n_x, n_y, n_z, d)``, any shape that reshapes to (P, 4).
    what : str
        Name used in the error message.

    Returns
    -------
    numpy.ndarray
        (P, 4) float64.

    Raises
    ------
    InvalidInput
        The values do not make rows of 4 or are not finite.
    """
    arr = np.asarray(planes, dtype=np.float64)
    if arr.size % 4:
        raise InvalidInput(f"{what} must have 4 values per plane, got shape {arr.shape}")
    arr = arr.reshape(-1, 4)
    if not np.all(np.isfinite(arr)):
        raise InvalidInput(f"{what} contain NaN or inf")
    return arr


def deprecated_name(owner: str, old: str, new: str) -> None:
    """Warn that ``owner.old`` is the former name of ``owner.new`` (removed in 0.3.0)."""
    # stacklevel 3: the line that used the old name, past this helper and the property
    warnings.warn(f"{owner}.{old} is deprecated; use {owner}.{new} (the old name goes in "
                  "0.3.0)", DeprecationWarning, stacklevel=3)


class PlaneSet:
    """Base of every result: planes (P, 4), their ids and their support.

    Subclasses store ``planes`` and ``support`` as attributes and set :attr:`result_kind`;
    :attr:`first_id` is the id of row 0 (1 where ids are label values, 0 for a scene's
    global planes).
    """

    result_kind: ClassVar[str] = ""
    first_id: ClassVar[int] = 1
    planes: np.ndarray
    support: np.ndarray

    @property
    def num_planes(self) -> int:
        """Number of planes P."""
        return int(self.planes.shape[0])

    @property
    def ids(self) -> np.ndarray:
        """(P,) int64 id of each row of ``planes``: ``first_id, first_id + 1, ...``."""
        return np.arange(self.first_id, self.first_id + self.num_planes, dtype=np.int64)
