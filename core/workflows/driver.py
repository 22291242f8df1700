"""An identification's optimiser on the one loop: the train's evaluation and the run ledger plugged in.

:func:`drive` runs any :class:`~suspid.interfaces.Optimizer` to its end through
:func:`suspid.optimize.driver.run_trials` (the one loop: serial, batch and asynchronous
execution, its fixed asynchronous schedule) with a :class:`TrainEvaluator`: J of the run's
problem on its executor (:func:`suspid.workflows.evaluation.evaluate_many`; asynchronously,
one task per trial in flight, ``ego.asynchronous`` with ``ego.batch = 1`` and several
workers, where the optimiser proposes one more trial beside those running: the kriging
believer of :meth:`suspid.optimize.ego.EGO.ask_beside`).

The asynchronous schedule is fixed (the module docstring of :mod:`suspid.optimize.driver`),
so the asks and tells are a function of the config and of n alone, not of which worker is
faster, and a killed run resumed from the ledger replays them, reading every finished
evaluation instead of simulating it. n is the executor's
:attr:`~suspid.interfaces.Executor.n_workers` when the optimiser starts; a run resumed with
another n goes its own (equally valid) way from the first trial whose pending set differs.

The ledger: the evaluation (w, J, Ψ, time, status) is committed once, by its content key,
when it finishes; once a trial is told, the evaluator writes one ``trials`` row for it
(its id, evaluation key, phase, status and what the proposal knew: EI, J_max, ...), in id
order. w and J are not written again: :meth:`suspid.infra.ledger.Ledger.trials` joins them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from suspid.errors import SimulatorError
from suspid.infra.ledger import Evaluation, Ledger
from suspid.interfaces import Executor, Optimizer, OptimizerResult
from suspid.optimize.driver import Evaluator, Flight, Outcome, run_trials
from suspid.optimize.trials import Trial
from suspid.workflows.evaluation import evaluate_many, evaluation_key_of, evaluation_task, from_ledger, record_outcome
from suspid.workflows.gradient import ProblemSpectraModel
from suspid.workflows.problem import Problem

__all__ = ["drive", "TrainEvaluator"]


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


class TrainEvaluator(Evaluator):
    """J of the run's problem on its executor, every evaluation committed to the ledger when it finishes
    (read from it when it is there), and one ``trials`` row per trial once it is told: what the one loop
    (:func:`suspid.optimize.driver.run_trials`) plugs in for an identification.

    An outcome's ``data`` is ``(key, Evaluation | None)``; a trial's ``w`` (and ``psi`` when it has a value)
    are set when it is evaluated.
    """

    def __init__(self, problem: Problem, ledger: Ledger, executor: Executor, bars, label: str,
                 retry_failed: bool = False) -> None:
        self.problem, self.ledger, self.executor, self.bars = problem, ledger, executor, bars
        self.n_workers = executor.n_workers
        self.label = label   # the phase of a failed point after the design
        self.retry_failed = retry_failed
        self.tally = _Tally()
        self.bar = None
        self._task = None

    def _outcome(self, trial: Trial, key: str, w: dict[str, float], ev: Evaluation | None) -> Outcome:
        trial.w = w
        if ev is not None:
            trial.psi = ev.psi
        return Outcome(ev.J if ev is not None else None, ev.wall_time_s if ev is not None else None, (key, ev))

    def evaluate(self, trials: list[Trial]) -> list[Outcome]:
        X = np.array([t.x for t in trials])
        evs = evaluate_many(self.problem, self.ledger, X, self.executor,
                            lambda i, ev, reused: self.bars.update(self.bar, advance=1), retry_failed=self.retry_failed)
        return [self._outcome(t, *evaluation_key_of(self.problem, t.x), ev) for t, ev in zip(trials, evs)]

    def start(self, trial: Trial) -> Flight:
        key, w, found = from_ledger(self.problem, self.ledger, trial.x, self.retry_failed)
        if found:
            return Flight(trial, outcome=self._outcome(trial, key, w, found.ev))
        if self._task is None:
            self._task = evaluation_task(self.problem)
        return Flight(trial, handle=(key, w, self.executor.submit(self._task, w)), started=time.perf_counter())

    def wait(self, flights) -> None:
        """Wait until a simulation in flight finishes; commit every finished one to the ledger."""
        running = {id(f.handle[2]): f for f in flights}
        for handle, result in self.executor.wait_first([f.handle[2] for f in running.values()]):
            f = running[id(handle)]
            key, w, _ = f.handle
            ev = record_outcome(self.problem, self.ledger, key, w, result, time.perf_counter() - f.started)
            f.outcome = self._outcome(f.trial, key, w, ev)

    def told(self, trials: list[Trial], outcomes: list[Outcome]) -> None:
        """The failed points, J_max and one ledger ``trials`` row per trial (after the tell: the optimiser
        may have added to a trial's details), in id order."""
        tally = self.tally
        phase = "design" if tally.n == 0 and len(trials) > 1 else self.label
        for t, o in zip(trials, outcomes):
            if o.J is None:
                tally.failed.append(failure(self.problem, self.ledger, phase, t.x))
            else:
                tally.j_max = max(tally.j_max, o.J)
        tally.n += len(trials)
        for t, o in zip(trials, outcomes):
            self.ledger.put_trial(t.id, {"key": o.data[0], **t.summary()})
        self.bars.update(self.bar, completed=tally.n,
                         status=f"J_max {tally.j_max:.4g}" if np.isfinite(tally.j_max) else "failed points")


def drive(optimizer: Optimizer, problem: Problem, ledger: Ledger, executor: Executor, bars, *,
          retry_failed: bool = False) -> tuple[OptimizerResult, list[dict[str, Any]]]:
    """Run ``optimizer`` through its trials to its end: the one loop
    (:func:`suspid.optimize.driver.run_trials`) with the train's evaluation (:class:`TrainEvaluator`).

    :param bars: a rich progress display (one bar for the optimiser).
    :param retry_failed: simulate again the points whose simulation failed before.
    :returns: the optimiser's result and the failed points (phase, w and the simulator's message).
    :raises SimulatorError: no point at all could be simulated.
    """
    if getattr(optimizer, "uses_jacobian", False):
        optimizer.spectra_model = ProblemSpectraModel(problem, ledger, executor)
    evaluator = TrainEvaluator(problem, ledger, executor, bars, optimizer.name, retry_failed)
    evaluator.bar = bars.add_task(optimizer.name, total=optimizer.budget, status="")
    run_trials(optimizer, evaluator)
    tally = evaluator.tally
    bars.update(evaluator.bar, total=max(tally.n, 1), completed=max(tally.n, 1))
    if not np.isfinite(tally.j_max):
        raise SimulatorError(f"none of the {tally.n} points could be simulated; see the failures in {ledger.path}")
    return optimizer.result(), tally.failed
