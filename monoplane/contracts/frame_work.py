"""Label-independent work on a frame, started while the RANSAC runs.

A refiner gets a frame's RANSAC result only after the plane search, but part of its work
(lattices, graphs, points) depends on the frame alone. :class:`WorkAhead` lets its ``prepare``
start that work on the background thread and its ``refine`` take the result, or do the work
itself when the frame is another one or there is a single thread (batch workers: the time then
stays in the refiner's own). The built-in refiners use it; a plugin's stage may too.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from monoplane.datamodel import Frame
from monoplane.jit import in_background, thread_budget

T = TypeVar("T")


class WorkAhead:
    """Mixin of a stage that prepares a frame's label-independent work in the background."""

    #: The frame whose work was started and the call that waits for it, until taken.
    _pending: tuple[Frame, Callable[[], Any]] | None = None

    def _start_ahead(self, frame: Frame, build: Callable[[Frame], Any]) -> None:
        """Start ``build(frame)`` on the background thread when there are two or more
        threads (the other core runs the RANSAC's plane loop meanwhile)."""
        if thread_budget() > 1:
            self._pending = (frame, in_background(lambda: build(frame)))

    def _take_ahead(self, frame: Frame, build: Callable[[Frame], T]) -> T:
        """The work started for ``frame`` (waiting for it), else ``build(frame)`` here; work
        started for another frame is dropped."""
        pending, self._pending = self._pending, None
        if pending is not None and pending[0] is frame:
            return pending[1]()
        return build(frame)
