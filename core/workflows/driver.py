"""The one driver of an optimiser: trials out, evaluations through the executor, values back by trial id.

:func:`drive` runs any :class:`~suspid.interfaces.Optimizer` to its end on the run's
executor. Serial, batch and asynchronous execution are the same loop with different
concurrency:

- **together** (the default, and every design or batch): ask as many trials as the
  executor has workers, evaluate them together
  (:func:`suspid.workflows.evaluation.evaluate_many`), tell them; with one worker this is
  the paper's serial loop;
- **asynchronous** (an optimiser whose :meth:`~suspid.interfaces.Optimizer.asynchronous`
  answers True: ``ego.asynchronous`` with ``ego.batch = 1`` and several workers): keep one
  trial in flight per worker. With ``ego.batch = 1`` the paper's loop waits for each
  simulation before it proposes the next point, so n - 1 of n workers idle; here, whenever
  a slot frees, the optimiser proposes one more trial beside those still running
  (``ask_trials(1, beside=True)``: the kriging believer of
  :meth:`suspid.optimize.ego.EGO.ask_beside`).

Reacting to whichever simulation finishes first would make the run depend on timing: the
same config would give another w_opt on a busier machine, and a resumed run could not
retrace its steps. So the asynchronous schedule is fixed:

1. with nothing in flight, ask without ``beside`` (the paper's step and its stopping rule,
   the design, a refinement step); several trials are evaluated together;
2. fill: while fewer than n trials are in flight, ask one beside them; stop filling when the
   optimiser has none to add now;
3. wait for the **oldest** trial in flight (the others go on running, and each evaluation is
   committed to the ledger the moment it arrives), tell it, go to 2 (to 1 when nothing is
   left in flight).

The asks and tells are then a function of the config and of n alone, not of which worker
is faster, and a killed run resumed from the ledger replays them, reading every finished
evaluation instead of simulating it. n is the executor's
:attr:`~suspid.interfaces.Executor.n_workers` when the optimiser starts; a run resumed with
another n goes its own (equally valid) way from the first trial whose pending set differs.

The ledger: the evaluation (w, J, Ψ, time, status) is committed once, by its content key,
when it finishes; the driver alone then writes one ``trials`` row per trial once it is told
(its id, evaluation key, phase, status and what the proposal knew: EI, J_max, ...), in id
order. w and J are not written again: :meth:`suspid.infra.ledger.Ledger.trials` joins them.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from suspid.errors import SimulatorError
from suspid.infra.ledger import Evaluation, Ledger
from suspid.interfaces import Executor, Optimizer, OptimizerResult, TaskHandle
from suspid.optimize.trials import Trial
from suspid.workflows.evaluation import evaluate_many, evaluation_key_of, evaluation_task, from_ledger, record_outcome
from suspid.workflows.gradient import ProblemSpectraModel
from suspid.workflows.problem import Problem

__all__ = ["drive", "InFlight"]


@dataclass
class InFlight:
    """A trial asked and not told yet: its simulation running (``handle``) or finished (``finished``)."""

    trial: Trial
    key: str
    w: dict[str, float]
    handle: TaskHandle | None = None
    started: float = 0.0
    finished: bool = False
    ev: Evaluation | None = None


@dataclass
class _Tally:
    """What the driver counts as trials are told: their number, J_max and the failed points."""

    n: int = 0
    j_max: float = -np.inf
    failed: list[dict[str, Any]] = field(default_factory=list)


def failure(problem: Problem, ledger: Ledger, phase: str, x_si: np.ndarray) -> dict[str, Any]:
    """A failed point for ``result.json``: its phase, w and the simulator's message from the ledger."""
    key, w = evaluation_key_of(problem, x_si)
    found = ledger.get(key)
    return {"phase": phase, "w": w, "error": found.error if found is not None else "unknown"}


def drive(optimizer: Optimizer, problem: Problem, ledger: Ledger, executor: Executor, bars, *,
          retry_failed: bool = False) -> tuple[OptimizerResult, list[dict[str, Any]]]:
    """Run ``optimizer`` through its trials to its end (see the module docstring).

    :param bars: a rich progress display (one bar for the optimiser).
    :param retry_failed: simulate again the points whose simulation failed before.
    :returns: the optimiser's result and the failed points (phase, w and the simulator's message).
    :raises SimulatorError: no point at all could be simulated.
    """
    if getattr(optimizer, "uses_jacobian", False):
        optimizer.spectra_model = ProblemSpectraModel(problem, ledger, executor)
    label = optimizer.name  # the phase of a failed point after the design
    bar = bars.add_task(label, total=optimizer.budget, status="")
    tally = _Tally()

    def tell(trials: list[Trial], evs: list[Evaluation | None]) -> None:
        phase = "design" if tally.n == 0 and len(trials) > 1 else label
        keys = []
        for t, ev in zip(trials, evs):
            key, t.w = evaluation_key_of(problem, t.x)
            keys.append(key)
            if ev is None:
                tally.failed.append(failure(problem, ledger, phase, t.x))
            else:
                tally.j_max = max(tally.j_max, ev.J)
                t.psi = ev.psi
        tally.n += len(trials)
        optimizer.tell_trials([t.id for t in trials], [ev.J if ev is not None else None for ev in evs],
                              [ev.wall_time_s if ev is not None else None for ev in evs])
        for t, key in zip(trials, keys):   # after the tell: the optimiser may add to a trial's details
            ledger.put_trial(t.id, {"key": key, **t.summary()})
        bars.update(bar, completed=tally.n,
                    status=f"J_max {tally.j_max:.4g}" if np.isfinite(tally.j_max) else "failed points")

    def together(trials: list[Trial]) -> None:
        X = np.array([t.x for t in trials])
        tell(trials, evaluate_many(problem, ledger, X, executor, lambda i, ev, reused: bars.update(bar, advance=1),
                                   retry_failed=retry_failed))

    n_workers = executor.n_workers
    if optimizer.asynchronous(n_workers):
        _asynchronously(optimizer, problem, ledger, executor, n_workers, tell, together, retry_failed)
    else:
        while not optimizer.done:
            trials = optimizer.ask_trials(n=n_workers)
            if not trials:
                break
            together(trials)
    bars.update(bar, total=max(tally.n, 1), completed=max(tally.n, 1))
    if not np.isfinite(tally.j_max):
        raise SimulatorError(f"none of the {tally.n} points could be simulated; see the failures in {ledger.path}")
    return optimizer.result(), tally.failed


def _asynchronously(optimizer: Optimizer, problem: Problem, ledger: Ledger, executor: Executor, n_workers: int,
                    tell, together, retry_failed: bool) -> None:
    """The asynchronous schedule of the module docstring, ``n_workers`` trials in flight."""
    task = evaluation_task(problem)
    flights: deque[InFlight] = deque()

    def start(t: Trial) -> None:
        key, w, found = from_ledger(problem, ledger, t.x, retry_failed)
        if found:
            flights.append(InFlight(t, key, w, finished=True, ev=found.ev))
        else:
            flights.append(InFlight(t, key, w, handle=executor.submit(task, w), started=time.perf_counter()))

    while True:
        if not flights:
            if optimizer.done:
                return
            trials = optimizer.ask_trials(n=n_workers)
            if not trials:
                return
            if len(trials) > 1:
                together(trials)
                continue
            start(trials[0])
        while len(flights) < n_workers:
            trials = optimizer.ask_trials(n=1, beside=True)
            if not trials:
                break
            start(trials[0])
        while not flights[0].finished:
            _collect(executor, flights, problem, ledger)
        oldest = flights.popleft()
        tell([oldest.trial], [oldest.ev])


def _collect(executor: Executor, flights: deque[InFlight], problem: Problem, ledger: Ledger) -> None:
    """Wait until a simulation in flight finishes; commit every finished one to the ledger."""
    running = {id(f.handle): f for f in flights if not f.finished}
    for handle, outcome in executor.wait_first([f.handle for f in running.values()]):
        f = running[id(handle)]
        f.ev = record_outcome(problem, ledger, f.key, f.w, outcome, time.perf_counter() - f.started)
        f.finished = True
