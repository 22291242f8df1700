"""Asynchronous EGO: one point in flight per worker, on a schedule that does not depend on timing.

With ``ego.batch = 1`` the paper's loop waits for each simulation before it
proposes the next point, so n - 1 of n workers idle. Asynchronous EGO keeps n
points in flight: whenever a slot frees, the optimiser proposes one more point
beside those still running (``ask(1, pending=X_p)``: the kriging believer of
:meth:`suspid.optimize.ego.EGO.ask_beside`).

Reacting to whichever simulation finishes first would make the run depend on
timing: the same config would give another w_opt on a busier machine, and a
resumed run could not retrace its steps. So the schedule is fixed:

1. with nothing in flight, ask without ``pending`` (the paper's step and its
   stopping rule, the design, a refinement step); a design or a batch of
   several points is evaluated together (:func:`suspid.workflows.evaluation.evaluate_many`);
2. fill: while fewer than n points are in flight, ask one point beside them;
   stop filling when the optimiser has none to add now;
3. wait for the **oldest** point in flight (the others go on running, and each
   result is committed to the ledger the moment it arrives), tell it, go to 2
   (to 1 when nothing is left in flight).

The asks and tells are then a function of the config and of n alone, not of
which worker is faster, and a killed run resumed from the ledger replays them,
reading every finished evaluation instead of simulating it. n is the
executor's :attr:`~suspid.interfaces.Executor.n_workers` when the optimiser
starts; a run resumed with another n goes its own (equally valid) way from
the first point whose pending set differs.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass
from typing import Callable

import numpy as np

from suspid.infra.ledger import Evaluation, Ledger
from suspid.interfaces import Executor, Optimizer, TaskHandle
from suspid.workflows.evaluation import evaluation_task, from_ledger, record_outcome
from suspid.workflows.problem import Problem

__all__ = ["drive_async", "InFlight"]

Tell = Callable[[np.ndarray, list], None]
"""``tell(X (k, q) SI, evaluations (k,))``: the driver's bookkeeping and the optimiser's tell."""


@dataclass
class InFlight:
    """A point asked and not told yet: its simulation running (``handle``) or finished (``finished``)."""

    x: np.ndarray
    key: str
    w: dict[str, float]
    handle: TaskHandle | None = None
    started: float = 0.0
    finished: bool = False
    ev: Evaluation | None = None


def drive_async(optimizer: Optimizer, problem: Problem, ledger: Ledger, executor: Executor, n_workers: int,
                tell: Tell, together: Callable[[np.ndarray], None], *, retry_failed: bool = False) -> None:
    """Run ``optimizer`` to its end with ``n_workers`` points in flight (the module docstring's schedule).

    :param tell: called with each point once its evaluation is in, oldest first.
    :param together: evaluates and tells a design or batch ``X (k, q)`` SI, k > 1.
    :param retry_failed: simulate again the points whose simulation failed before.
    """
    task = evaluation_task(problem)
    flights: deque[InFlight] = deque()

    def start(x: np.ndarray) -> None:
        key, w, found = from_ledger(problem, ledger, x, retry_failed)
        if found:
            flights.append(InFlight(x, key, w, finished=True, ev=found.ev))
        else:
            flights.append(InFlight(x, key, w, handle=executor.submit(task, w), started=time.perf_counter()))

    while True:
        if not flights:
            if optimizer.done:
                return
            X = np.atleast_2d(optimizer.ask(n=n_workers))
            if X.size == 0:
                return
            if len(X) > 1:
                together(X)
                continue
            start(X[0])
        while len(flights) < n_workers:
            X = np.atleast_2d(optimizer.ask(n=1, pending=np.array([f.x for f in flights])))
            if X.size == 0:
                break
            start(X[0])
        while not flights[0].finished:
            _collect(executor, flights, problem, ledger)
        oldest = flights.popleft()
        tell(oldest.x[None, :], [oldest.ev])


def _collect(executor: Executor, flights: deque[InFlight], problem: Problem, ledger: Ledger) -> None:
    """Wait until a simulation in flight finishes; commit every finished one to the ledger."""
    running = {id(f.handle): f for f in flights if not f.finished}
    for handle, outcome in executor.wait_first([f.handle for f in running.values()]):
        f = running[id(handle)]
        f.ev = record_outcome(problem, ledger, f.key, f.w, outcome, time.perf_counter() - f.started)
        f.finished = True
