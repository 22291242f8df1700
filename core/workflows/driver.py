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
from suspid.infra.ledger import evaluation_key
from suspid.workflows.evaluation import (evaluate_many, evaluation_key_of, evaluation_task, from_ledger,
                                         j_of_spectra, legacy_evaluation_key, record_outcome, y_sim_key)
from suspid.workflows.identity import IDENTITY_VERSION
from suspid.workflows.gradient import ProblemSpectraModel
from suspid.workflows.problem import Problem

__all__ = ["drive", "TrainEvaluator", "REPLAY_TOLERANCE"]

REPLAY_TOLERANCE = 1e-6
"""How far (max over components, in the normalised ``[0, 1]^q``) a resumed run's trial may lie from the point
the ledger's trial of the same id was evaluated at and still take that evaluation (:meth:`TrainEvaluator.replay`).
The optimiser's proposals are computed (GP fits, EI maximisation, linear solves), so on another processor they
differ from the recorded ones in their last bits; 1e-6 of the admissible interval is far above that noise and far
below any move of an estimate that matters (the intervals are percents of it)."""


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


LEGACY_J_TOLERANCE = 1e-6
"""Relative agreement of J recomputed from recorded spectra with the J a ledger of an earlier suspid recorded there
(:func:`same_data`): the same spectra through the same objective on this machine's B differ from it by about 1e-10;
other data or another objective differ by far more than 1e-6."""


def same_data(problem: Problem, ledger: Ledger, rows: dict[int, dict[str, Any]]) -> bool:
    """Whether trials recorded before the input identities were evaluated on this run's data with its objective,
    without a simulation: at the first of their points whose spectra the ledger also holds (the run's
    intervals keep y_sim at w_opt), J recomputed here from those spectra matches the recorded J."""
    for row in rows.values():
        ev = ledger.get(row["key"])
        y = ledger.get_array(y_sim_key(problem, ev.w) + ":y") if ev is not None and ev.ok else None
        if y is not None and y.shape == problem.y_mes.shape:
            J, _ = j_of_spectra(problem, y)
            return abs(J - ev.J) <= LEGACY_J_TOLERANCE * max(1.0, abs(ev.J))
    return False


def recorded_trials(problem: Problem, ledger: Ledger) -> dict[int, list[dict[str, Any]]]:
    """The recorded trials a resumed run may replay, by id, each id's candidates in order: the trials of every
    run of the folder (the current run's first: a folder moved elsewhere has another ``output.dir`` and so
    another run id), each checked by its key when it is replayed; and of a ledger written before the input
    identities (rows without ``identity``), the runs whose recorded J :func:`same_data` confirms."""
    groups: dict[str, dict[int, dict[str, Any]]] = {}
    for run, i, rec in ledger.all_iterations():
        if (run == "trials" or run.endswith("/trials")) and rec.get("key"):
            groups.setdefault(run, {})[int(rec.get("id", i))] = rec
    ordered = [groups.pop("trials", {}), *groups.values()]
    out: dict[int, list[dict[str, Any]]] = {}
    for rows in ordered:
        legacy = {i: r for i, r in rows.items() if "identity" not in r}
        keep = {i: r for i, r in rows.items() if "identity" in r}
        if legacy and same_data(problem, ledger, legacy):
            keep |= legacy
        for i, r in sorted(keep.items()):
            out.setdefault(i, []).append(r)
    return out


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
        self._stored: dict[int, list[dict[str, Any]]] | None = None   # recorded trials by id (replay)

    def _outcome(self, trial: Trial, key: str, w: dict[str, float], ev: Evaluation | None) -> Outcome:
        trial.w = w
        if ev is not None:
            trial.psi = ev.psi
        return Outcome(ev.J if ev is not None else None, ev.wall_time_s if ev is not None else None, (key, ev))

    def replay(self, trial: Trial) -> None:
        """Resume on another machine: where the ledger has no evaluation at ``trial.x`` but the run's recorded
        trial of the same id was evaluated within :data:`REPLAY_TOLERANCE` of it, on the same data, that
        evaluation is the trial's: its point becomes the recorded one (so that every later key at it, w_opt's
        included, is the recorded run's) and the evaluation is filed under this run's key.

        The same data: the recorded key is this run's key (or the key a ledger of an earlier suspid gave it on
        this machine) at the recorded point. A trial recorded before the input identities (no ``identity`` in
        its row) cannot be checked that way on another machine: its run's recorded J is checked instead
        (:func:`recorded_trials`).
        """
        p = self.problem
        if self._stored is None:
            self._stored = recorded_trials(p, self.ledger)
        if from_ledger(p, self.ledger, trial.x, self.retry_failed)[2] is not None:
            return
        u = p.to_unit(np.asarray(trial.x, float))
        for row in self._stored.get(trial.id, []):
            ev = self.ledger.get(row["key"])
            if ev is None or (not ev.ok and self.retry_failed) or set(ev.w) != set(p.names):
                continue
            x = np.array([ev.w[n] for n in p.names], float)
            if not np.max(np.abs(p.to_unit(x) - u)) <= REPLAY_TOLERANCE:
                continue
            key = evaluation_key(p.simulator_identity, ev.w, p.data_identity)
            if row["key"] not in (key, legacy_evaluation_key(p, ev.w)) and "identity" in row:
                continue   # recorded on other data
            self.ledger.get_migrating(key, [row["key"]])
            trial.x, trial.u = x, p.to_unit(x)
            return

    def evaluate(self, trials: list[Trial]) -> list[Outcome]:
        for t in trials:
            self.replay(t)
        X = np.array([t.x for t in trials])
        evs = evaluate_many(self.problem, self.ledger, X, self.executor,
                            lambda i, ev, reused: self.bars.update(self.bar, advance=1), retry_failed=self.retry_failed)
        return [self._outcome(t, *evaluation_key_of(self.problem, t.x), ev) for t, ev in zip(trials, evs)]

    def start(self, trial: Trial) -> Flight:
        self.replay(trial)
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
            self.ledger.put_trial(t.id, {"key": o.data[0], "identity": IDENTITY_VERSION, **t.summary()})
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
