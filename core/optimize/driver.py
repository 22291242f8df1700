"""The one optimisation loop: ask trials, evaluate them, tell their values by id, record them.

:func:`run_trials` drives any ask/tell loop on trials (:class:`suspid.optimize.trials.TrialLoop`
with a ``done`` property: :class:`suspid.optimize.ego.EGO`, every
:class:`suspid.interfaces.Optimizer`) to its end. What J is and where its values are kept is
plugged in as an :class:`Evaluator`:

- :class:`FunctionEvaluator`: a plain Python function ``func(w (q,)) -> float`` (and optionally
  ``func_batch(X (k, q))``): :func:`suspid.optimize.ego.run_ego` and
  :func:`suspid.optimize.ego.maximize`;
- the train's evaluation on the run's executor, committed to the run ledger
  (:func:`suspid.workflows.driver.drive`).

Serial, batch and asynchronous execution are the same loop with different concurrency:

- **together** (the default, every design and batch): ask as many trials as the evaluator has
  workers, evaluate them together, tell them; with one worker this is the paper's serial loop.
  An evaluator may cut the trials of one ask into groups told one after the other
  (:meth:`Evaluator.groups`); the loop then stops between groups once the optimiser is done
  (a callback that stopped the run: the rest is not evaluated);
- **asynchronous** (an optimiser whose ``asynchronous(n_workers)`` answers True, with an
  evaluator that can :meth:`~Evaluator.start` a trial): keep one trial in flight per worker on a
  fixed schedule, so that the asks and tells depend on the config and the number of workers
  alone, not on which worker is faster:

  1. with nothing in flight, ask without ``beside`` (the paper's step and its stopping rule, the
     design, a refinement step); several trials are evaluated together;
  2. fill: while fewer than n trials are in flight, ask one beside them
     (``ask_trials(1, beside=True)``); stop filling when the optimiser has none to add now;
  3. wait for the **oldest** trial in flight (the others go on running), tell it, go to 2 (to 1
     when nothing is left in flight).

After every tell the evaluator's :meth:`~Evaluator.told` records the trials (a ledger row per
trial, a progress bar): the loop alone decides when a trial is told, and so when it is recorded.

Public API: :func:`run_trials`, :class:`Outcome`, :class:`Flight`, :class:`Evaluator`,
:class:`FunctionEvaluator`.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from suspid.errors import SuspidError
from suspid.optimize.trials import Trial

__all__ = ["run_trials", "Outcome", "Flight", "Evaluator", "FunctionEvaluator"]


@dataclass
class Outcome:
    """The evaluation of one trial: J (None when it failed), its wall time in s and what the
    evaluator keeps of it (the ledger's evaluation, ...)."""

    J: float | None
    seconds: float | None = None
    data: Any = None


@dataclass
class Flight:
    """A trial started and not told yet (asynchronous loop): ``outcome`` once it finished."""

    trial: Trial
    handle: Any = None
    started: float = 0.0
    outcome: Outcome | None = None

    @property
    def finished(self) -> bool:
        return self.outcome is not None


class Evaluator:
    """What the loop plugs in: how trials are evaluated and recorded (see the module docstring).

    :ivar n_workers: trials evaluated at once (the number of trials asked together).
    """

    n_workers: int = 1

    def evaluate(self, trials: list[Trial]) -> list[Outcome]:
        """Evaluate the trials together; one outcome each, in order."""
        raise NotImplementedError

    def groups(self, trials: list[Trial]) -> list[list[Trial]]:
        """The trials of one ask cut into groups evaluated and told one after the other (default: one group)."""
        return [trials]

    def told(self, trials: list[Trial], outcomes: list[Outcome]) -> None:
        """Record trials just told (default: nothing)."""

    # -- asynchronous evaluation (optional) ---------------------------------------------------
    def start(self, trial: Trial) -> Flight:
        """Start evaluating one trial without waiting for it."""
        raise NotImplementedError

    def wait(self, flights: Sequence[Flight]) -> None:
        """Wait until at least one of the unfinished ``flights`` finishes; set the outcome of every finished one."""
        raise NotImplementedError


def run_trials(loop: Any, evaluator: Evaluator) -> None:
    """Run ``loop`` (ask/tell on trials, with ``done``) to its end with ``evaluator`` (module docstring)."""
    n_workers = evaluator.n_workers

    def tell(trials: list[Trial], outcomes: list[Outcome]) -> None:
        loop.tell_trials([t.id for t in trials], [o.J for o in outcomes], [o.seconds for o in outcomes])
        evaluator.told(trials, outcomes)

    def together(trials: list[Trial]) -> None:
        for i, group in enumerate(evaluator.groups(trials)):
            if i and loop.done:   # the run stopped after a group (a callback): the rest is not evaluated
                return
            tell(group, evaluator.evaluate(group))

    asynchronous = getattr(loop, "asynchronous", None)
    if asynchronous is not None and asynchronous(n_workers):
        _asynchronously(loop, evaluator, n_workers, tell, together)
        return
    while not loop.done:
        trials = loop.ask_trials(n=n_workers)
        if not trials:
            return
        together(trials)


def _asynchronously(loop: Any, evaluator: Evaluator, n_workers: int, tell, together) -> None:
    """The asynchronous schedule of the module docstring, ``n_workers`` trials in flight."""
    flights: deque[Flight] = deque()
    while True:
        if not flights:
            if loop.done:
                return
            trials = loop.ask_trials(n=n_workers)
            if not trials:
                return
            if len(trials) > 1:
                together(trials)
                continue
            flights.append(evaluator.start(trials[0]))
        while len(flights) < n_workers:
            trials = loop.ask_trials(n=1, beside=True)
            if not trials:
                break
            flights.append(evaluator.start(trials[0]))
        while not flights[0].finished:
            evaluator.wait([f for f in flights if not f.finished])
        oldest = flights.popleft()
        tell([oldest.trial], [oldest.outcome])


class FunctionEvaluator(Evaluator):
    """J from a plain Python function, in this process (:func:`suspid.optimize.ego.run_ego`).

    The trials of an EGO batch (``ego.batch`` > 1) are evaluated together, through
    ``func_batch(X (k, q)) -> k values`` when given (so that k workers stay busy), else one by
    one through ``func``, and told together; every other trial (the design, the paper's serial
    step, the refinement) is evaluated and told alone, so that a callback can stop after any.

    :param func: ``func(w (q,)) -> float``, SI units.
    :param func_batch: evaluates a batch ``(k, q)`` SI at once, or None.
    :param batch: ``ego.batch``: EGO trials come in batches when it exceeds 1.
    :raises SuspidError: a value that is not a finite number.
    """

    def __init__(self, func: Callable[[np.ndarray], float],
                 func_batch: Callable[[np.ndarray], Sequence[float]] | None = None, batch: int = 1) -> None:
        self.func = func
        self.func_batch = func_batch
        self.batch = batch

    def _batched(self, trials: list[Trial]) -> bool:
        """Trials of an EGO batch (``ego.batch`` > 1): evaluated and told together."""
        return self.batch > 1 and all(t.phase == "ego" for t in trials)

    def groups(self, trials: list[Trial]) -> list[list[Trial]]:
        return [trials] if self._batched(trials) else [[t] for t in trials]

    def evaluate(self, trials: list[Trial]) -> list[Outcome]:
        if len(trials) == 1 and not self._batched(trials):
            return [Outcome(*self._one(trials[0].x))]
        X = np.array([t.x for t in trials])
        t0 = time.perf_counter()
        if self.func_batch is not None:
            values = [float(v) for v in self.func_batch(X)]
            if len(values) != len(X) or not all(math.isfinite(v) for v in values):
                raise SuspidError(f"func_batch returned {values!r} for {len(X)} points")
        else:
            values = [self._one(x)[0] for x in X]
        dt = (time.perf_counter() - t0) / len(X)
        return [Outcome(v, dt) for v in values]

    def _one(self, x: np.ndarray) -> tuple[float, float]:
        """J at ``x (q,)`` SI and the call's wall time in s."""
        t0 = time.perf_counter()
        value = self.func(x.copy())
        try:
            J = float(value)
        except (TypeError, ValueError):
            raise SuspidError(f"the objective returned {value!r} at w={x.tolist()}; expected a number") from None
        if not math.isfinite(J):
            raise SuspidError(f"the objective returned {J} at w={x.tolist()}; EGO needs finite values")
        return J, time.perf_counter() - t0
