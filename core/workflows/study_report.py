"""The statistics outputs of ``suspid study``: ``study.csv`` (per variant, over seeds), ``study_runs.csv``
columns, the markdown sections and the anytime figure (measures in :mod:`suspid.workflows.study_stats`)."""

from __future__ import annotations

import csv
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from suspid.infra.files import atomic_open, pyplot, save_figure
from suspid.workflows.report import markdown_table
from suspid.workflows.study_stats import Summary, calls_to_reach, error_at, paired_test, run_metrics, summarize

METRICS = {"worst_error": ("worst identifiable error (%)", 2), "mean_error": ("mean identifiable error (%)", 2),
           "n_simulator_calls": ("simulator calls", 1), "coverage": ("coverage of w_ref", 2),
           "wall_time_s": ("wall time (s)", 1)}
"""The measures summarised over seeds: column title and decimals shown in study.md."""


@dataclass
class RunStats:
    """One run of a study: its variant, seed, measures and anytime curve (empty without w_ref)."""

    label: str
    variant: str
    seed: int | None
    metrics: dict[str, float]
    curve: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def at(self, checkpoints: list[int]) -> dict[str, float]:
        """``error_at_<N>`` for every checkpoint N (only with an anytime curve)."""
        return {f"error_at_{n}": error_at(self.curve, n) for n in checkpoints} if self.curve.size else {}


def run_stats(label: str, variant: str, seed: int | None, result: dict[str, Any], curve: np.ndarray) -> RunStats:
    """:class:`RunStats` of a run's ``result.json`` and its anytime curve."""
    return RunStats(label, variant, seed, run_metrics(result), curve)


def by_variant(runs: list[RunStats]) -> dict[str, list[RunStats]]:
    """The runs grouped by variant name, in first-seen order."""
    out: dict[str, list[RunStats]] = {}
    for r in runs:
        out.setdefault(r.variant, []).append(r)
    return out


def summaries(runs: list[RunStats], checkpoints: list[int]) -> dict[str, dict[str, Summary]]:
    """variant -> measure (``METRICS`` and ``error_at_<N>``) -> :class:`Summary` over its seeds."""
    out = {}
    for variant, group in by_variant(runs).items():
        values = [{**r.metrics, **r.at(checkpoints)} for r in group]
        keys = [k for k in [*METRICS, *(f"error_at_{n}" for n in checkpoints)] if k in values[0]]
        out[variant] = {k: summarize([v[k] for v in values]) for k in keys}
    return out


def write_variants_csv(path: Path, table: dict[str, dict[str, Summary]]) -> None:
    """``study.csv``: one row per variant, ``n_seeds`` and ``<measure>_{mean,sd,ci_low,ci_high}``."""
    keys = list(next(iter(table.values())))
    fields = ["variant", "n_seeds"] + [f"{k}_{s}" for k in keys for s in ("mean", "sd", "ci_low", "ci_high")]
    with atomic_open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        for variant, summary in table.items():
            row: dict[str, Any] = {"variant": variant, "n_seeds": max(s.n for s in summary.values())}
            for k, s in summary.items():
                row.update({f"{k}_mean": s.mean, f"{k}_sd": s.sd, f"{k}_ci_low": s.low, f"{k}_ci_high": s.high})
            writer.writerow(row)


def _cell(s: Summary, digits: int, interval: bool = True) -> str:
    """``mean ± sd [low, high]`` (the parts that are defined), ``–`` without values."""
    if s.n == 0:
        return "–"
    text = f"{s.mean:.{digits}f}"
    if s.n > 1:
        text += f" ± {s.sd:.{digits}f}"
        if interval:
            text += f" [{s.low:.{digits}f}, {s.high:.{digits}f}]"
    return text


def statistics_markdown(runs: list[RunStats], checkpoints: list[int], compare: list[str] | None,
                        target: float = 2.0) -> str:
    """The markdown sections: measures over seeds, errors at the checkpoints, the simulator calls to
    reach ``target`` %, the paired comparison."""
    table = summaries(runs, checkpoints)
    keys = [k for k in METRICS if k in next(iter(table.values()))]
    rows = [[v, max(s.n for s in summary.values()), *(_cell(summary[k], METRICS[k][1]) for k in keys)]
            for v, summary in table.items()]
    text = ("## Over seeds\n\nPer variant: mean ± standard deviation [95 % t-interval] over its seeds. "
            "Errors in % of the admissible interval, over the identifiable components; coverage: the "
            "fraction of them whose interval contains w_ref.\n\n"
            + markdown_table(["variant", "seeds", *(METRICS[k][0] for k in keys)], rows) + "\n")
    has_curves = any(r.curve.size for r in runs)
    if has_curves:
        header = ["variant", *(f"N = {n}" for n in checkpoints)]
        rows = [[v, *(_cell(summary[f"error_at_{n}"], 2, interval=False) for n in checkpoints)]
                for v, summary in table.items()]
        text += ("\n## Worst identifiable error at N simulator calls\n\nThe error of the best-J point "
                 "among the first N evaluations, mean ± sd over seeds (a run that stopped before N keeps "
                 "its last value).\n\n" + markdown_table(header, rows)
                 + "\n\n![error against simulator calls](study_anytime.png)\n")
        text += "\n" + reach_markdown(runs, target) + "\n"
    if compare is not None:
        text += "\n" + paired_markdown(runs, *compare) + "\n"
    return text


def reach_markdown(runs: list[RunStats], target: float) -> str:
    """Per variant: how many seeds reach a worst identifiable error <= ``target`` % and after how many calls."""
    rows = []
    for variant, group in by_variant(runs).items():
        calls = [calls_to_reach(r.curve, target) for r in group if r.curve.size]
        reached = [c for c in calls if np.isfinite(c)]
        rows.append([variant, f"{len(reached)} of {len(calls)}",
                     _cell(summarize(reached), 1, interval=False), ", ".join(
                         f"{c:.0f}" if np.isfinite(c) else "never" for c in calls)])
    return (f"## Simulator calls to reach a worst identifiable error <= {target:g} %\n\nThe first N after "
            f"which the best-J point is within {target:g} % on every identifiable component; mean ± sd over "
            "the seeds that reach it (a seed that never does is counted apart).\n\n"
            + markdown_table(["variant", "seeds that reach it", "calls (mean ± sd)", "per seed"], rows))


def paired_markdown(runs: list[RunStats], a: str, b: str) -> str:
    """The paired comparison of the worst identifiable error of variants ``a`` and ``b`` on their common seeds."""
    groups = by_variant(runs)
    va = {r.seed: r.metrics.get("worst_error", math.nan) for r in groups.get(a, [])}
    vb = {r.seed: r.metrics.get("worst_error", math.nan) for r in groups.get(b, [])}
    seeds = [s for s in va if s in vb]
    title = f"## Paired comparison: {a} against {b}\n\n"
    if not any(r.metrics.get("worst_error") is not None for r in runs):
        return title + "Not available: the worst identifiable error needs w_ref (the numerical experiment).\n"
    t = paired_test([va[s] for s in seeds], [vb[s] for s in seeds])
    name = "Wilcoxon signed-rank test" if t.test == "wilcoxon" else "Exact sign test"
    return (title + f"Worst identifiable error on the same seeds ({t.n_pairs} pairs with both errors defined): "
            f"{a} lower on {t.n_a_lower}, {b} lower on {t.n_b_lower}; difference {a} − {b}: mean "
            f"{t.mean_difference:.3f} %, median {t.median_difference:.3f} %. {name} (two-sided): "
            f"p = {t.p_value:.3g}.\n")


def figure_anytime(path: Path, runs: list[RunStats]) -> Path:
    """Worst identifiable error of the best-J point against simulator calls: per variant, the mean
    over seeds (a line) and their range (a band); a run that stopped keeps its last value."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4.2))
    plotted: list[np.ndarray] = []
    for variant, group in by_variant(runs).items():
        curves = [r.curve for r in group if r.curve.size]
        if not curves:
            continue
        n = max(c.size for c in curves)
        padded = np.array([np.concatenate([c, np.full(n - c.size, c[-1])]) for c in curves])
        calls = np.arange(1, n + 1)
        with warnings.catch_warnings():  # calls where no seed has an error yet (no identifiable component) are NaN
            warnings.simplefilter("ignore", RuntimeWarning)
            mean, low, high = (np.nanmean(padded, axis=0), np.nanmin(padded, axis=0), np.nanmax(padded, axis=0))
        line, = ax.plot(calls, mean, label=f"{variant} ({len(curves)} seeds)")
        ax.fill_between(calls, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
        plotted += [low, high]
    values = np.concatenate(plotted) if plotted else np.zeros(0)
    values = values[np.isfinite(values) & (values > 0)]
    if values.size:   # a log axis needs positive values; its limits set here, not from NaN-padded data
        ax.set_yscale("log")
        ax.set_ylim(values.min() / 1.5, values.max() * 1.5)
    else:
        ax.text(0.5, 0.5, "no identifiable component with a defined error in any run", ha="center",
                va="center", transform=ax.transAxes, fontsize=9)
    ax.set_xlabel("simulator calls")
    ax.set_ylabel("worst identifiable error (%)")
    ax.set_title("best-J point so far: mean over seeds, band from min to max", fontsize=9)
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return save_figure(fig, path)
