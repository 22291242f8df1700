"""Statistics over seeds for ``suspid study``: per-run measures, anytime curves, summaries, a paired test.

Per run (one variant at one seed), from its ``result.json`` (numerical
experiment, w_ref known):

- the **worst** and the **mean identifiable error**: max and mean over the
  components flagged identifiable of |w_opt - w_ref| in % of the admissible
  interval (NaN when no component is identifiable);
- the **coverage**: the fraction of identifiable components whose interval
  contains w_ref;
- the number of **simulator calls** and the **wall time** (s).

The **anytime curve** of a run: for n = 1, 2, ... simulator calls, the worst
identifiable error of the point with the best J among the first n evaluations,
read in order from the run ledger (the design first, then every other loop's
iterations by their index). The identifiable components are those of the
final analysis. The **error at N calls** is the curve at N; a run that stopped
before N calls keeps its last value (it would spend no more).

Over the seeds of a variant, :func:`summarize` gives the mean, the standard
deviation (ddof = 1) and the 95 % t-interval mean ± t_{0.975, n-1} sd/√n.
:func:`paired_test` compares two variants on the same seeds: the Wilcoxon
signed-rank test (``scipy.stats.wilcoxon``), or the exact sign test when
fewer than :data:`MIN_WILCOXON` differences are non-zero (with five or fewer
pairs no two-sided Wilcoxon p-value can fall below 0.06).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from scipy import stats

from suspid.infra.ledger import Ledger

MIN_WILCOXON = 6
"""Fewest non-zero paired differences for the Wilcoxon test; below it the exact sign test is used."""


@dataclass(frozen=True)
class Summary:
    """Mean, standard deviation (ddof = 1) and 95 % t-interval of ``n`` finite values (NaN where undefined)."""

    n: int
    mean: float
    sd: float
    low: float
    high: float


def summarize(values: Sequence[float]) -> Summary:
    """:class:`Summary` of the finite ``values`` (NaN are left out); sd and interval need n >= 2."""
    x = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    n = x.size
    if n == 0:
        return Summary(0, math.nan, math.nan, math.nan, math.nan)
    mean = float(x.mean())
    if n == 1:
        return Summary(1, mean, math.nan, math.nan, math.nan)
    sd = float(x.std(ddof=1))
    half = float(stats.t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return Summary(n, mean, sd, mean - half, mean + half)


def _errors(w: Mapping[str, float], result: Mapping[str, Any]) -> np.ndarray:
    """Errors in % of the admissible interval of the identifiable components of ``w``."""
    names = [n for n in result["parameters"] if result["identifiable"][n]]
    return np.array([100.0 * abs(w[n] - result["w_ref"][n]) / (result["bounds"][n][1] - result["bounds"][n][0])
                     for n in names])


def _worst(errors: np.ndarray) -> float:
    return float(errors.max()) if errors.size else math.nan


def run_metrics(result: Mapping[str, Any]) -> dict[str, float]:
    """``worst_error``, ``mean_error`` (%), ``coverage`` (fraction), ``n_simulator_calls``, ``wall_time_s``
    of one run's ``result.json``; the first three only when w_ref is known."""
    out = {"n_simulator_calls": float(result["n_simulator_calls"]), "wall_time_s": float(result["wall_time_s"])}
    if "w_ref" not in result:
        return out
    errors = _errors(result["w_opt"], result)
    names = [n for n in result["parameters"] if result["identifiable"][n]]
    inside = [result["interval"][n][0] <= result["w_ref"][n] <= result["interval"][n][1] for n in names]
    out.update(worst_error=_worst(errors), mean_error=float(errors.mean()) if errors.size else math.nan,
               coverage=float(np.mean(inside)) if inside else math.nan)
    return out


def evaluations_in_order(ledger_path: str | Path) -> list[dict[str, Any]]:
    """The run's evaluations ``{"w": {name: SI}, "J": float}`` in the order they were made.

    The ledger's trials (:meth:`~suspid.infra.ledger.Ledger.trials`, every optimiser's points
    by id), or in a ledger written before optimisers recorded them: the design's iterations
    first, then those of every other loop (``ego``, ``refine``, ...) merged by their index,
    which counts the points of the run.
    """
    ledger = Ledger(ledger_path)
    try:
        rows = ledger.all_iterations()
        trials = ledger.trials() if any(run == "trials" for run, _, _ in rows) else []
    finally:
        ledger.close()
    if trials:
        return [r for r in trials if r.get("J") is not None and r.get("w") is not None]
    design = [r for run, _, r in rows if run == "design"]
    later = [r for _, _, r in sorted((row for row in rows if row[0] != "design"), key=lambda row: row[1])]
    ordered = design + later
    return [r for r in ordered if r.get("J") is not None and r.get("w") is not None]


def anytime_errors(ledger_path: str | Path, result: Mapping[str, Any]) -> np.ndarray:
    """``(n_evaluations,)`` %: the worst identifiable error of the best-J point after each evaluation."""
    best_J, best_err, out = -math.inf, math.nan, []
    for r in evaluations_in_order(ledger_path):
        if r["J"] > best_J:
            best_J, best_err = r["J"], _worst(_errors(r["w"], result))
        out.append(best_err)
    return np.array(out[:int(result["n_simulator_calls"])], dtype=float)  # not a longer earlier run's


def error_at(curve: np.ndarray, n_calls: int) -> float:
    """The anytime curve after ``n_calls`` calls; its last value for a run that stopped earlier."""
    if curve.size == 0:
        return math.nan
    return float(curve[min(n_calls, curve.size) - 1])


def calls_to_reach(curve: np.ndarray, target: float) -> float:
    """The number of simulator calls after which the anytime curve is first ``<= target`` (%), NaN if never."""
    reached = np.flatnonzero(curve <= target)
    return float(reached[0] + 1) if reached.size else math.nan


@dataclass(frozen=True)
class PairedTest:
    """A paired comparison of ``a`` and ``b`` (same seeds): differences d = a - b.

    :ivar test: ``"wilcoxon"`` or ``"sign"``.
    :ivar n_pairs: pairs with both values finite; ``n_a_lower``/``n_b_lower``: pairs where each is lower.
    """

    test: str
    n_pairs: int
    n_a_lower: int
    n_b_lower: int
    mean_difference: float
    median_difference: float
    p_value: float


def paired_test(a: Sequence[float], b: Sequence[float]) -> PairedTest:
    """Two-sided paired test of ``a`` against ``b`` (equal lengths, pairs with a NaN left out).

    Wilcoxon signed-rank (zero differences dropped) with at least :data:`MIN_WILCOXON`
    non-zero differences, else the exact sign test (binomial, p = 1 when every difference is 0).
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    keep = np.isfinite(a) & np.isfinite(b)
    d = a[keep] - b[keep]
    n_neg, n_pos = int(np.sum(d < 0)), int(np.sum(d > 0))
    mean = float(d.mean()) if d.size else math.nan
    median = float(np.median(d)) if d.size else math.nan
    if n_neg + n_pos >= MIN_WILCOXON:
        p = float(stats.wilcoxon(d, zero_method="wilcox").pvalue)
        return PairedTest("wilcoxon", int(d.size), n_neg, n_pos, mean, median, p)
    p = float(stats.binomtest(n_pos, n_neg + n_pos, 0.5).pvalue) if n_neg + n_pos else 1.0
    return PairedTest("sign", int(d.size), n_neg, n_pos, mean, median, p)
