"""One identification, as ``suspid run`` and :func:`suspid.identify` run it (the paper's whole chain).

1. the problem: measured spectra, noise model B and objective
   (:func:`suspid.workflows.problem.build_problem`);
2. the optimiser the config names (``optimizer:``, default ``ego``: the paper's
   maximin design of m0 points, then EGO on the Kriging metamodel, eq. 9) driven
   through its trials by :func:`suspid.workflows.driver.drive`, every J through the run's executor;
3. the loop's state at its end (:meth:`suspid.interfaces.Optimizer.loop_state`) and the
   surrogate fitted on its points (the EGO loop's own; for optimisers without a metamodel,
   the configured surrogate fitted on every evaluated point), which the analysis reads;
4. identifiability, intervals (:mod:`suspid.workflows.analysis`),
   ``result.json`` and ``report.md`` (:mod:`suspid.workflows.report`).

Every evaluation of J is committed to the run ledger the moment it finishes.
The chain is deterministic for a given config, so a run that was interrupted
is resumed by running it again: the optimiser's steps are retraced and every
finished evaluation is read from the ledger instead of being simulated again.
The ledger's ``trials`` rows (:meth:`suspid.infra.ledger.Ledger.trials`, and ``result.json``'s
``anytime``) keep J and w of every trial in order: the anytime history of the run.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import yaml

from suspid import registry
from suspid.config import Config, optimizer_budget
from suspid.errors import ConfigError
from suspid.infra import history
from suspid.infra.files import write_json, write_text
from suspid.infra.ledger import Ledger
from suspid.infra.seeds import seed_for
from suspid.infra.lock import open_run_dir
from suspid.infra.threads import single_blas_thread
from suspid.interfaces import Executor
from suspid.workflows.analysis import analyse, cached_y_sim
from suspid.workflows.driver import drive
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
    if n_before:   # a resumed or repeated run: what it will not simulate again
        log(f"reusing {n_before} finished simulations from the ledger {ledger.path} (--fresh starts over)")
    problem = build_problem(config, ledger, log, executor)
    problem.noise_model.save(run_dir / "noise_model.npz")
    optimizer = optimizer_for(config, problem)
    # The Kriging fits and the EI search work on small matrices: OpenBLAS threads only contend (suspid.infra.threads)
    with make_progress(progress) as bars, single_blas_thread():
        opt_result, failed = drive(optimizer, problem, ledger, executor, bars, retry_failed=retry_failed)
    ego = optimizer.loop_state()   # the loop's state at its end, and the surrogate fitted on its points
    surrogate = ego.fitted_surrogate(surrogate_for(config))
    ei_history = [float(r.EI) if r.EI is not None else float("nan") for r in ego.history if r.phase != "initial"]

    model = getattr(optimizer, "spectra_model", None)
    model = model if isinstance(model, ProblemSpectraModel) else None   # identifiability from the Fisher information
    with make_progress(progress) as bars, single_blas_thread():   # minutes on measured data: shown phase by phase
        analysis = analyse(problem, ledger, ego, surrogate, config, failed, retry_failed, executor,
                           ProgressPhases(bars), spectra_model=model)
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
    out.objective_weights = problem.weights_record
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
