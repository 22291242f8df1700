"""One identification, as ``suspid run`` and :func:`suspid.identify` run it (the paper's whole chain).

1. the problem: measured spectra, noise model B and objective
   (:func:`suspid.workflows.problem.build_problem`);
2. the optimiser the config names (``optimizer:``, default ``ego``: the paper's
   maximin design of m0 points, then EGO on the Kriging metamodel, eq. 9) driven
   through its trials by :func:`suspid.workflows.driver.drive`, every J through the run's executor;
3. for optimisers without a metamodel of their own, the configured surrogate
   fitted on every evaluated point (the analysis reads it);
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

import copy
import json
from html import escape
import time
from dataclasses import dataclass, field
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
from suspid.interfaces import Executor, OptimizerResult
from suspid.optimize.loop import LoopOutcome
from suspid.workflows.analysis import analyse, cached_y_sim
from suspid.workflows.driver import drive
from suspid.workflows.gradient import ProblemSpectraModel
from suspid.workflows.elements import localisation_markdown, localisation_wanted, localise_problem, moved_kinds
from suspid.workflows.phases import ProgressPhases
from suspid.workflows.problem import Problem, build_problem
from suspid.workflows.report import trust_word, write_report
from suspid.workflows.verdict import VerdictRow, rows_of, summary_line, table, verdict_block, verdict_rows


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
    :ivar trustworthy: ``name -> True | False | None``, trust under model error: True (yes) where the
        model-error checks all ran and none flags the component, False (no) where a check flags it (the value
        is not a finding; reasons in :attr:`untrustworthy_reasons`), None (not assessed) where no check that
        ran flags it but the checks that would judge it did not all run (why in :attr:`not_assessed_reasons`).
    :ivar untrustworthy_reasons, not_assessed_reasons: ``name -> [str]`` for the no's and the not assessed.
    :ivar J_max: J(w_opt).
    :ivar n_initial, n_iterations, n_simulator_calls: m0, EGO iterations, evaluations of J.
    :ivar stop_reason, refine_stop_reason: why the EGO loop (and the refinement) stopped.
    :ivar nominal: ``name -> nominal value`` (SI) the verdict measures the change from.
    :ivar verdict: the maintenance verdict, one :class:`~suspid.workflows.verdict.VerdictRow` per identified
        parameter and per localised element group (:meth:`summary`, :meth:`verdict_table`, :meth:`to_dataframe`).
    :ivar run_dir: the run directory (``result.json``, ``report.md``, ``ledger.sqlite``, ``noise_model.npz``):
        they are the latest finished run's; this run's own are in ``history/<run_id>/`` (``result["run_id"]``).
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
    trustworthy: dict[str, bool | None] | None = None
    untrustworthy_reasons: dict[str, list[str]] = field(default_factory=dict)
    not_assessed_reasons: dict[str, list[str]] = field(default_factory=dict)
    nominal: dict[str, float | None] = field(default_factory=dict)
    verdict: list[VerdictRow] = field(default_factory=list)
    problem: Problem | None = field(default=None, repr=False, compare=False)
    ego: LoopOutcome | None = field(default=None, repr=False, compare=False)
    _data: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def from_dict(cls, data: dict[str, Any], run_dir: Path, problem: Problem | None = None,
                  ego: LoopOutcome | None = None) -> "IdentificationResult":
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
                   untrustworthy_reasons=dict(data.get("untrustworthy_reasons", {})),
                   not_assessed_reasons=dict(data.get("not_assessed_reasons", {})),
                   nominal=dict(data.get("nominal", {})), verdict=rows_of(data), problem=problem, ego=ego, _data=data)

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
    def trust(self) -> dict[str, str]:
        """``name -> "yes" | "no" | "not assessed"``: :attr:`trustworthy` in words."""
        return {n: trust_word((self.trustworthy or {}).get(n)) for n in self.parameters}

    def verdict_table(self) -> list[dict[str, Any]]:
        """The verdict as plain rows (no pandas needed): one dict per parameter or group, SI values and units,
        change and interval in % of nominal, identifiable, trust, verdict and its rule."""
        return [r.to_dict() for r in self.verdict]

    def to_dataframe(self):
        """The verdict table as a pandas DataFrame, one row per parameter or group (pandas is imported here,
        only when asked for: suspid does not depend on it).

        :raises ImportError: pandas is not installed (``verdict_table()`` gives the same rows without it).
        """
        try:
            import pandas as pd   # optional: only this method needs it
        except ImportError:
            raise ImportError("to_dataframe() needs pandas (pip install pandas); verdict_table() gives the same "
                              "rows as plain dicts") from None
        return pd.DataFrame(self.verdict_table()).set_index("name")

    def _table(self) -> tuple[list[str], list[list[str]]]:
        return table(self.verdict, with_reference=self.w_ref is not None)

    def summary(self) -> str:
        """A plain-text table: per parameter (and localised group) nominal, identified value with units, change
        and interval in % of nominal, identifiable, trust and verdict; then one plain-language line each."""
        header, cells = self._table()
        widths = [max(len(h), *(len(c[i]) for c in cells)) if cells else len(h) for i, h in enumerate(header)]
        line = lambda row: "  ".join(v.ljust(w) for v, w in zip(row, widths)).rstrip()  # noqa: E731
        title = (f"{self._data.get('name', 'identification')}: J_max = {self.J_max:.6g}, "
                 f"{self.n_simulator_calls} simulations, {self.wall_time_s:.0f} s")
        out = [title, line(header), line(["-" * w for w in widths]), *map(line, cells), ""]
        out += [summary_line(r, markdown=False) for r in self.verdict]
        return "\n".join(out)

    def _repr_html_(self) -> str:
        """The verdict table in a notebook (HTML), with the plain-language lines below it."""
        header, cells = self._table()
        colour = {"ok": "#1a7f37", "warning": "#b35900", "alarm": "#c62828", "not assessable": "#666"}
        k = header.index("verdict")
        body = "".join("<tr>" + "".join(
            f'<td style="color:{colour.get(c, "inherit")}">{escape(c)}</td>' if i == k else f"<td>{escape(c)}</td>"
            for i, c in enumerate(row)) + "</tr>" for row in cells)
        lines = "".join(f"<li>{escape(summary_line(r, markdown=False))}</li>" for r in self.verdict)
        return (f"<p><b>{escape(str(self._data.get('name', 'identification')))}</b>: J_max = {self.J_max:.6g}, "
                f"{self.n_simulator_calls} simulations, run directory <code>{escape(str(self.run_dir))}</code></p>"
                f"<table><thead><tr>{''.join(f'<th>{escape(h)}</th>' for h in header)}</tr></thead>"
                f"<tbody>{body}</tbody></table><ul>{lines}</ul>")

    def __repr__(self) -> str:
        states = ", ".join(f"{r.name} {r.verdict}" for r in self.verdict)
        return (f"IdentificationResult({self._data.get('name', '?')!r}, {len(self.parameters)} parameters, "
                f"J_max={self.J_max:.6g}, verdict: {states or 'none'}, run_dir={str(self.run_dir)!r})")

    @property
    def max_error_percent(self) -> float | None:
        """The largest error over the identifiable components (numerical experiment), else None."""
        if self.errors_percent is None:
            return None
        errors = [e for n, e in self.errors_percent.items() if self.identifiable[n]]
        return max(errors) if errors else None


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
    problem = build_problem(config, ledger, log, executor)
    problem.noise_model.save(run_dir / "noise_model.npz")
    optimizer = optimizer_for(config, problem)
    # The Kriging fits and the EI search work on small matrices: OpenBLAS threads only contend (suspid.infra.threads)
    with make_progress(progress) as bars, single_blas_thread():
        opt_result, failed = drive(optimizer, problem, ledger, executor, bars, retry_failed=retry_failed)
    ego = loop_outcome(opt_result, optimizer, surrogate_for(config), problem)
    ei_history = [float(r.EI) if r.EI is not None else float("nan") for r in ego.history if r.phase != "initial"]

    model = getattr(optimizer, "spectra_model", None)
    model = model if isinstance(model, ProblemSpectraModel) else None   # identifiability from the Fisher information
    with make_progress(progress) as bars, single_blas_thread():   # minutes on measured data: shown phase by phase
        result = analyse(problem, ledger, ego, config, failed, retry_failed, executor, ProgressPhases(bars),
                         spectra_model=model)
    result.update({
        "run_id": run_id,
        "n_initial": int(ego.n_initial), "n_iterations": int(ego.n_iterations),
        "n_simulator_calls": int(ego.n_evaluations),
        "n_simulator_calls_this_session": int(ledger.count() - n_before),
        "stop_reason": ego.stop_reason, "n_refine_iterations": int(ego.n_refine),
        "refine_stop_reason": ego.refine_stop_reason, "wall_time_s": round(time.perf_counter() - t_start, 3),
        "design_min_distance": float(ego.design_min_distance) if np.isfinite(ego.design_min_distance) else None,
        "optimizer": config.optimizer.plugin, "budget": int(optimizer.budget),
        "anytime": {"J": [None if not np.isfinite(v) else float(v) for v in opt_result.y],
                    "w_normalized": problem.to_unit(opt_result.X).tolist() if len(opt_result.X) else []},
    })
    if model is not None:   # Jacobians: counted apart from the simulator calls
        # a plain simulation's wall time: the evaluations asked one at a time, after the design's batch
        walls = [ev.wall_time_s for ev in ledger.evaluations("ok") if ev.wall_time_s][int(ego.n_initial):]
        result["jacobian"] = model.summary(float(np.median(walls)) if walls else None)
    floor = problem.noise_model.floor_
    if floor is not None:
        result["noise_floor"] = {"mode": config.noise.floor if config.noise.path is None else "file",
                                 "channels": floor.summary(problem.freqs, problem.channels)}
    localisation = _localise(config, problem, result, executor, log)
    if localisation is not None:
        result["localisation"] = localisation
    add_verdict(result, problem, config)   # after every other finding (a localisation's groups included)
    write_json(run_dir / "result.json", result)
    with make_progress(progress) as bars:
        phases = ProgressPhases(bars)
        phases.start("figures and report")
        y_opt = cached_y_sim(problem, ledger, problem.to_unit(np.asarray(ego.x_opt, float)), executor=executor)
        write_report(run_dir, problem, ego, result, ei_history, executor, y_opt=y_opt)
        phases.done()
    if localisation is not None:   # a short section after the report (suspid.workflows.elements)
        report = run_dir / "report.md"
        text = report.read_text(encoding="utf-8") if report.exists() else ""
        write_text(report, text.rstrip("\n") + "\n\n" + localisation_markdown(localisation, result.get("units")))
    return IdentificationResult.from_dict(result, run_dir, problem, ego)


def loop_outcome(res: OptimizerResult, optimizer, surrogate, problem: Problem) -> LoopOutcome:
    """What the analysis reads of the finished loop: the EGO loop's own outcome (its surrogate), or for
    another optimiser its points with the configured ``surrogate`` fitted on them (identifiability,
    Sobol indices and intervals read it), with the optimiser's trials."""
    if isinstance(res.details, LoopOutcome):
        return res.details
    trials = getattr(getattr(optimizer, "book_", None), "trials", None) or \
        getattr(getattr(optimizer, "_trial_book", None), "trials", None) or []
    return LoopOutcome.of_points(res.x_opt, res.y_opt, res.X, res.y, problem.to_unit(res.X), res.n_initial,
                                 res.stop_reason, surrogate, problem.bounds, trials)


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


def add_verdict(result: dict[str, Any], problem: Problem, config: Config) -> None:
    """``result["nominal"]`` (SI, per identified parameter) and ``result["verdict"]``
    (:func:`suspid.workflows.verdict.verdict_block`): the maintenance verdict per parameter and localised group."""
    parameters = problem.simulator.parameters()
    rows = verdict_rows(result, parameters, config.limits)
    result["nominal"] = {r.name: r.nominal for r in rows if r.source == "identification"}
    result["verdict"] = verdict_block(rows, config.limits)
