"""The test of "nothing changed" (w = w0) on the measurement date, and the intervals it widens.

Known answers: the bias-aware interval reaching a given point (closed form at its limits), and on the numerical
experiment a measurement date whose suspension differs from w0 by 20-30 % of its nominal values, where J at the
truth is far above J at w0 (rejected), against an estimate at w0 itself (ΔJ = 0: never rejected).
"""

from __future__ import annotations

import numpy as np
import pytest

from suspid.config import load_config
from suspid.infra.ledger import Ledger
from suspid.method.identifiability import bias_aware_half_width
from suspid.workflows.analysis import cached_y_sim, no_change_check
from suspid.workflows.no_change import NoChange, apply_no_change, no_change_test, reach_bound
from suspid.workflows.problem import build_problem

W_REF = {"k_sec_z": 280.0e3, "c_sec_z": 14.0e3, "k_prim_z": 1.28e6, "c_sec_y": 21.0e3, "c_yaw": 210.0e3}
"""The quickstart's damaged suspension (-20 to -30 % of nominal but k_prim_z +7 %)."""


def test_reach_bound_makes_the_interval_hold_the_point():
    sd = np.array([0.02, 0.02, 0.0, 0.03])
    bound = np.array([0.01, 0.0, 0.02, 0.0])
    distance = np.array([0.10, -0.01, 0.05, 0.0])
    new = reach_bound(sd, bound, distance, 2.0)
    half = bias_aware_half_width(sd, new, 2.0)
    assert half[0] == pytest.approx(0.10, rel=1e-6) and new[0] > bound[0]      # widened just to the point
    assert new[1] == bound[1] and new[3] == bound[3]   # already held (2 sigma = 4 % > 1 %; the estimate itself)
    assert new[2] == pytest.approx(0.05)               # no sampling spread: the bound is the distance
    assert np.all(half >= np.abs(distance) - 1e-9)


def test_apply_no_change_only_where_w0_is_not_rejected():
    names = ["a", "b"]
    sd, bound, distance = np.array([0.01, 0.01]), np.array([0.0, 0.0]), np.array([0.12, 0.01])
    rejected = NoChange(delta_j=1.0, sd=0.1, rejected=True, n_redraws=32, n_sigmas=2.0)
    reasons: dict[str, list[str]] = {}
    assert apply_no_change(rejected, names, sd, bound, distance, 2.0, 0.08, reasons) is bound and not reasons
    kept = NoChange(delta_j=0.1, sd=0.1, rejected=False, n_redraws=32, n_sigmas=2.0)
    new = apply_no_change(kept, names, sd, bound, distance, 2.0, 0.08, reasons)
    assert bias_aware_half_width(sd, new, 2.0)[0] == pytest.approx(0.12, rel=1e-6)
    assert list(reasons) == ["a"] and "do not tell it from its value at the reference date" in reasons["a"][0]
    assert "is 1.0 bootstrap standard deviations below J(w_opt)" in reasons["a"][0]
    # J higher at the null than at w_opt (the search's maximum is not the highest point): said as such
    above: dict[str, list[str]] = {}
    apply_no_change(NoChange(delta_j=-0.02, sd=0.1, rejected=False, n_redraws=32, n_sigmas=2.0), names, sd, bound,
                    distance, 2.0, 0.08, above)
    assert "is 0.2 bootstrap standard deviations above J(w_opt)" in above["a"][0]


@pytest.fixture(scope="module")
def damaged(tmp_path_factory):
    """The numerical experiment (16 segments, frequency solver) with the quickstart's damaged suspension."""
    tmp = tmp_path_factory.mktemp("no_change")
    config = load_config({
        "name": "no-change", "seed": 7,
        "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 100.0}},
        "parameters": {n: {} for n in W_REF},
        "data": {"source": "experiment", "w_ref": W_REF,
                 "track": {"n_segments": 16, "length_m": 1000.0, "speed_kmh": 300.0}},
        "spectra": {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 200},
        "identifiability": {"n_redraws": 16, "model_error": {"run": "always"}}})
    ledger = Ledger(tmp / "ledger.sqlite")
    return build_problem(config, ledger), ledger


def test_a_damaged_date_rejects_w0_and_w0_never_rejects_itself(damaged):
    problem, ledger = damaged
    names = problem.names
    u_ref = problem.to_unit(np.array([W_REF[n] for n in names]))
    u0 = problem.to_unit(np.array([problem.w0[n] for n in names]))
    opts = problem.config.identifiability.model_error
    test, report = no_change_check(problem, ledger, u_ref, opts, False, None)
    assert report["status"] == "done" and report["n_simulations"] == 1     # the simulation at w0
    assert test.rejected and test.delta_j > 0 and test.z > 2, report
    again, report = no_change_check(problem, ledger, u_ref, opts, False, None)
    assert report["n_simulations"] == 0 and again.delta_j == test.delta_j    # cached; the same draws
    y0 = cached_y_sim(problem, ledger, u0)
    itself = no_change_test(problem, y0, y0, 16, 2.0)
    assert itself.delta_j == 0.0 and not itself.rejected
    off = opts.model_copy(update={"no_change": False})
    assert no_change_check(problem, ledger, u_ref, off, False, None)[0] is None


def test_report_names_the_linearised_checks_and_reads_an_older_calibration():
    from suspid.workflows.linearised import calibration_markdown, calibration_result
    from suspid.workflows.report import checks_lines
    from suspid.workflows.trust import checks_report

    checks = checks_report({"self_check": "done", "adequacy": "done", "groups": "done", "nuisance": "done",
                            "no_change": "done"})
    lines = checks_lines({"model_error": {"method": "linearised", "checks": checks}})
    assert "self-check on the spectra linearised at w0" in lines[0] and "no-change test at w0" in lines[0]
    assert "reference-date self-check, adequacy" in checks_lines({"model_error": {"method": "full",
                                                                                  "checks": checks}})[0]
    cal = {"status": "done", "method": "m", "n_iterations": 1, "n_clusters": 4, "residual_rms_db": 0.1,
           "source": "s", "max_sd_fraction": 0.1, "n_sigmas": 2.0,
           "parameters": {"k_yaw_s": {"nominal": 1e7, "assumed_range": [5e6, 2e7], "value": 9e6,
                                      "interval": [8e6, 1e7], "status": "calibrated"}}}
    report = {"calibration": dict(cal)}
    assert calibration_result(report) == cal and "calibration" not in report   # carried once, at the top level
    old = {"model_error": {"calibration": cal}}                                  # a result.json written before
    assert "| k_yaw_s |" in calibration_markdown(old) == calibration_markdown({"calibration": cal})


def test_the_corrected_null_is_where_w_opt_lies_when_nothing_changed(damaged):
    """Where the checks correct w_opt (a model-form bias of known sign), nothing changed means w_opt at w0 less the
    correction, not at w0: the test against that point. Known answers on the numerical experiment: w_opt halfway
    to the damaged suspension, rejected against w0; with the correction that maps it onto w0 exactly, its null is
    w_opt itself (ΔJ = 0, not rejected); with half that correction still rejected; without one, the plain test."""
    problem, ledger = damaged
    names = problem.names
    u0 = problem.to_unit(np.array([problem.w0[n] for n in names]))
    u_opt = u0 + 0.5 * (problem.to_unit(np.array([W_REF[n] for n in names])) - u0)
    opts = problem.config.identifiability.model_error
    plain, _ = no_change_check(problem, ledger, u_opt, opts, False, None)       # simulates w0 and w_opt
    assert plain.rejected
    exact, report = no_change_check(problem, ledger, u_opt, opts, False, None, u0 - u_opt)
    assert exact.delta_j == 0.0 and exact.z == 0.0 and not exact.rejected
    assert report["n_simulations"] == 0 and report["against_w0"]["z"] == pytest.approx(plain.z)   # both cached
    half, report = no_change_check(problem, ledger, u_opt, opts, False, None, 0.5 * (u0 - u_opt))
    assert half.rejected and report["n_simulations"] == 1                          # the new null simulated
    none, report = no_change_check(problem, ledger, u_opt, opts, False, None, None)
    assert none.delta_j == plain.delta_j and "against_w0" not in report
    off = opts.model_copy(update={"no_change": False})
    assert no_change_check(problem, ledger, u_opt, off, False, None, None)[0] is None


def test_where_w0_is_not_rejected_the_reference_values_are_reported_and_the_interval_holds_the_estimate():
    """Known answers: the reported shift moves w_opt onto w0 exactly when the test ran and kept w0, and the
    interval that apply_no_change widened, centred there, still holds the (corrected) estimate; a rejected w0,
    the 'estimate' choice or a test that did not run leave the correction as it was."""
    from suspid.workflows.no_change import reported_correction

    u_opt, u0 = np.array([0.55, 0.40, 0.62]), np.array([0.50, 0.50, 0.50])
    corr = np.array([-0.01, 0.02, 0.0])
    kept = {"status": "done", "rejected": False}
    shift = reported_correction(kept, u_opt, corr, u0, "reference")
    assert np.allclose(u_opt + shift, u0) and kept["reported"].startswith("the reference date's values")
    assert kept["estimate_minus_w0_percent"] == pytest.approx([4.0, -8.0, 12.0])
    sd = np.full(3, 0.01)
    bound = apply_no_change(NoChange(0.1, 0.1, False, 32, 2.0), ["a", "b", "c"], sd, np.zeros(3),
                            u_opt + corr - u0, 2.0, 0.08, {})
    half = bias_aware_half_width(sd, bound, 2.0)
    assert np.all(np.abs(u_opt + corr - u0) <= half + 1e-9)            # centred on w0, it holds the estimate
    for report, how in (({"status": "done", "rejected": True}, "reference"), (dict(kept), "estimate"),
                        ({"status": "disabled"}, "reference")):
        assert reported_correction(report, u_opt, corr, u0, how) is corr
    assert reported_correction({"status": "done", "rejected": True}, u_opt, None, u0, "reference") is None


def test_the_terminal_and_report_line_says_no_change_was_shown_only_when_it_was():
    from suspid.workflows.report import no_change_line

    nc = {"status": "done", "rejected": False, "z": 1.24, "n_sigmas": 2.0}
    from suspid.workflows.no_change import reported_correction

    reported_correction(nc, np.array([0.46, 0.5]), None, np.array([0.5, 0.5]), "reference")
    line = no_change_line({"parameters": ["k_sec_z", "c_yaw"], "model_error": {"no_change": nc}})
    assert line.startswith("No change shown since the reference date") and "z = 1.2" in line
    assert "k_sec_z -4.0 %, c_yaw +0.0 %" in line
    rejected = {"status": "done", "rejected": True, "z": 9.0, "n_sigmas": 2.0}
    reported_correction(rejected, np.array([0.46, 0.5]), None, np.array([0.5, 0.5]), "reference")
    assert no_change_line({"parameters": ["k_sec_z", "c_yaw"], "model_error": {"no_change": rejected}}) is None
    assert no_change_line({"parameters": ["k_sec_z"]}) is None
