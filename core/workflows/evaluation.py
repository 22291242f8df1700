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
from typing import Callable

import numpy as np

from suspid import registry
from suspid.errors import SimulatorError, SuspidError
from suspid.infra.ledger import Evaluation, Ledger, evaluation_key
from suspid.interfaces import Executor
from suspid.method.objective import ObjectiveFunction
from suspid.workflows.problem import Problem
from suspid.workflows.tasks import SpectraTask, in_process


def j_of_spectra(problem: Problem, y_sim: np.ndarray, b: np.ndarray | None = None,
                 y_mes: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """J = Σ α_k Ψ_k (eq. 5) with Y_mod = y_sim + b (by default the run's fixed paths and measured spectra)."""
    fn = ObjectiveFunction(problem.objective, problem.y_mes if y_mes is None else y_mes, problem.freqs,
                           problem.b if b is None else b, weights=problem.weights, channels=problem.channels,
                           floor=problem.noise_model.floor_)
    J, psi = fn.evaluate(y_sim)
    return J, psi


def simulate_spectra_task(task: tuple) -> np.ndarray:
    """One evaluation from a tuple ``(plugin name, options, w, segments, spectra) -> y_sim``.

    Module-level and built from picklable parts; the simulator class comes from
    the registry of the process that runs it. Each item carries its segments:
    :class:`SpectraTask` sends them once per worker instead.
    """
    plugin, options, w, segments, spectra_options = task
    return SpectraTask(registry.get("simulator", plugin), dict(options), list(segments), spectra_options)(w)


def evaluation_key_of(problem: Problem, x_si: np.ndarray) -> tuple[str, dict[str, float]]:
    """The ledger key of ``x_si (q,)`` SI and its parameter mapping w."""
    w = problem.w_of(x_si)
    return evaluation_key(problem.simulator_identity, w, problem.data_identity), w


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
        key, w = evaluation_key_of(problem, x)
        found = ledger.get(key)
        if found is not None and (found.ok or not retry_failed):
            out[i] = found if found.ok else None
            on_done(i, out[i], True)
        else:
            keys[len(todo)] = (i, key, w)
            todo.append(w)
    task = SpectraTask.of(problem.simulator, problem.segments, problem.config.spectra)
    t0 = time.perf_counter()
    for j, result in executor.map_unordered(task, todo) if todo else ():
        i, key, w = keys[j]
        wall = time.perf_counter() - t0
        if isinstance(result, SimulatorError):
            ledger.put(Evaluation(key, w, None, None, status="failed", error=str(result), wall_time_s=wall))
            on_done(i, None, False)
            continue
        if isinstance(result, SuspidError):  # bad data or options, a plugin's bug: the run cannot go on
            raise result
        if isinstance(result, BaseException):  # the executor lost the task (a worker died, ...)
            raise result
        J, psi = j_of_spectra(problem, result)
        ev = Evaluation(key, w, J, psi.tolist(), wall_time_s=wall)
        ledger.put(ev)
        out[i] = ev
        on_done(i, ev, False)
    return out


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
