"""Comparative studies: variants of one base config (paper Table 1 and Figure 2).

The ``study:`` section of a config lists the variants; each is the base
config with ``--set``-style overrides, run in its own directory
``<run dir>/variants/<variant>/`` with its own ledger (so a study resumes like
a run)::

    study:
      variants:
        - {name: likelihood, set: {objective.plugin: likelihood}}
        - {name: overlap,    set: {objective.plugin: overlap}}
      seeds: [1, 2, 3]     # optional: every variant once per seed

Variants that differ only by their objective share the seed, hence the same
initial design and the same noise paths, as in the paper ("starting with the
same initial experimental design"). With ``seeds``, ``compare: [a, b]`` adds a
paired test of two variants over the seeds, and ``checkpoints`` (default
``[100, 300]``) the numbers of simulator calls at which the worst identifiable
error is reported. Outputs (statistics in :mod:`suspid.workflows.study_stats`):

- ``study.csv``: one row per variant, mean, sd and 95 % t-interval over its
  seeds of the worst and mean identifiable error, simulator calls, coverage of
  w_ref, wall time and the error at each checkpoint;
- ``study_runs.csv``: one row per run (variant and seed);
- ``study.md``: those tables, the paired comparison, and the Table 1 analogue
  (every run);
- ``study_anytime.png``: error against simulator calls, per variant (mean and
  range over seeds); ``study_parameters.png``: the Figure 2 analogue.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from suspid.config import Config, loaded
from suspid.errors import DataError
from suspid.infra.files import atomic_open, write_json, write_text
from suspid.workflows.records import read_json
from suspid.workflows.identify import IdentificationResult, run
from suspid.sections import StudyOptions
from suspid.workflows.report import figure_parameters, markdown_table
from suspid.workflows.study_report import (RunStats, figure_anytime, run_stats, statistics_markdown, summaries,
                                           write_variants_csv)
from suspid.workflows.study_stats import anytime_errors


@dataclass
class StudyResult:
    """A finished study: its folder (``study.csv``, ``study.md``, ``study.json``, the figure) and every variant.

    ``study.json`` is its serialisation (:meth:`to_json`): ``label -> result.json`` of each run, each
    versioned by its own ``schema_version``.

    :ivar variants: label -> :class:`~suspid.workflows.identify.IdentificationResult`, in run order.
    """

    study_dir: Path
    variants: dict[str, IdentificationResult]

    def to_json(self) -> dict[str, Any]:
        """The content of ``study.json``: each run's result, by label, in run order."""
        return {label: r.to_json() for label, r in self.variants.items()}

    @classmethod
    def from_json(cls, data: Mapping[str, Any], study_dir: str | Path) -> "StudyResult":
        """The study of a ``study.json``'s content (each run's folder: ``variants/<label>/`` of ``study_dir``)."""
        study_dir = Path(study_dir)
        return cls(study_dir, {label: IdentificationResult.from_dict(r, study_dir / "variants" / label)
                               for label, r in data.items()})

    @classmethod
    def load(cls, study_dir: str | Path) -> "StudyResult":
        """Read a finished study's ``study.json``."""
        path = Path(study_dir) / "study.json"
        try:
            return cls.from_json(read_json(path), study_dir)
        except DataError as exc:
            raise DataError(str(exc) if str(path) in str(exc) else f"{path}: {exc}") from None


@dataclass
class StudyRun:
    """One run of a study: ``label`` (its folder under ``variants/``), its variant's name and seed, its config."""

    label: str
    variant: str
    seed: int | None
    config: Config


def study_variants(source: str | Path | Mapping[str, Any], overrides: Sequence[str],
                   config: Config) -> list[StudyRun]:
    """The configs of every variant (each validated), in order: ``config`` with the variant's keys set
    (:meth:`~suspid.config.Config.with_`).

    :param source: the config file (or mapping) ``config`` was loaded from (read only when ``config`` was
        not made by :func:`~suspid.config.load_config`).
    :param overrides: the ``--set`` overrides of the study itself.
    :raises ConfigError: the config has no ``study:`` section, or a variant's config is invalid.
    """
    if config.study is None:
        raise config.error("this config has no 'study:' section listing variants", "study")
    out = []
    base = loaded(source, overrides, config)
    base_dir = config.run_dir()
    for seed in config.study.seeds or [None]:
        for v in config.study.variants:
            label = v.name if seed is None else f"{v.name}-seed{seed}"
            extra = {"output.dir": str(base_dir / "variants" / label), "name": f"{config.name}-{label}"}
            if seed is not None:
                extra["seed"] = seed
            out.append(StudyRun(label, v.name, seed, base.with_(v.set, extra)))
    return out


def run_study(source: str | Path | Mapping[str, Any], overrides: Sequence[str], config: Config, *,
              fresh: bool = False, progress: bool = False, log: Callable[[str], None] = lambda s: None,
              report_only: bool = False) -> StudyResult:
    """Run every variant (resuming finished ones from their ledgers), then write the study outputs.

    :param config: the study's own config, loaded from ``source`` with ``overrides``.
    :param report_only: run nothing: write the outputs from the variants that have finished
        (their ``result.json``), e.g. while a long study is still running elsewhere or after it
        was interrupted; the others are left out and named in the log.
    :raises ConfigError: ``report_only`` and no variant has finished.
    """
    results: dict[str, IdentificationResult] = {}
    runs = study_variants(source, overrides, config)
    if report_only:
        missing = [r.label for r in runs if not (r.config.run_dir() / "result.json").is_file()]
        runs = [r for r in runs if r.label not in missing]
        if not runs:
            raise config.error("no variant of this study has finished yet (no result.json); nothing to report",
                               "study")
        if missing:
            log(f"left out, not finished: {', '.join(missing)}")
    for r in runs:
        log(f"variant {r.label}")
        results[r.label] = IdentificationResult.load(r.config.run_dir()) if report_only else \
            run(r.config, fresh=fresh, progress=progress, log=log)
    study_dir = config.run_dir()
    study_dir.mkdir(parents=True, exist_ok=True)
    # Every variant of a seed is measured on the same components: those identifiable in the run of the
    # study's first variant with that seed (an optimiser's own flags come from a metamodel fitted on
    # its own points, which differ from method to method).
    first = config.study.variants[0].name
    common = {r.seed: results[r.label].identifiable for r in runs if r.variant == first}
    stats = []
    for r in runs:
        result = results[r.label].to_dict()
        measured = {**result, "identifiable": common.get(r.seed, result["identifiable"])}
        curve = anytime_errors(r.config.run_dir() / "ledger.sqlite", measured) if "w_ref" in result else None
        stats.append(run_stats(r.label, r.variant, r.seed, measured, np.zeros(0) if curve is None else curve))
    write_study(study_dir, [(label, r.to_dict()) for label, r in results.items()], stats, config.study)
    return StudyResult(study_dir, results)


def write_study(study_dir: Path, rows: list[tuple[str, dict[str, Any]]], stats: list[RunStats],
                options: StudyOptions) -> None:
    """study.csv, study_runs.csv, study.md and the figures from the runs' results (``rows``, in run
    order) and their measures (``stats``, the same order)."""
    checkpoints = options.checkpoints
    write_variants_csv(study_dir / "study.csv", summaries(stats, checkpoints))
    if any(s.curve.size for s in stats):
        figure_anytime(study_dir / "study_anytime.png", stats)
    statistics = statistics_markdown(stats, checkpoints, options.compare, options.target_error)
    names = rows[0][1]["parameters"]
    has_ref = "w_ref" in rows[0][1]
    measures = ["worst_error", "mean_error", "coverage", *(f"error_at_{n}" for n in checkpoints)] if has_ref else []
    fields = ["run", "variant", "objective", "surrogate", "seed", "n_initial", "n_iterations", "n_simulator_calls",
              "J_max", "stop_reason", "wall_time_s", *measures]
    fields += [f"error_{n}" for n in names] if has_ref else []
    fields += [f"identifiable_{n}" for n in names] + [f"w_opt_{n}" for n in names]
    fields += ["paper_loop_n_iterations", "paper_loop_n_simulator_calls"]  # empty without ego.refine
    fields += [f"paper_loop_error_{n}" for n in names] if has_ref else []
    with atomic_open(study_dir / "study_runs.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        for (label, r), st in zip(rows, stats):
            row = {"run": label, **{m: st.metrics[m] for m in measures[:3]}, **st.at(checkpoints),
                   "variant": st.variant, **{k: r[k] for k in ("objective", "surrogate", "seed", "n_initial",
                                                          "n_iterations", "n_simulator_calls", "J_max",
                                                          "stop_reason", "wall_time_s")}}
            for n in names:
                if has_ref:
                    row[f"error_{n}"] = round(r["errors_percent"][n], 3)
                row[f"identifiable_{n}"] = r["identifiable"][n]
                row[f"w_opt_{n}"] = r["w_opt"][n]
            if "paper_loop" in r:
                p = r["paper_loop"]
                row.update(paper_loop_n_iterations=p["n_iterations"], paper_loop_n_simulator_calls=p["n_simulator_calls"])
                row.update({f"paper_loop_error_{n}": round(p["errors_percent"][n], 3) for n in names if has_ref})
            writer.writerow(row)
    header = ["variant", "iterations", "simulator calls"] + [f"{i + 1}: {n}" for i, n in enumerate(names)] \
        + ["wall time (s)"]
    table = []

    # trust under model error per run and component: True, False or None (not assessed)
    assessed = any(v is not None for _, r in rows for v in r.get("trustworthy", {}).values())

    def cells_of(r: dict[str, Any], values: dict[str, Any]) -> list[str]:
        cells = []
        for n in names:
            cell = f"{values['errors_percent'][n]:.2f}" if has_ref else f"{values['w_opt'][n]:.4g}"
            trust = r.get("trustworthy", {}).get(n)
            if not r["identifiable"][n]:
                cell = f"({cell}) n.i."
            elif trust is False:
                cell = f"({cell}) n.t."  # not trustworthy under model error: not a finding either
            elif trust is None and assessed:
                cell = f"{cell} n.a."  # trust not assessed in this run (its checks did not all run)
            cells.append(cell)
        return cells

    for label, r in rows:
        if "paper_loop" in r:  # the paper's loop alone, then with the local refinement
            p = r["paper_loop"]
            table.append([f"{label}: paper's loop", p["n_iterations"], p["n_simulator_calls"], *cells_of(r, p), ""])
            label = f"{label}: + refinement"
        table.append([label, r["n_iterations"], r["n_simulator_calls"], *cells_of(r, r), f"{r['wall_time_s']:.0f}"])
    trust_note = "" if assessed else ("No run assessed trust under model error (its checks did not run), "
                                      "so no cell carries `n.a.`: none is trustworthy or not.")
    what = "error in % of the admissible interval" if has_ref else "w_opt"
    refined = ""
    if any("paper_loop" in r for _, r in rows):
        refined = ("Variants with `ego.refine` show two rows: where the paper's EGO loop stopped (EI < eps), "
                   "and the same run after the local refinement (its iterations and calls include the loop's); "
                   "the identifiability flags are those of the final analysis.\n\n")
    text = (f"# Study\n\n{statistics}\n## Runs\n\nPer component: {what}; `n.i.` marks a component flagged "
            f"not identifiable, `n.t.` one not trustworthy under model error (its value is shown in brackets "
            f"and is not a finding), `n.a.` one whose trust under model error was not assessed (the checks that "
            f"would judge it did not all run). {trust_note}\n\n{refined}{markdown_table(header, table)}"
            f"\n\n![parameters](study_parameters.png)\n")
    write_text(study_dir / "study.md", text)
    variants = {label: np.array([r["w_opt_normalized"][n] for n in names]) for label, r in rows}
    intervals = {label: np.array([r["interval_normalized"][n] for n in names]) for label, r in rows}
    w_ref = np.array([rows[0][1]["w_ref_normalized"][n] for n in names]) if has_ref else None
    figure_parameters(study_dir / "study_parameters.png", names, variants, w_ref, intervals)
    write_json(study_dir / "study.json", {label: r for label, r in rows})
