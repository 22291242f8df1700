"""One identification, as ``suspid run`` and :func:`suspid.identify` run it (the paper's whole chain).

1. the problem: measured spectra, noise model B and objective
   (:func:`suspid.workflows.problem.build_problem`);
2. J on the maximin design of m0 points, through the run's executor;
3. EGO on the Kriging metamodel (eq. 9), through the ask/tell loop of
   :mod:`suspid.optimize.ego`;
4. identifiability, intervals (:mod:`suspid.workflows.analysis`),
   ``result.json`` and ``report.md`` (:mod:`suspid.workflows.report`).

Every evaluation of J is committed to the run ledger the moment it finishes.
The chain is deterministic for a given config, so a run that was interrupted
is resumed by running it again: the design and the EGO steps are retraced and
every finished evaluation is read from the ledger instead of being simulated
again.
"""

from __future__ import annotations

import copy
import json
import time
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np
import yaml

from suspid import registry
from suspid.config import Config
from suspid.errors import SimulatorError
from suspid.infra.files import write_json, write_text
from suspid.infra.ledger import Evaluation, Ledger
from suspid.infra.lock import open_run_dir
from suspid.infra.threads import single_blas_thread
from suspid.interfaces import Executor
from suspid.optimize.design import from_unit, make_design
from suspid.optimize.ego import EGOResult, run_ego
from suspid.workflows.analysis import analyse
from suspid.workflows.evaluation import evaluate_many, evaluation_key_of
from suspid.workflows.problem import Problem, build_problem
from suspid.workflows.report import write_report


def make_progress(enabled: bool):
    """A rich progress display with elapsed and remaining time (disabled: a no-op display)."""
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)  # rich is imported by the display only

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    TextColumn("eta"), TimeRemainingColumn(), TextColumn("{task.fields[status]}"),
                    disable=not enabled, transient=False)


@dataclass
class IdentificationResult:
    """What one identification found (the content of ``result.json``), typed.

    Parameter mappings are keyed by the identified parameter names, in order.

    :ivar w_opt: identified values, SI units.
    :ivar w_opt_normalized: the same in ``[0, 1]`` of each admissible interval.
    :ivar intervals: ``name -> (lower, upper)`` SI; not a finding where ``identifiable`` is False.
    :ivar identifiable: ``name -> bool``; :ivar reasons: why a component is not identifiable.
    :ivar w_ref: the known parameters of a numerical experiment, else None.
    :ivar errors_percent: ``|w_opt - w_ref|`` in % of the interval (numerical experiment), else None.
    :ivar trustworthy: ``name -> bool``: False where the model-error checks (measured data) say the
        value is not a finding (reasons in ``result["untrustworthy_reasons"]``).
    :ivar J_max: J(w_opt).
    :ivar n_initial, n_iterations, n_simulator_calls: m0, EGO iterations, evaluations of J.
    :ivar stop_reason, refine_stop_reason: why the EGO loop (and the refinement) stopped.
    :ivar run_dir: the run directory (``result.json``, ``report.md``, ``ledger.sqlite``, ``noise_model.npz``).
    """

    parameters: list[str]
    units: dict[str, str]
    bounds: dict[str, tuple[float, float]]
    w_opt: dict[str, float]
    w_opt_normalized: dict[str, float]
    intervals: dict[str, tuple[float, float]]
    identifiable: dict[str, bool]
    reasons: dict[str, list[str]]
    J_max: float
    n_initial: int
    n_iterations: int
    n_simulator_calls: int
    stop_reason: str
    refine_stop_reason: str | None
    wall_time_s: float
    run_dir: Path
    w_ref: dict[str, float] | None = None
    errors_percent: dict[str, float] | None = None
    trustworthy: dict[str, bool] | None = None
    problem: Problem | None = field(default=None, repr=False, compare=False)
    ego: EGOResult | None = field(default=None, repr=False, compare=False)
    _data: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def from_dict(cls, data: dict[str, Any], run_dir: Path, problem: Problem | None = None,
                  ego: EGOResult | None = None) -> "IdentificationResult":
        """From the content of a ``result.json`` (and, in a live run, the problem and the EGO result)."""
        return cls(parameters=list(data["parameters"]), units=dict(data["units"]),
                   bounds={n: tuple(b) for n, b in data["bounds"].items()}, w_opt=dict(data["w_opt"]),
                   w_opt_normalized=dict(data["w_opt_normalized"]),
                   intervals={n: tuple(b) for n, b in data["interval"].items()},
                   identifiable=dict(data["identifiable"]), reasons=dict(data["non_identifiable_reasons"]),
                   J_max=float(data["J_max"]), n_initial=int(data["n_initial"]),
                   n_iterations=int(data["n_iterations"]), n_simulator_calls=int(data["n_simulator_calls"]),
                   stop_reason=data["stop_reason"], refine_stop_reason=data.get("refine_stop_reason"),
                   wall_time_s=float(data["wall_time_s"]), run_dir=Path(run_dir), w_ref=data.get("w_ref"),
                   errors_percent=data.get("errors_percent"), trustworthy=data.get("trustworthy"),
                   problem=problem, ego=ego, _data=data)

    @classmethod
    def load(cls, run_dir: str | Path) -> "IdentificationResult":
        """Read the ``result.json`` of a finished run."""
        run_dir = Path(run_dir)
        return cls.from_dict(json.loads((run_dir / "result.json").read_text(encoding="utf-8")), run_dir)

    @property
    def result(self) -> dict[str, Any]:
        """The whole result as in ``result.json`` (sensitivity indices, interval method, ...)."""
        return self._data

    def to_dict(self) -> dict[str, Any]:
        """A copy of the JSON-able dict written to ``result.json`` (equal to it once read back)."""
        return copy.deepcopy(self._data)

    @property
    def max_error_percent(self) -> float | None:
        """The largest error over the identifiable components (numerical experiment), else None."""
        if self.errors_percent is None:
            return None
        errors = [e for n, e in self.errors_percent.items() if self.identifiable[n]]
        return max(errors) if errors else None


def write_config(config: Config, run_dir: Path) -> None:
    """The resolved config, ``config.yaml`` in the run directory (atomically)."""
    write_text(run_dir / "config.yaml", yaml.safe_dump(config.model_dump(mode="json", exclude={"source_file"}),
                                                       sort_keys=False))


def failure(problem: Problem, ledger: Ledger, phase: str, x_si: np.ndarray) -> dict[str, Any]:
    """A failed point for ``result.json``: its phase, w and the simulator's message from the ledger."""
    key, w = evaluation_key_of(problem, x_si)
    found = ledger.get(key)
    return {"phase": phase, "w": w, "error": found.error if found is not None else "unknown"}


def surrogate_for(config: Config):
    """The configured surrogate; its options were resolved (seed included) when the config was loaded."""
    return registry.get("surrogate", config.surrogate.plugin)(**config.surrogate.options)


def run(config: Config, *, fresh: bool = False, progress: bool = False,
        log: Callable[[str], None] = lambda s: None, retry_failed: bool = False,
        force: bool = False) -> IdentificationResult:
    """The whole identification (see the module docstring); writes result.json and report.md.

    A simulation that fails (a :class:`~suspid.errors.SimulatorError`) at a point
    of the design, of EGO or of the refinement does not end the run: the failure
    is kept in the ledger with its message, the point is infeasible for the
    metamodel (it takes the worst J found so far, so EI leads away from it and it
    is never w_opt), and ``result.json``/``report.md`` list it. Running again
    does not simulate recorded failures unless ``retry_failed``.

    :param config: a loaded config (:func:`suspid.config.load_config`).
    :param fresh: forget the ledger of a previous run in the same directory.
    :param progress: show rich progress bars.
    :param log: receives one line per step.
    :param retry_failed: simulate again the points whose simulation failed before.
    :param force: take over a run directory that holds another config's run.
    :raises RunDirError: the run directory is in use by another process, or holds another config's run.
    """
    run_dir = config.run_dir()
    # the executor first: an unreachable cluster, or workers that cannot run suspid, stop the run before anything
    with registry.get("executor", config.executor.plugin)(**config.executor.options) as executor, \
            open_run_dir(run_dir, config_name=config.name, config_file=config.source_file, fresh=fresh,
                         force=force, log=log) as ledger:
        log(executor.describe())
        write_config(config, run_dir)
        return _run(config, run_dir, ledger, executor, progress=progress, log=log, retry_failed=retry_failed)


def _run(config: Config, run_dir: Path, ledger: Ledger, executor: Executor, *, progress: bool,
         log: Callable[[str], None], retry_failed: bool) -> IdentificationResult:
    """:func:`run` inside its locked run directory; every simulation runs on ``executor`` (entered)."""
    t_start = time.perf_counter()
    n_before = ledger.count()
    problem = build_problem(config, ledger, log, executor)
    problem.noise_model.save(run_dir / "noise_model.npz")

    surrogate = surrogate_for(config)
    X0 = from_unit(make_design(config.design, problem.q), problem.bounds)
    ei_history: list[float] = []
    # The Kriging fits and the EI search work on small matrices: OpenBLAS threads only contend (suspid.infra.threads)
    with make_progress(progress) as bars, single_blas_thread():
        design_task = bars.add_task("initial design", total=len(X0), status="")
        j_max = -np.inf

        def design_done(i: int, ev: Evaluation | None, reused: bool) -> None:
            nonlocal j_max
            if ev is not None:
                j_max = max(j_max, ev.J)
            bars.update(design_task, advance=1, status=f"J_max {j_max:.4g}" if ev else "failed point")

        with nullcontext(executor):  # entered by run(): the same executor serves the whole run
            evs = evaluate_many(problem, ledger, X0, executor, design_done, retry_failed=retry_failed)
            ok = np.array([e is not None for e in evs])
            failed = [failure(problem, ledger, "design", x) for x, e in zip(X0, evs) if e is None]
            if ok.sum() < 2:
                raise SimulatorError(f"only {int(ok.sum())} of {len(evs)} design points could be simulated; "
                                     f"see the failures in {ledger.path}")
            for i, e in enumerate(evs):
                if e is not None:
                    ledger.put_iteration("design", i, {"w": e.w, "J": e.J})
            y0 = np.array([e.J for e in evs if e is not None])
            ego_opts = config.ego
            ego_task = bars.add_task("EGO", total=ego_opts.max_iter + (ego_opts.refine.max_iter
                                                                       if ego_opts.refine.enabled else 0), status="")

            worst = [float(np.min(y0))]  # J given to failed points: the worst J found so far

            def value(x: np.ndarray, ev: Evaluation | None) -> float:
                if ev is None:
                    failed.append(failure(problem, ledger, "ego", x))
                    return worst[0]
                worst[0] = min(worst[0], ev.J)
                return ev.J

            def func(x: np.ndarray) -> float:
                return func_batch(np.asarray(x, float)[None, :])[0]

            def func_batch(X: np.ndarray) -> list[float]:
                """EGO points, simulated in parallel by the executor when ``ego.batch`` > 1."""
                out = evaluate_many(problem, ledger, X, executor, retry_failed=retry_failed)
                return [value(x, e) for x, e in zip(X, out)]

            def callback(record) -> None:
                if record.phase != "initial":
                    ei_history.append(float(record.EI) if record.EI is not None else float("nan"))
                    run_key = "refine" if record.phase.startswith("refine") else "ego"
                    ledger.put_iteration(run_key, record.index, {
                        "iteration": record.iteration, "phase": record.phase, "w": problem.w_of(record.x),
                        "J": record.J, "EI": record.EI, "J_max": record.J_max, "epsilon": record.epsilon,
                        "hyperparameters": record.hyperparameters, "fit_s": record.fit_seconds,
                        "search_s": record.search_seconds, "eval_s": record.eval_seconds})
                    bars.update(ego_task, advance=1 if record.phase in ("ego", "refine") else 0,
                                status=f"J_max {record.J_max:.4g}  EI {record.EI:.2e}"
                                if record.EI is not None else "")

            ego = run_ego(func, problem.bounds, ego=ego_opts, design=config.design, surrogate=surrogate,
                          X_init=X0[ok], y_init=y0, callback=callback,
                          func_batch=func_batch if ego_opts.batch > 1 else None)
        bars.update(ego_task, total=max(ego.n_iterations, 1), completed=max(ego.n_iterations, 1))

    with single_blas_thread():
        result = analyse(problem, ledger, ego, config, failed, retry_failed, executor)
    result.update({
        "n_initial": int(ok.sum()), "n_iterations": int(ego.n_iterations),
        "n_simulator_calls": int(ego.n_evaluations),
        "n_simulator_calls_this_session": int(ledger.count() - n_before),
        "stop_reason": ego.stop_reason, "n_refine_iterations": int(ego.n_refine),
        "refine_stop_reason": ego.refine_stop_reason, "wall_time_s": round(time.perf_counter() - t_start, 3),
        "design_min_distance": float(ego.design_min_distance),
    })
    write_json(run_dir / "result.json", result)
    write_report(run_dir, problem, ego, result, ei_history, executor)
    return IdentificationResult.from_dict(result, run_dir, problem, ego)
