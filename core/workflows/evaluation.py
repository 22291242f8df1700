"""J(w) through the run ledger and an executor (paper eq. 5 with common random numbers).

One evaluation is one parameter vector w through the simulator on the run's
segments, its spectra y_sim (v, n_channels, n_freqs) dB and J = Σ α_k Ψ_k
with Y_mod = y_sim + b_i (through the noise model's floor when it has one). Each result is committed to the ledger the moment
it arrives, keyed by the simulator's identity, w and the data identity, so
that a resumed run reads it instead of simulating it again.

Workers receive picklable tasks with resolved options (:class:`SpectraTask`,
called with w); the simulator is built once per process. Every simulation of
a run, not only the evaluations of J, goes through the run's executor
(:func:`run_tasks`), so that with a cluster the driver simulates nothing.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from suspid import registry
from suspid.errors import SimulatorError
from suspid.infra.ledger import Evaluation, Ledger, evaluation_key, stable_hash
from suspid.interfaces import Executor
from suspid.method.noise import NoiseModel
from suspid.method.objective import ObjectiveFunction
from suspid.workflows.problem import Problem
from suspid.workflows.tasks import SpectraTask, in_process


def j_of_spectra(problem: Problem, y_sim: np.ndarray, b: np.ndarray | None = None,
                 y_mes: np.ndarray | None = None, noise_model: NoiseModel | None = None) -> tuple[float, np.ndarray]:
    """J = Σ α_k Ψ_k (eq. 5) with Y_mod = y_sim + b (by default the run's fixed paths and measured spectra);
    the sensor-noise floor is ``noise_model``'s (by default the run's).

    With the defaults this is the run's own J, :attr:`Problem.objective_function` (built once per run);
    other paths, spectra or noise model (a bootstrap replicate) make a J of their own.
    """
    if b is None and y_mes is None and noise_model is None:
        return problem.objective_function.evaluate(y_sim)
    return objective_on(problem, b, y_mes, noise_model).evaluate(y_sim)


def objective_on(problem: Problem, b: np.ndarray | None = None, y_mes: np.ndarray | None = None,
                 noise_model: NoiseModel | None = None) -> ObjectiveFunction:
    """J of eq. 5 with the run's objective plugin and weights on other data: noise paths ``b``
    ``(v, n_channels, n_freqs)`` dB (by default the run's, all its draws: :attr:`Problem.noise_paths`),
    measured spectra ``y_mes`` (same shape) and ``noise_model``'s floor (each by default the run's)."""
    model = problem.noise_model if noise_model is None else noise_model
    return ObjectiveFunction(problem.objective, problem.y_mes if y_mes is None else y_mes, problem.freqs,
                             problem.noise_paths if b is None else b, weights=problem.weights,
                             channels=problem.channels, floor=model.floor_)


def simulate_spectra_task(task: tuple) -> np.ndarray:
    """One evaluation from a tuple ``(plugin name, options, w, segments, spectra) -> y_sim``.

    Module-level and built from picklable parts; the simulator class comes from
    the registry of the process that runs it. Each item carries its segments:
    :class:`SpectraTask` sends them once per worker instead.
    """
    plugin, options, w, segments, spectra_options = task
    return SpectraTask(registry.get("simulator", plugin), dict(options), list(segments), spectra_options)(w)


def y_sim_key(problem: Problem, w: dict[str, float]) -> str:
    """The ledger key of the simulated spectra at ``w`` on the measurement date's segments (``key + ":y"``)."""
    return stable_hash("y_sim", problem.simulator_identity, w, problem.segments_digest)


def evaluation_key_of(problem: Problem, x_si: np.ndarray) -> tuple[str, dict[str, float]]:
    """The ledger key of ``x_si (q,)`` SI and its parameter mapping w."""
    w = problem.w_of(x_si)
    return evaluation_key(problem.simulator_identity, w, problem.data_identity), w


def legacy_evaluation_key(problem: Problem, w: dict[str, float]) -> str | None:
    """The key a ledger written before the input identities gave the evaluation at ``w`` (its data part the array
    digests of this machine's y_mes, b and α: found only where they have the same bits), or None."""
    if problem.legacy_identity is None:
        return None
    return evaluation_key(problem.simulator_identity, w, problem.legacy_identity)


def evaluate_many(problem: Problem, ledger: Ledger, X_si: np.ndarray, executor: Executor,
                  on_done: Callable[[int, Evaluation | None, bool], None] = lambda i, ev, reused: None,
                  retry_failed: bool = False) -> list[Evaluation | None]:
    """J at many parameter vectors: reused from the ledger, or simulated by ``executor``.

    Each result is committed to the ledger the moment it arrives. A failed
    simulation (a :class:`~suspid.errors.SimulatorError`) is recorded as failed
    with its message and gives ``None`` in the returned list; a later call does
    not simulate it again unless ``retry_failed``. Any other exception of the
    simulator is a bug of its plugin: it is not recorded and ends the run as a
    :class:`~suspid.errors.PluginBugError` naming the plugin.

    :param X_si: ``(n_points, q)`` SI values.
    :param on_done: called as ``on_done(index, evaluation, reused)`` for every point
        (``evaluation`` None for a failed point).
    """
    out: list[Evaluation | None] = [None] * len(X_si)
    todo, keys = [], {}
    for i, x in enumerate(np.asarray(X_si, float)):
        key, w, found = from_ledger(problem, ledger, x, retry_failed)
        if found:
            out[i] = found.ev
            on_done(i, out[i], True)
        else:
            keys[len(todo)] = (i, key, w)
            todo.append(w)
    t0 = time.perf_counter()
    for j, result in executor.map_unordered(evaluation_task(problem), todo) if todo else ():
        i, key, w = keys[j]
        out[i] = record_outcome(problem, ledger, key, w, result, time.perf_counter() - t0)
        on_done(i, out[i], False)
    return out


@dataclass(frozen=True)
class Found:
    """An evaluation the ledger holds: ``ev`` None for a recorded failure."""

    ev: Evaluation | None


def from_ledger(problem: Problem, ledger: Ledger, x_si: np.ndarray, retry_failed: bool = False
                ) -> tuple[str, dict[str, float], Found | None]:
    """``(key, w, found)`` of ``x_si (q,)`` SI: ``found`` when the ledger answers for it (a recorded
    failure too, unless ``retry_failed``), None when it must be simulated."""
    key, w = evaluation_key_of(problem, x_si)
    ev = ledger.get_migrating(key, [legacy_evaluation_key(problem, w)])
    if ev is not None and (ev.ok or not retry_failed):
        return key, w, Found(ev if ev.ok else None)
    return key, w, None


def evaluation_task(problem: Problem) -> SpectraTask:
    """The executor task of an evaluation: ``task(w) -> y_sim`` on the run's segments."""
    return SpectraTask.of(problem.simulator, problem.segments, problem.config.spectra)


def record_outcome(problem: Problem, ledger: Ledger, key: str, w: dict[str, float], result: object,
                   wall_s: float) -> Evaluation | None:
    """A task's outcome (y_sim or an exception) as J, committed to the ledger; None for a failed simulation.

    :raises SuspidError: bad data or options, a plugin's bug (not recorded): the run cannot go on.
    :raises BaseException: the executor lost the task (the exception it returned).
    """
    if isinstance(result, SimulatorError):
        ledger.put(Evaluation(key, w, None, None, status="failed", error=str(result), wall_time_s=wall_s))
        return None
    if isinstance(result, BaseException):  # a SuspidError, or the executor lost the task (a worker died, ...)
        raise result
    J, psi = j_of_spectra(problem, result)
    ev = Evaluation(key, w, J, psi.tolist(), wall_time_s=wall_s)
    ledger.put(ev)
    return ev


def evaluate(problem: Problem, ledger: Ledger, x_si: np.ndarray, retry_failed: bool = False) -> Evaluation:
    """J at one parameter vector in this process: :func:`evaluate_many` with the serial executor.

    :param x_si: ``(q,)`` SI values in the order of ``problem.names``.
    :raises SimulatorError: when the simulator fails (the failure is recorded first), or failed before.
    """
    ev = evaluate_many(problem, ledger, np.asarray(x_si, float)[None, :], in_process(),
                       retry_failed=retry_failed)[0]
    if ev is None:
        key, _ = evaluation_key_of(problem, x_si)
        raise SimulatorError(ledger.get(key).error)
    return ev
