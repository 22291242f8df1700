"""Statistics over seeds in `suspid study`: measures, anytime curves, summaries and the paired test."""

from __future__ import annotations

import csv
import json
import math
import statistics

import numpy as np
import pytest
import yaml
from scipy import stats

import suspid
from suspid.errors import ConfigError
from suspid.infra.ledger import Ledger
from suspid.workflows.study_stats import anytime_errors, calls_to_reach, error_at, paired_test, summarize
from conftest import run_cli
from test_study import STUDY

BASE = yaml.safe_load(STUDY.split("study:")[0])


# -- unit tests ---------------------------------------------------------------------------------
def test_summary_of_known_numbers():
    s = summarize([1.0, 2.0, 3.0, 4.0, math.nan])  # NaN (no identifiable component) is left out
    assert s.n == 4 and s.mean == 2.5 and s.sd == pytest.approx(math.sqrt(5 / 3), rel=1e-12)
    half = 3.182446305284263 * math.sqrt(5 / 3) / 2  # t_{0.975, 3}
    assert (s.low, s.high) == pytest.approx((2.5 - half, 2.5 + half), rel=1e-12)
    one = summarize([7.0])
    assert one.mean == 7.0 and math.isnan(one.sd) and math.isnan(one.low)
    assert summarize([]).n == 0


def test_paired_test_known_cases():
    wil = paired_test([2, 3, 4, 5, 6, 7, 8, 9], [1] * 8)  # 8 positive differences
    assert wil.test == "wilcoxon" and wil.p_value == pytest.approx(2 / 2 ** 8, rel=1e-12)
    assert (wil.n_a_lower, wil.n_b_lower, wil.mean_difference) == (0, 8, 4.5)
    sign = paired_test([1.0, 2.0, 3.0, 0.5, math.nan], [0.0, 0.0, 0.0, 1.0, 2.0])  # 3 up, 1 down; NaN pair out
    assert sign.test == "sign" and sign.n_pairs == 4 and sign.p_value == pytest.approx(2 * 5 / 16, rel=1e-12)
    same = paired_test([1.0, 2.0], [1.0, 2.0])
    assert same.test == "sign" and same.p_value == 1.0 and same.median_difference == 0.0


def test_anytime_curve_follows_the_best_j_in_evaluation_order(tmp_path):
    ledger = Ledger(tmp_path / "ledger.sqlite")
    result = {"parameters": ["a", "b"], "identifiable": {"a": True, "b": False}, "w_ref": {"a": 5.0, "b": 0.0},
              "bounds": {"a": [0.0, 10.0], "b": [0.0, 1.0]}, "n_simulator_calls": 5}
    ledger.put_iteration("design", 0, {"w": {"a": 1.0, "b": 0.9}, "J": -3.0})  # error 40 %
    ledger.put_iteration("design", 1, {"w": {"a": 7.0, "b": 0.1}, "J": -2.0})  # 20 %
    ledger.put_iteration("refine", 4, {"w": {"a": 5.5, "b": 0.5}, "J": -0.5})  # 5 %, the last point
    ledger.put_iteration("ego", 2, {"w": {"a": 2.0, "b": 0.0}, "J": -2.5})     # worse J: the best stays
    ledger.put_iteration("ego", 3, {"w": {"a": 4.0, "b": 0.0}, "J": -1.0})     # 10 %
    ledger.close()
    curve = anytime_errors(tmp_path / "ledger.sqlite", result)
    np.testing.assert_allclose(curve, [40.0, 20.0, 20.0, 10.0, 5.0])
    assert error_at(curve, 3) == 20.0 and error_at(curve, 300) == 5.0


def test_compare_must_name_two_variants_of_the_study():
    study = {"variants": [{"name": "a"}, {"name": "b"}], "seeds": [1, 2], "compare": ["a", "c"]}
    with pytest.raises(ConfigError, match="study.*unknown variant.*c"):
        suspid.load_config({**BASE, "study": study})
    with pytest.raises(ConfigError, match="checkpoints"):
        suspid.load_config({**BASE, "study": {**study, "compare": ["a", "b"], "checkpoints": [0]}})


# -- end to end ---------------------------------------------------------------------------------
def expected_measures(result: dict) -> dict[str, float]:
    """The per-run measures, recomputed from result.json with its own errors_percent."""
    ident = [n for n in result["parameters"] if result["identifiable"][n]]
    errors = [result["errors_percent"][n] for n in ident]
    inside = [result["interval"][n][0] <= result["w_ref"][n] <= result["interval"][n][1] for n in ident]
    return {"worst_error": max(errors) if errors else math.nan,
            "mean_error": statistics.mean(errors) if errors else math.nan,
            "coverage": statistics.mean(inside) if inside else math.nan,
            "n_simulator_calls": result["n_simulator_calls"], "wall_time_s": result["wall_time_s"]}


def test_two_variants_two_seeds_study_aggregates_the_runs(tmp_path):
    study = {"variants": [{"name": "likelihood", "set": {"objective.plugin": "likelihood"}},
                          {"name": "mean-spectrum", "set": {"objective.plugin": "mean-spectrum"}}],
             "seeds": [1, 2], "compare": ["likelihood", "mean-spectrum"], "checkpoints": [7, 1000]}
    # 12 segments: with 6, the likelihood finds no identifiable component and every error is undefined
    data = {**BASE["data"], "track": {**BASE["data"]["track"], "n_segments": 12}}
    config = {**BASE, "data": data, "ego": {"max_iter": 2}, "output": {"dir": str(tmp_path / "runs")}, "study": study}
    out = suspid.study(config).study_dir

    results = {(v, s): json.loads((out / "variants" / f"{v}-seed{s}" / "result.json").read_text())
               for v in ("likelihood", "mean-spectrum") for s in (1, 2)}
    for (v, s), result in results.items():  # every run is measured on the first variant's identifiable components
        result["identifiable"] = dict(results["likelihood", s]["identifiable"])
    table = {r["variant"]: r for r in csv.DictReader(open(out / "study.csv"))}
    assert list(table) == ["likelihood", "mean-spectrum"]
    runs = list(csv.DictReader(open(out / "study_runs.csv")))
    assert [(r["variant"], r["seed"]) for r in runs] == [("likelihood", "1"), ("mean-spectrum", "1"),
                                                         ("likelihood", "2"), ("mean-spectrum", "2")]
    for variant, row in table.items():
        per_run = [expected_measures(results[variant, s]) for s in (1, 2)]
        assert row["n_seeds"] == "2"
        for key in ("worst_error", "mean_error", "coverage", "n_simulator_calls", "wall_time_s"):
            values = [m[key] for m in per_run]
            mean, sd = statistics.mean(values), statistics.stdev(values)
            half = stats.t.ppf(0.975, 1) * sd / math.sqrt(2)
            got = [float(row[f"{key}_{s}"]) for s in ("mean", "sd", "ci_low", "ci_high")]
            assert got == pytest.approx([mean, sd, mean - half, mean + half], rel=1e-9, abs=1e-9), key
    reach: dict[str, list[float]] = {}
    for r in runs:
        result = results[r["variant"], int(r["seed"])]
        assert float(r["worst_error"]) == pytest.approx(expected_measures(result)["worst_error"], rel=1e-9)
        # the anytime curve has one value per call and ends at w_opt, the best-J point the run reports
        curve = anytime_errors(out / "variants" / r["run"] / "ledger.sqlite", result)
        assert curve.size == result["n_simulator_calls"] == 8
        assert float(r["error_at_1000"]) == pytest.approx(float(r["worst_error"]), rel=1e-9)
        assert float(r["error_at_7"]) == pytest.approx(curve[6], rel=1e-12)
        # and it is the curve of the run's own record of every evaluation, in order (result.json "anytime")
        names, best, expected = result["parameters"], -math.inf, []
        for J, u in zip(result["anytime"]["J"], result["anytime"]["w_normalized"]):
            if J is not None and J > best:
                best, worst = J, max(100 * abs(u[i] - result["w_ref_normalized"][n])
                                     for i, n in enumerate(names) if result["identifiable"][n])
            expected.append(worst)
        assert curve == pytest.approx(expected, rel=1e-9, abs=1e-9)
        reach.setdefault(r["variant"], []).append(calls_to_reach(curve, 2.0))
    text = (out / "study.md").read_text()
    assert "## Over seeds" in text and "## Worst identifiable error at N simulator calls" in text
    assert "## Paired comparison: likelihood against mean-spectrum" in text
    d = [expected_measures(results["likelihood", s])["worst_error"]
         - expected_measures(results["mean-spectrum", s])["worst_error"] for s in (1, 2)]
    n_up, n_down = sum(x > 0 for x in d), sum(x < 0 for x in d)  # 2 pairs: always the sign test
    p = stats.binomtest(n_up, n_up + n_down).pvalue if n_up + n_down else 1.0
    assert f"likelihood lower on {n_down}, mean-spectrum lower on {n_up}" in text
    assert f"Exact sign test (two-sided): p = {p:.3g}." in text
    assert "| N = 7 | N = 1000 |" in text and (out / "study_anytime.png").stat().st_size > 0
    assert "## Simulator calls to reach a worst identifiable error <= 2 %" in text
    # --report-only: the same outputs from the finished runs, without running anything
    before = {name: (out / name).read_text() for name in ("study.csv", "study_runs.csv")}
    (out / "study.csv").unlink()
    again = suspid.study(config, report_only=True)
    assert {name: (out / name).read_text() for name in before} == before
    assert again.variants["likelihood-seed1"].J_max == pytest.approx(results["likelihood", 1]["J_max"])
    for variant, calls in reach.items():
        per_seed = ", ".join(f"{c:.0f}" if math.isfinite(c) else "never" for c in calls)
        n = sum(math.isfinite(c) for c in calls)
        assert f"| {variant} | {n} of 2 |" in text and f"| {per_seed} |" in text


def test_calls_to_reach_a_target():
    curve = np.array([9.0, 5.0, 2.5, 2.0, 1.0, 1.0])
    assert calls_to_reach(curve, 2.0) == 4 and calls_to_reach(curve, 5.0) == 2
    assert math.isnan(calls_to_reach(curve, 0.5)) and math.isnan(calls_to_reach(np.zeros(0), 1.0))


def test_a_bad_compare_is_one_line_naming_the_key(tmp_path):
    cfg = tmp_path / "study.yaml"
    cfg.write_text(STUDY + "  compare: [likelihood, overlapp]\n")
    res = run_cli("validate", str(cfg))
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert "key 'study.compare'" in res.stderr and "unknown variant(s) overlapp" in res.stderr


def test_anytime_figure_with_no_defined_error(tmp_path):
    """Runs whose components are all not identifiable have an all-NaN anytime curve: the figure is still
    written (linear axis, a note), and a curve with errors gets a log axis spanning them."""
    from suspid.workflows.study_report import RunStats, figure_anytime

    nan = RunStats("a-seed1", "a", 1, {}, np.full(5, np.nan))
    assert figure_anytime(tmp_path / "none.png", [nan]).stat().st_size > 0
    some = RunStats("b-seed1", "b", 1, {}, np.array([np.nan, 8.0, 2.0, 0.5]))
    assert figure_anytime(tmp_path / "some.png", [nan, some]).stat().st_size > 0
