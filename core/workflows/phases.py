"""The phases of a run after its optimiser, shown while they run (they take minutes on measured data).

:class:`Phases` is what the analysis calls: :meth:`~Phases.start` when a phase begins, :meth:`~Phases.status`
for a step inside it (a self-check split), :meth:`~Phases.done` at the end; the base class shows nothing
(the Python API's default). :class:`ProgressPhases` shows each phase as a line of a rich progress display with
its elapsed time, so that no phase longer than a few seconds runs without a sign on the screen.
"""

from __future__ import annotations

import time
from typing import Any

__all__ = ["Phases", "ProgressPhases"]


class Phases:
    """Phases shown nowhere (the default); subclasses show them."""

    def start(self, name: str) -> None:
        """A phase begins (the previous one, if any, is finished)."""

    def status(self, text: str) -> None:
        """A step inside the current phase (one line, replaced by the next)."""

    def done(self) -> None:
        """The current phase is finished."""


class ProgressPhases(Phases):
    """Each phase a task of a rich ``Progress`` (:func:`suspid.workflows.identify.make_progress`): a pulsing
    bar and the elapsed time while it runs, then its duration."""

    def __init__(self, bars: Any) -> None:
        self.bars = bars
        self._task: Any = None
        self._t0 = 0.0

    def start(self, name: str) -> None:
        self.done()
        self._task = self.bars.add_task(name, total=None, status="")
        self._t0 = time.perf_counter()

    def status(self, text: str) -> None:
        if self._task is not None:
            self.bars.update(self._task, status=text)

    def done(self) -> None:
        if self._task is not None:
            self.bars.update(self._task, total=1, completed=1,
                             status=f"done in {time.perf_counter() - self._t0:.0f} s")
            self._task = None
