"""One identification, as ``suspid run`` and :func:`suspid.identify` run it (the paper's whole chain).

1. the problem: measured spectra, noise model B and objective
   (:func:`suspid.workflows.problem.build_problem`);
2. the optimiser the config names (``optimizer:``, default ``ego``: the paper's
   maximin design of m0 points, then EGO on the Kriging metamodel, eq. 9) driven
   through ask/tell by :func:`drive`, every J through the run's executor;
3. for optimisers without a metamodel of their own, the configured surrogate
   fitted on every evaluated point (the analysis reads it);
4. identifiability, intervals (:mod:`suspid.workflows.analysis`),
   ``result.json`` and ``report.md`` (:mod:`suspid.workflows.report`).

Every evaluation of J is committed to the run ledger the moment it finishes.
The chain is deterministic for a given config, so a run that was interrupted
is resumed by running it again: the optimiser's steps are retraced and every
finished evaluation is read from the ledger instead of being simulated again.
The ledger's ``evaluations`` rows (and ``result.json``'s ``anytime``) keep J and
w of every evaluation in order: the anytime history of the run.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import yaml

from suspid import registry
from suspid.config import Config, optimizer_budget
from suspid.errors import ConfigError, SimulatorError
from suspid.infra import history
from suspid.infra.files import write_json, write_text
from suspid.infra.ledger import Ledger
from suspid.infra.seeds import seed_for
from suspid.infra.lock import open_run_dir
from suspid.infra.threads import single_blas_thread
from suspid.interfaces import Executor, OptimizerResult
from suspid.optimize.design import min_distance
from suspid.optimize.ego import EGOResult
from suspid.workflows.analysis import analyse, cached_y_sim
from suspid.workflows.asynchronous import drive_async
from suspid.workflows.evaluation import evaluate_many, evaluation_key_of
from suspid.workflows.gradient import ProblemSpectraModel
from suspid.workflows.elements import localisation_markdown, localisation_wanted, localise_problem, moved_kinds
from suspid.workflows.phases import ProgressPhases
from suspid.workflows.problem import Problem, build_problem
from suspid.workflows.report import write_report
from suspid.workflows.verdict import verdict_block, verdict_rows
from suspid.workflows.results import Anytime, IdentificationResult


def make_progress(enabled: bool):
    """A rich progress display with elapsed and remaining time (disabled: a no-op display)."""
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn,
                               TimeRemainingColumn)  # rich is imported by the display only

    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    TextColumn("eta"), TimeRemainingColumn(), TextColumn("{task.fields[status]}"),
                    disable=not enabled, transient=False)


def resolved_config(config: Config) -> dict[str, Any]:
    """The resolved config as data: what ``config.yaml`` holds, and what the run id is the digest of."""
    return config.model_dump(mode="json", exclude={"source_file"})


def write_config(config: Config, run_dir: Path) -> None:
    """The resolved config, ``config.yaml`` in the run's folder (atomically)."""
    write_text(run_dir / "config.yaml", yaml.safe_dump(resolved_config(config), sort_keys=False))


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

    The run writes its outputs into ``<run dir>/history/<run id>/`` (the run id is the digest of the
    resolved config) and, once finished, puts them at the top of the run directory
    (:mod:`suspid.infra.history`): another run of a config of the same name (another seed, ...) in the
    same directory keeps its own results; the same config again resumes.

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
    run_id = history.run_id_of(resolved_config(config))
    # the executor first: an unreachable cluster, or workers that cannot run suspid, stop the run before anything
    with registry.get("executor", config.executor.plugin)(**config.executor.options) as executor, \
            open_run_dir(run_dir, config_name=config.name, config_file=config.source_file, fresh=fresh,
                         force=force, log=log) as ledger:
        log(executor.describe())
        own_dir = history.begin(run_dir, run_id, ledger)   # this run writes only there (suspid.infra.history)
        write_config(config, own_dir)
        out = _run(config, own_dir, run_id, ledger, executor, progress=progress, log=log,
                   retry_failed=retry_failed)
        history.publish(run_dir, run_id)
        out.run_dir = run_dir
        return out


def optimizer_for(config: Config, problem: Problem):
    """The configured optimiser (:class:`suspid.interfaces.Optimizer`) over the problem's box.

    Its options were validated when the config was loaded; its seed is the option ``seed``
    where its options have one (``ego.seed``), else derived from the run seed (stream
    ``"optimizer"``); its budget is :func:`suspid.config.optimizer_budget`.
    """
    cls = registry.get("optimizer", config.optimizer.plugin)
    options = dict(config.optimizer.options)
    seed = options.pop("seed", seed_for(config.seed, "optimizer"))  # an option ``seed`` (``ego.seed``) is the seed
    return cls(problem.bounds, budget=optimizer_budget(config, problem.q), seed=seed, design=config.design,
               surrogate=surrogate_for(config), **options)


def _run(config: Config, run_dir: Path, run_id: str, ledger: Ledger, executor: Executor, *, progress: bool,
         log: Callable[[str], None], retry_failed: bool) -> IdentificationResult:
    """:func:`run` inside its locked run directory; every simulation runs on ``executor`` (entered).

    ``run_dir`` is the run's own folder (``history/<run id>/``), where its outputs go.
    """
    t_start = time.perf_counter()
    n_before = ledger.count()
    problem = build_problem(config, ledger, log, executor)
    problem.noise_model.save(run_dir / "noise_model.npz")
    optimizer = optimizer_for(config, problem)
    # The Kriging fits and the EI search work on small matrices: OpenBLAS threads only contend (suspid.infra.threads)
    with make_progress(progress) as bars, single_blas_thread():
        opt_result, failed = drive(optimizer, problem, ledger, executor, bars, retry_failed=retry_failed)
    ego = opt_result.details if isinstance(opt_result.details, EGOResult) else \
        as_ego_result(opt_result, surrogate_for(config), problem)
    ei_history = [float(r.EI) if r.EI is not None else float("nan") for r in ego.history if r.phase != "initial"]

    model = getattr(optimizer, "spectra_model", None)
    model = model if isinstance(model, ProblemSpectraModel) else None   # identifiability from the Fisher information
    with make_progress(progress) as bars, single_blas_thread():   # minutes on measured data: shown phase by phase
        analysis = analyse(problem, ledger, ego, config, failed, retry_failed, executor, ProgressPhases(bars),
                           spectra_model=model)
    out = IdentificationResult.of(
        analysis, run_id=run_id,
        n_initial=int(ego.n_initial), n_iterations=int(ego.n_iterations),
        n_simulator_calls=int(ego.n_evaluations),
        n_simulator_calls_this_session=int(ledger.count() - n_before),
        stop_reason=ego.stop_reason, n_refine_iterations=int(ego.n_refine),
        refine_stop_reason=ego.refine_stop_reason, wall_time_s=round(time.perf_counter() - t_start, 3),
        design_min_distance=float(ego.design_min_distance) if np.isfinite(ego.design_min_distance) else None,
        optimizer=config.optimizer.plugin, budget=int(optimizer.budget),
        anytime=Anytime(J=[None if not np.isfinite(v) else float(v) for v in opt_result.y],
                        w_normalized=problem.to_unit(opt_result.X).tolist() if len(opt_result.X) else []),
        run_dir=run_dir, problem=problem, ego=ego)
    if model is not None:   # Jacobians: counted apart from the simulator calls
        # a plain simulation's wall time: the evaluations asked one at a time, after the design's batch
        walls = [ev.wall_time_s for ev in ledger.evaluations("ok") if ev.wall_time_s][int(ego.n_initial):]
        out.jacobian = model.summary(float(np.median(walls)) if walls else None)
    floor = problem.noise_model.floor_
    if floor is not None:
        out.noise_floor = {"mode": config.noise.floor if config.noise.path is None else "file",
                           "channels": floor.summary(problem.freqs, problem.channels)}
    out.localisation = _localise(config, problem, out.to_json(), executor, log)
    add_verdict(out, problem, config)   # after every other finding (a localisation's groups included)
    result = out.to_json()
    write_json(run_dir / "result.json", result)
    with make_progress(progress) as bars:
        phases = ProgressPhases(bars)
        phases.start("figures and report")
        y_opt = cached_y_sim(problem, ledger, problem.to_unit(np.asarray(ego.x_opt, float)), executor=executor)
        write_report(run_dir, problem, ego, result, ei_history, executor, y_opt=y_opt)
        phases.done()
    if out.localisation is not None:   # a short section after the report (suspid.workflows.elements)
        report = run_dir / "report.md"
        text = report.read_text(encoding="utf-8") if report.exists() else ""
        write_text(report, text.rstrip("\n") + "\n\n" + localisation_markdown(out.localisation, out.units))
    return out


def _localise(config: Config, problem: Problem, result: dict[str, Any], executor, log) -> dict[str, Any] | None:
    """The localisation entry of ``result`` (:func:`suspid.workflows.elements.localise_problem`) when
    ``localisation.enabled`` asks for it (``auto``: an identified kind with elements moved out of its nominal
    value); ``None`` otherwise. Without a reference date it is ``{"named": False, "not_assessed": why}``."""
    if not localisation_wanted(config, result, problem.simulator):
        return None
    try:
        return localise_problem(problem, config.localisation, moved=moved_kinds(result, problem.simulator),
                                executor=executor, log=log)
    except ConfigError as exc:
        if config.localisation.enabled is True:
            raise
        return {"named": False, "rows": [], "hypotheses": [], "not_assessed": str(exc),
                "options": config.localisation.model_dump()}


def add_verdict(result: IdentificationResult, problem: Problem, config: Config) -> None:
    """``result.nominal`` (SI, per identified parameter) and ``result.verdict_block``
    (:func:`suspid.workflows.verdict.verdict_block`): the maintenance verdict per parameter and localised group."""
    parameters = problem.simulator.parameters()
    rows = verdict_rows(result.to_json(), parameters, config.limits)
    result.nominal = {r.name: r.nominal for r in rows if r.source == "identification"}
    result.verdict_block = verdict_block(rows, config.limits)


def drive(optimizer, problem: Problem, ledger: Ledger, executor, bars, *, retry_failed: bool = False
          ) -> tuple[OptimizerResult, list[dict[str, Any]]]:
    """Run an optimiser through ask/tell, every J through the executor and the ledger (failures kept).

    Each step asks as many points as the executor has workers and evaluates them
    together (:func:`evaluate_many`); an optimiser that asks for it
    (:meth:`suspid.interfaces.Optimizer.asynchronous`: ``ego.asynchronous`` with
    ``ego.batch = 1`` and several workers) keeps one point in flight per worker
    instead (:func:`suspid.workflows.asynchronous.drive_async`).

    Every evaluation is recorded in the ledger's ``evaluations`` rows (index -> w and J, None for a
    failed point) in the order the optimiser is told: the anytime history of the run. The optimiser's
    own rows (:attr:`suspid.interfaces.Optimizer.on_record`) go to the ledger with ``x`` given as w.

    :returns: the optimiser's result and the failed points (phase, w and the simulator's message).
    """
    def on_record(run: str, index: int, row: dict) -> None:
        row = dict(row)
        if "x" in row:
            row = {"w": problem.w_of(np.asarray(row.pop("x"), float)), **row}
        ledger.put_iteration(run, index, row)

    optimizer.on_record = on_record
    if getattr(optimizer, "uses_jacobian", False):
        optimizer.spectra_model = ProblemSpectraModel(problem, ledger, executor)
    label = optimizer.name  # the phase of a failed point after the design
    task = bars.add_task(label, total=optimizer.budget, status="")
    failed: list[dict[str, Any]] = []
    n, j_max = 0, -np.inf

    def tell(X: np.ndarray, evs: list) -> None:
        nonlocal n, j_max
        phase = "design" if n == 0 and len(X) > 1 else label
        for x, ev in zip(X, evs):
            if ev is None:
                failed.append(failure(problem, ledger, phase, x))
            else:
                j_max = max(j_max, ev.J)
            ledger.put_iteration("evaluations", n, {"w": problem.w_of(x), "J": ev.J if ev else None})
            n += 1
        optimizer.tell(X, [ev.J if ev is not None else None for ev in evs])
        bars.update(task, completed=n, status=f"J_max {j_max:.4g}" if np.isfinite(j_max) else "failed points")

    def together(X: np.ndarray) -> None:
        tell(X, evaluate_many(problem, ledger, X, executor, lambda i, ev, reused: bars.update(task, advance=1),
                              retry_failed=retry_failed))

    n_workers = executor.n_workers
    if optimizer.asynchronous(n_workers):
        drive_async(optimizer, problem, ledger, executor, n_workers, tell, together, retry_failed=retry_failed)
    else:
        while not optimizer.done:
            X = np.atleast_2d(optimizer.ask(n=n_workers))
            if X.size == 0:
                break
            together(X)
    bars.update(task, total=max(n, 1), completed=max(n, 1))
    if not np.isfinite(j_max):
        raise SimulatorError(f"none of the {n} points could be simulated; see the failures in {ledger.path}")
    return optimizer.result(), failed


def as_ego_result(res: OptimizerResult, surrogate, problem: Problem) -> EGOResult:
    """An optimiser's result in the form the analysis takes: points with a value, and the configured
    surrogate fitted on them (identifiability, Sobol indices and intervals read it)."""
    ok = np.isfinite(res.y)
    U = problem.to_unit(res.X[ok])
    fitted = None
    if ok.sum() >= 2:
        with single_blas_thread():
            fitted = surrogate.fit(U, res.y[ok])
    return EGOResult(x_opt=np.asarray(res.x_opt, float), y_opt=float(res.y_opt), X=res.X[ok], y=res.y[ok], X_unit=U,
                     n_initial=int(min(res.n_initial, ok.sum())), stop_reason=res.stop_reason, history=[],
                     surrogate=fitted, bounds=problem.bounds, design_min_distance=min_distance(U[:res.n_initial]),
                     n_function_calls=res.n_evaluations, X_failed=res.X[~ok])
