"""Calibration of the model parameters at the reference date and the linearised model-error checks.

Known answers: a linear least squares with known offsets and parameters, the maximiser of a quadratic
(implicit-function theorem), the bias-aware interval's limits; and, on the numerical experiment, a known
creep scale and a known yaw-damper series stiffness of the reference date's vehicle, different from the
config's nominal values, recovered within their reported intervals.
"""

from __future__ import annotations

import numpy as np
import pytest

from suspid.config import load_config
from suspid.errors import ConfigError
from suspid.infra.ledger import Ledger
from suspid.method.calibration import calibrate_step, implicit_shifts, octave_clusters
from suspid.method.identifiability import bias_aware_half_width
from suspid.workflows import linearised as L
from suspid.workflows.problem import build_problem
from suspid.workflows.trust import BiasSources, combine_sources
from test_nuisance import dates  # noqa: F401  (the fixture of the two dates with 5 MN/m yaw-damper mounts)


def test_calibrate_step_recovers_offsets_and_parameters():
    rng = np.random.default_rng(3)
    K, F, p = 3, 80, 2
    freqs = np.geomspace(0.5, 20, F)
    J = rng.normal(size=(K, F, p))
    offsets, t_true = np.array([1.0, -0.5, 2.0]), np.array([0.3, -0.2])
    residual = offsets[:, None] + J @ t_true
    step = calibrate_step(residual, J, np.ones((K, F)), octave_clusters(freqs, K), np.zeros(p), np.zeros(p))
    np.testing.assert_allclose(step.step, t_true, atol=1e-8)
    np.testing.assert_allclose(step.offsets_db, offsets, atol=1e-8)
    # with noise: the estimate within 3 of its standard deviations, which are not zero
    noisy = residual + 0.2 * rng.normal(size=(K, F))
    step = calibrate_step(noisy, J, np.full((K, F), 25.0), octave_clusters(freqs, K), np.zeros(p), np.zeros(p))
    sd = np.sqrt(np.diag(step.covariance))
    assert np.all(sd > 0)
    assert np.all(np.abs(step.step - t_true) < 3 * sd)
    # a parameter the data do not see keeps the prior's spread
    J[..., 1] = 0.0
    step = calibrate_step(offsets[:, None] + J @ t_true, J, np.ones((K, F)), octave_clusters(freqs, K),
                          np.zeros(p), np.full(p, 12.0))
    assert abs(step.step[1]) < 1e-6
    assert np.sqrt(step.covariance[1, 1]) == pytest.approx(1 / np.sqrt(12.0), rel=1e-3)


def test_implicit_shifts_of_a_quadratic():
    # J(u, t) = -1/2 u'Au + u'Bt has its maximum at u = A^-1 B t
    A = np.array([[2.0, 0.5], [0.5, 1.0]])
    B = np.array([[1.0, -1.0, 0.0], [0.5, 2.0, 1.0]])
    G, flat = implicit_shifts(-A, B)
    np.testing.assert_allclose(G, np.linalg.solve(A, B))
    assert not flat.any()
    G, flat = implicit_shifts(np.diag([-1.0, 0.0]), B[:, :1])   # the second component is not defined
    assert flat.tolist() == [False, True] and np.isnan(G[1]).all() and G[0, 0] == pytest.approx(1.0)


def test_equivalent_bias_bound_limits():
    sd = np.array([0.02, 0.03])
    shift = np.array([0.05, 0.0])
    # no model-parameter spread: the bound is the shift itself
    np.testing.assert_allclose(L.equivalent_bias_bound(sd, shift, np.zeros(2), 2.0), shift, atol=1e-9)
    # no shift: the interval is 2 sigma of the spreads in quadrature
    b = L.equivalent_bias_bound(sd, np.zeros(2), np.array([0.04, 0.0]), 2.0)
    np.testing.assert_allclose(bias_aware_half_width(sd, b, 2.0), [2 * np.hypot(0.02, 0.04), 2 * 0.03], rtol=1e-6)


def test_a_significant_self_check_bias_is_corrected_and_the_interval_keeps_its_level():
    """Known answer (Monte Carlo): w_opt = w + b + σ Z with a model-form bias b = 6 % of the interval that the
    self-check measures as b̂ = b + se Z'. Corrected by b̂, the error σ Z − se Z' is N(0, σ² + se²) and the
    interval, of half-width 2 √(σ² + se²), holds w at P(|Z| ≤ 2) = 95.4 %; bounding the bias by |b̂| instead
    gives intervals more than 1.5 times as wide. A mean shift within 2 standard errors is not corrected: it bounds the bias."""
    rng = np.random.default_rng(11)
    n, b = 1000, 0.06
    sd, se = np.full(n, 0.02), np.full(n, 0.01)     # n draws, as n components of one call
    error = b + sd * rng.normal(size=n)             # w_opt − w
    sc_bias = b + se * rng.normal(size=n)
    zeros = np.zeros(n)
    half = {}
    for correct in (True, False):
        sources = BiasSources(sc_bias, zeros, zeros, zeros, zeros, se)
        bound, corr = combine_sources(sd, sources, True, 2.0, correct_self_check=correct)
        fix = sources.significant_self_check() if correct else zeros
        half[correct] = bias_aware_half_width(sd, bound, 2.0)
        if correct:
            held, fixed = np.abs(error + corr) <= half[True], fix
    assert np.all(fixed == sc_bias)                  # 6 % against a standard error of 1 %: always corrected
    assert 0.93 <= held.mean() <= 0.975, held.mean()     # 95.4 % ± 0.7 % (1000 draws)
    np.testing.assert_allclose(half[True], 2 * np.hypot(sd, se), rtol=1e-6)
    assert np.mean(half[False]) > 1.5 * np.mean(half[True])
    # within its noise: no correction, |b̂| bounds the bias
    one = np.zeros(1)
    sources = BiasSources(np.array([0.015]), one, one, one, one, np.array([0.01]))
    bound, corr = combine_sources(np.array([0.02]), sources, True, 2.0, correct_self_check=True)
    fix = sources.significant_self_check()
    assert fix[0] == 0.0 and corr[0] == 0.0 and bound[0] == pytest.approx(0.015)


def _experiment(tmp_path, reference_vehicle: dict, model_error_db: float | None = None,
                calibration: dict | None = None):
    data_reference = {"simulator_options": {"vehicle": reference_vehicle}}
    if model_error_db is not None:
        data_reference["model_error_db"] = model_error_db
    config = load_config({
        "name": "calibration", "seed": 7,
        "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 100.0}},
        "parameters": {"k_sec_z": {}, "c_sec_z": {}, "k_prim_z": {}, "c_sec_y": {}, "c_yaw": {}},
        "data": {"source": "experiment", "track": {"n_segments": 16, "length_m": 1000.0, "speed_kmh": 300.0},
                 "reference": data_reference},
        "spectra": {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 200},
        "identifiability": {"model_error": {"run": "always", "method": "linearised",
                                            **({"calibration": calibration} if calibration else {})}}})
    ledger = Ledger(tmp_path / "ledger.sqlite")
    return build_problem(config, ledger), ledger


def _calibrated(problem, ledger):
    opts = problem.config.identifiability.model_error
    theta = L.model_parameters(problem, opts)
    jac0 = L.date_jacobian(problem, ledger, problem.reference_segments, dict(problem.w0), problem.names, theta, None)
    return L.calibrate(problem, ledger, theta, jac0, problem.names, opts, None)


def test_known_creep_scale_and_series_stiffness_recovered(tmp_path):
    """The reference date's vehicle has 70 % of Kalker's creep and 13 MN/m yaw-damper mounts (nominal: 100 %,
    10 MN/m); its measurement process keeps the per-segment gains and the sensor noise, without the systematic
    per-channel gain curve (which the calibration confounds with the mounts, see below)."""
    truth = {"kalker_scale": 0.7, "k_yaw_s": 13.0e6}
    problem, ledger = _experiment(tmp_path, truth, model_error_db=0.0)
    cal = _calibrated(problem, ledger)
    assert cal["status"] == "done" and cal["n_simulations"] <= cal["n_iterations"]   # analytic: one call per step
    for name, value in truth.items():
        entry = cal["parameters"][name]
        assert entry["status"] == "calibrated", entry
        lo, hi = entry["interval"]
        assert lo <= value <= hi, (name, entry)
        assert not lo <= entry["nominal"] <= hi, (name, entry)     # the data moved it off the nominal value
    opts = problem.config.identifiability.model_error
    bad = opts.model_copy(update={"calibration": opts.calibration.model_copy(
        update={"parameters": {"no_such_mount": (1.0, 2.0)}})})
    with pytest.raises(ConfigError, match="no_such_mount"):
        L.model_parameters(problem, bad)


def test_known_creep_scale_under_the_default_measurement_process(tmp_path):
    """With the numerical experiment's whole measurement process (fixed channel gains and gain curves, segment
    gains, a sensor floor) the creep scale's estimate stays within two standard deviations of the truth; a
    parameter whose standard deviation exceeds ``max_sd_fraction`` of its range is not called calibrated and
    keeps its assumed range (on seed 7 the creep scale itself: 0.78 ± 0.07 for 0.7, just over the 10 %)."""
    problem, ledger = _experiment(tmp_path, {"kalker_scale": 0.7})
    cal = _calibrated(problem, ledger)
    entry = cal["parameters"]["kalker_scale"]
    assert abs(entry["estimate"] - 0.7) <= 2 * entry["standard_deviation"], entry
    for e in cal["parameters"].values():
        if e["status"] != "calibrated":
            assert e["interval"] == e["assumed_range"] and "keeps its assumed range" in e["status"], e
            assert e["standard_deviation"] > 0.05 * (e["assumed_range"][1] - e["assumed_range"][0]) or \
                not e["assumed_range"][0] < e["estimate"] < e["assumed_range"][1], e


@pytest.mark.slow
def test_self_check_on_the_calibrated_model_has_no_bias_without_model_form_error(tmp_path):
    """The reference date's vehicle differs from the model only in its model parameters (2.5 MN/m mounts of the
    secondary vertical dampers, 70 % of Kalker's creep; nominal 5 MN/m and 100 %), so the model calibrated there has no model-form error left and the self-check,
    run on its spectra simulated at the calibrated values, finds no bias beyond its noise: every component's mean
    shift within 3 standard errors or 1.5 % of its interval. The nominal spectra extrapolated linearly to the
    calibrated values (what the self-check read before) carry the linearisation's error into the bias."""
    truth = {"k_sec_z_s": 2.5e6, "kalker_scale": 0.7}
    problem, ledger = _experiment(tmp_path, truth, model_error_db=0.0)
    opts = problem.config.identifiability.model_error
    theta = L.model_parameters(problem, opts)
    cal = _calibrated(problem, ledger)
    t_hat = np.array(cal["t_hat"])
    simulated = L.date_jacobian(problem, ledger, problem.reference_segments, dict(problem.w0) | theta.w(t_hat),
                                problem.names, theta, None)
    shifts = L.linear_self_check(problem, simulated, opts)
    bias, se = shifts.mean(axis=0), shifts.std(axis=0, ddof=1) / np.sqrt(len(shifts))
    assert np.all(np.abs(bias) <= np.maximum(3 * se, 0.015)), (bias, se)
    jac0 = L.date_jacobian(problem, ledger, problem.reference_segments, dict(problem.w0), problem.names, theta, None)
    extrapolated = L.DateJacobian(jac0.y + jac0.dt @ t_hat, jac0.du, jac0.dt, 0, {}, True)
    bias_extrapolated = L.linear_self_check(problem, extrapolated, opts).mean(axis=0)
    assert np.abs(bias_extrapolated).max() > 1.5 * np.abs(bias).max(), (bias_extrapolated, bias)


@pytest.mark.long
def test_linearised_checks_within_budget(tmp_path):
    """The linearised checks at w_ref of a run whose reference vehicle has 70 % of Kalker's creep: every check
    done, the simulator called once per Jacobian (analytic), each flag a verdict with its reason."""
    from suspid.workflows.analysis import model_error

    problem, ledger = _experiment(tmp_path, {"kalker_scale": 0.7})
    u = problem.to_unit(np.array([problem.w_ref[n] for n in problem.names]))
    opts = problem.config.identifiability.model_error
    trust = model_error(problem, ledger, u, problem.config.identifiability.step, opts, False,
                        np.full(problem.q, 0.02), None)
    report = trust["report"]
    assert report["method"] == "linearised"
    for part in (report["self_check"], report["nuisance"], report["adequacy"], report["calibration"]):
        assert part["status"] == "done", part
    budget = report["budget"]
    assert budget["jacobian_reference_w0"] == 1 and budget["jacobian_measurement_w_opt"] == 1
    # the two Jacobians, the calibration's steps, and at the calibrated values one per date (one more where the
    # calibrated shift is searched again)
    assert budget["total"] == 2 + report["calibration"]["n_simulations"] + budget.get("jacobians_at_calibrated", 0) \
        + budget.get("jacobian_reference_calibrated", 0) + budget["no_change"]
    assert budget["total"] <= 2 + opts.calibration.max_iterations + 4
    entry = report["calibration"]["parameters"]["kalker_scale"]   # 0.78 ± 0.07 on seed 7: just not pinned down
    assert abs(entry["estimate"] - 0.7) <= 2 * entry["standard_deviation"], entry
    assert trust["bias_bound"].shape == (problem.q,) and np.all(trust["bias_bound"] >= 0)
    for name, ok in trust["trustworthy"].items():
        assert ok == (name not in trust["reasons"])


@pytest.mark.long
def test_linearised_run_calibrates_the_mounts_and_corrects_w_opt(dates):
    """tests/test_nuisance.py's known answer by the linearised method: both dates from a car whose yaw dampers'
    series stiffness is 5 MN/m, the model assuming 10 MN/m. The reference date calibrates the mounts near
    5 MN/m, and the implicit-function shift to the calibrated value brings c_yaw to the truth; the
    checks took a few simulator calls (one per Jacobian)."""
    import json

    import yaml
    from test_nuisance import TRUE_K_YAW_S, _cli, _config

    out, c_yaw_true = dates
    cfg = _config(out, {}, "linearised.yaml")
    data = yaml.safe_load(cfg.read_text())
    data["name"] = "linearised"
    data["identifiability"]["model_error"].update(
        {"method": "linearised", "calibration": {"parameters": {"k_yaw_s": [2.0e6, 20.0e6]}}})
    cfg.write_text(yaml.safe_dump(data, sort_keys=False))
    assert _cli("run", str(cfg), "--quiet") == 0
    result = json.loads((out / "runs" / "linearised" / "result.json").read_text())
    entry = result["calibration"]["parameters"]["k_yaw_s"]
    assert entry["status"] == "calibrated" and entry["interval"][0] <= TRUE_K_YAW_S <= entry["interval"][1], entry
    lo, hi = result["bounds"]["c_yaw"]
    corrected = result["model_error"]["nuisance"]["w_opt_calibrated"]["c_yaw"]
    assert abs(corrected - c_yaw_true) / (hi - lo) < 0.03, (corrected, c_yaw_true, result["w_opt"]["c_yaw"])
    # the reported value is the corrected one (no self-check here: the calibrated model's shift alone), and the
    # interval around it holds the truth
    assert result["w_corrected"]["c_yaw"] == pytest.approx(corrected, rel=1e-9)
    assert result["interval"]["c_yaw"][0] <= c_yaw_true <= result["interval"]["c_yaw"][1], result["interval"]
    budget = result["model_error"]["budget"]
    assert budget["total"] <= result["n_simulator_calls"]
    assert "Model parameters calibrated at the reference date" in (out / "runs" / "linearised" / "report.md").read_text()
