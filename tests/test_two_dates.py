"""The two-date protocol on measured files, as a new user runs it: generate, write a config, `suspid run`.

The files come from the independent train (tests/independent), not from
suspid's model; the reference date runs at w0, the measurement date with a
damaged yaw damper and lateral damper. Sizes are cut to seconds.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from independent import train as TR
from independent.protocol import VEHICLE
from suspid import cli
from suspid.method.adequacy import band_residuals, frequency_bands, information_share
from suspid.method.noise import fit_noise_model
from suspid.workflows.adequacy import data_groups

W_DAMAGED = {"c_yaw": 560.0e3, "c_sec_y": 11.0e3}


def _cli(*args: str) -> int:
    with pytest.raises(SystemExit) as exit_:
        cli.main(list(args))
    return exit_.value.code


@pytest.fixture(scope="module")
def two_dates(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("two-dates")
    TR.generate_two_dates(out, {}, W_DAMAGED, seed=3, n_segments=8, speed_mps=300 / 3.6, length_m=600.0)
    return out


def _config(out: Path, method: str = "full", **extra) -> Path:
    cfg = {"name": "two-dates", "seed": 3,
           "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0,
                                                                "vehicle": VEHICLE}},
           "parameters": {"c_sec_y": {}, "c_yaw": {}},
           "data": {"source": "measured", "measurements": "measurement/accelerations",
                    "track_file": "measurement/track"},
           "noise": {"reference": {"measurements": "reference/accelerations", "track_file": "reference/track"}},
           "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 40},
           "design": {"n_initial": 6}, "ego": {"max_iter": 2},
           "identifiability": {"n_redraws": 6, "model_error": {
               "method": method, "self_check": {"n_splits": 2, "max_evaluations": 8},
               "adequacy": {"group_evaluations": 4}}}} | extra
    path = out / "config.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def test_run_identifies_the_noise_model_from_the_reference_files_and_flags_model_error(two_dates):
    cfg = _config(two_dates)
    assert _cli("validate", str(cfg)) == 0
    assert _cli("run", str(cfg), "--quiet") == 0
    run = two_dates / "runs" / "two-dates"
    result = json.loads((run / "result.json").read_text())
    assert (run / "noise_model.npz").exists()
    assert set(result["trustworthy"]) == {"c_sec_y", "c_yaw"}
    assert all(isinstance(v, bool) for v in result["trustworthy"].values())  # every check ran: yes or no
    assert result["not_assessed_reasons"] == {}
    assert all(c["ran"] for c in result["model_error"]["checks"].values() if c["required"])
    for n, reasons in result["untrustworthy_reasons"].items():
        assert result["trustworthy"][n] is False and reasons
    sc = result["model_error"]["self_check"]
    assert sc["status"] == "done" and sc["n_splits"] == 2 and sc["segments_fit"] == 4
    assert result["model_error"]["adequacy"]["status"] == "done"
    for n in result["parameters"]:        # the widened interval contains the sampling one
        lo, hi = result["interval"][n]
        slo, shi = result["interval_sampling"][n]
        assert lo <= slo + 1e-9 and hi >= shi - 1e-9
    me = result["model_error"]   # the bias-aware interval is w_opt ± the reported half-width, clipped to the box
    centre = result.get("w_corrected_normalized") or result["w_opt_normalized"]   # bias-corrected (calibration)
    for n in result["parameters"]:
        u, half = centre[n], me["half_width_percent"][n] / 100
        assert result["interval_normalized"][n] == pytest.approx([max(u - half, 0.0), min(u + half, 1.0)], abs=1e-9)
        assert me["bias_bound_percent"][n] >= 0
        if half > me["max_half_width_percent"] / 100 and result["identifiable"][n]:
            assert not result["trustworthy"][n]
    report = (run / "report.md").read_text()
    assert "## Model error" in report and "trustworthy under model error" in report
    assert "Bias correction" in report   # the model parameters calibrated, their shift corrected (correct: true)
    budget = result["model_error"]["budget"]   # every check's simulations, counted
    assert budget["total"] == sum(v for k, v in budget.items() if k != "total") > result["n_simulator_calls"]
    # a second run reuses the reference-date simulation and the self-check from the ledger
    assert _cli("run", str(cfg), "--quiet") == 0
    assert json.loads((run / "result.json").read_text())["w_opt"] == result["w_opt"]


def test_the_default_linearised_checks_cost_less_than_the_identification(two_dates):
    """The default checks (linearised, the model parameters calibrated at the reference date) on the same two
    dates: every required check ran, their simulator calls are fewer than the identification's, and the interval
    is centred on the bias-corrected value."""
    cfg = _config(two_dates, method="linearised", name="two-dates-linearised")
    data = yaml.safe_load(cfg.read_text())
    del data["identifiability"]["model_error"]["method"]           # the default
    cfg.write_text(yaml.safe_dump(data, sort_keys=False))
    assert _cli("run", str(cfg), "--quiet") == 0
    result = json.loads((two_dates / "runs" / "two-dates-linearised" / "result.json").read_text())
    me = result["model_error"]
    assert me["method"] == "linearised"
    assert all(isinstance(v, bool) for v in result["trustworthy"].values())  # every check ran: yes or no
    assert 0 < me["budget"]["total"] <= result["n_simulator_calls"], (me["budget"], result["n_simulator_calls"])
    assert result["calibration"]["status"] == "done"
    for n in result["parameters"]:
        u, half = result["w_corrected_normalized"][n], me["half_width_percent"][n] / 100
        assert result["interval_normalized"][n] == pytest.approx([max(u - half, 0.0), min(u + half, 1.0)], abs=1e-9)
        assert me["correction"]["correction_percent"][n] == pytest.approx(
            100 * (u - result["w_opt_normalized"][n]), abs=1e-6) or u in (0.0, 1.0)
    # the calibrated shift's transfer error: transfer_error (default 0.25) x |shift|, in result.json and report.md
    assert me["transfer_error"] == 0.25
    for n in result["parameters"]:
        src = me["bias_sources_percent"][n]
        assert src["model_parameters_transfer"] == pytest.approx(0.25 * abs(src["model_parameters_shift"]), abs=1e-9)
    report = (two_dates / "runs" / "two-dates-linearised" / "report.md").read_text()
    assert "Bias correction" in report and "its transfer error (%)" in report
    # the calibrated shift averaged over 8 draws of the noise paths; their Monte Carlo error is in the spread
    nu = me["nuisance"]
    assert nu["shift_draws"] == 8
    for n in result["parameters"]:
        se = nu["shift_standard_error_percent"][n]
        assert 0.0 <= se <= me["bias_sources_percent"][n]["model_parameters_spread"] + 1e-9


def test_the_shipped_two_date_config_validates_beside_generated_files(tmp_path):
    """configs/two-dates.yaml as the README says: copied beside `reference/` and `measurement/`, it validates
    (its numbers in the exponent form 14.68e6 read as numbers, its nuisance parameters are the model's)."""
    TR.generate_two_dates(tmp_path, {}, W_DAMAGED, seed=3, n_segments=2, speed_mps=300 / 3.6)
    shipped = Path(__file__).resolve().parents[1] / "configs" / "two-dates.yaml"
    cfg = tmp_path / "two-dates.yaml"
    cfg.write_text(shipped.read_text())
    assert _cli("validate", str(cfg)) == 0


def test_validate_names_a_missing_reference_file(two_dates):
    cfg = _config(two_dates, noise={"reference": {"measurements": "nowhere", "track_file": "reference/track"}})
    assert _cli("validate", str(cfg)) == 2


def test_validate_rejects_a_reference_date_on_another_grid(tmp_path, two_dates):
    TR.generate_date(tmp_path / "short", {}, seed=9, n_segments=2, speed_mps=300 / 3.6, length_m=300.0)
    cfg = _config(two_dates, noise={"reference": {"measurements": str(tmp_path / "short" / "accelerations"),
                                                  "track_file": str(tmp_path / "short" / "track")}})
    assert _cli("validate", str(cfg)) == 2


def test_band_residuals_flag_a_shift_the_noise_cannot_explain():
    rng = np.random.default_rng(0)
    freqs = np.geomspace(0.5, 16, 60)
    y_sim0 = rng.normal(0, 1, (30, 2, 60))
    b0 = rng.normal(0, 0.5, (30, 2, 60))
    noise = fit_noise_model(y_sim0 + b0, y_sim0)
    y_sim = rng.normal(0, 1, (30, 2, 60))
    y_mes = y_sim + rng.normal(0, 0.5, (30, 2, 60))
    y_mes[:, 1, freqs > 8] += 2.0                       # channel 1 above 8 Hz: what the model misses
    bands = frequency_bands(freqs, 1.0)
    res = band_residuals(y_mes, y_sim, noise, bands)
    high = np.array([freqs[b].min() >= 8 for b in bands])
    assert res.inadequate[1, high].all() and not res.inadequate[0].any() and not res.inadequate[1, ~high].any()
    S = np.zeros((2, 2, 60))
    S[0, 1, freqs > 8] = 1.0                             # parameter 0 read where the model is wrong
    S[1, 0] = 1.0                                        # parameter 1 elsewhere
    share, _ = information_share(S, noise.variance_, np.array([0.5, 0.5]), res)
    assert share[0] > 0.9 and share[1] < 0.05


def test_band_residuals_take_the_mean_of_b_at_each_speed():
    """Reference date and measurements at 200 and 300 km/h, B's mean 3 dB higher at 200 km/h: nothing is
    inadequate with μ_B per speed; with one μ_B for both speeds every band of both channels is."""
    rng = np.random.default_rng(1)
    freqs = np.geomspace(0.5, 16, 60)
    speeds = np.repeat([200 / 3.6, 300 / 3.6], 30)
    shift = np.where(speeds < 70, 1.5, -1.5)[:, None, None]
    y_sim0 = rng.normal(0, 1, (60, 2, 60))
    noise = fit_noise_model(y_sim0 + rng.normal(0, 0.5, (60, 2, 60)) + shift, y_sim0, speeds=speeds)
    y_sim = rng.normal(0, 1, (60, 2, 60))
    y_mes = y_sim + rng.normal(0, 0.5, (60, 2, 60)) + shift
    bands = frequency_bands(freqs, 1.0)
    keep = np.r_[0:10, 30:60]                          # 10 segments at 200, 30 at 300 km/h: unequal weights
    res = band_residuals(y_mes[keep], y_sim[keep], noise, bands, speeds=speeds[keep])
    assert not res.inadequate.any() and np.abs(res.mean_db).max() < 0.3
    pooled = band_residuals(y_mes[keep], y_sim[keep], noise, bands)
    assert pooled.inadequate.all() and np.allclose(pooled.mean_db, -0.75, atol=0.2)


def test_data_groups_split_directions_and_frequencies():
    groups = data_groups(["a_vertical", "a_lateral", "b_vertical"], np.geomspace(0.4, 20, 10))
    names = [g.name for g in groups]
    assert names[:2] == ["vertical channels", "lateral channels"] and len(groups) == 4
    assert groups[0].channels.tolist() == [True, False, True]
    assert (groups[2].freqs ^ groups[3].freqs).all()


def test_a_significant_self_check_shift_over_the_tolerance_is_a_bias():
    """The self-check's rule on known numbers (fractions of the interval, tolerance 3 %): 4.7 ± 1.2 % is a bias
    over the tolerance (its 2-sigma lower bound, 2.3 %, is not: the size is judged on the estimate); 4.7 ± 3.0 %
    could be scatter; 2.0 ± 0.5 % is a bias within the tolerance."""
    from suspid.workflows.analysis import biased

    bias = [0.047, -0.047, 0.047, 0.020, 0.060]
    se = [0.012, 0.012, 0.030, 0.005, 0.035]
    assert biased(bias, se, 0.03).tolist() == [True, True, False, False, False]


def test_with_a_noise_model_file_no_component_is_called_trustworthy(two_dates, capsys):
    """noise.path without the reference date's files: the self-check cannot run, and with the adequacy test off
    no check examines any component: each is *not assessed* (never yes), with the reason, in result.json,
    report.md and the terminal table."""
    first = two_dates / "runs" / "two-dates"
    if not (first / "noise_model.npz").exists():
        assert _cli("run", str(_config(two_dates)), "--quiet") == 0
    cfg = _config(two_dates, name="two-dates-path", noise={"path": str(first / "noise_model.npz")})
    with open(cfg) as fh:
        raw = yaml.safe_load(fh)
    raw["identifiability"]["model_error"]["adequacy"]["enabled"] = False
    raw["identifiability"]["model_error"]["no_change"] = False   # (on its own it may say no: test_no_change.py)
    cfg.write_text(yaml.safe_dump(raw, sort_keys=False))
    capsys.readouterr()
    assert _cli("run", str(cfg), "--quiet") == 0
    out = capsys.readouterr().out
    run = two_dates / "runs" / "two-dates-path"
    result = json.loads((run / "result.json").read_text())
    assert result["trustworthy"] == {"c_sec_y": None, "c_yaw": None}
    for n in result["parameters"]:
        reasons = " ".join(result["not_assessed_reasons"][n])
        assert "self-check not run" in reasons and "noise.path" in reasons and "adequacy" in reasons
    checks = result["model_error"]["checks"]
    assert not checks["self_check"]["ran"] and not checks["adequacy"]["ran"] and not checks["groups"]["ran"]
    assert result["interval"] == result["interval_sampling"]   # nothing bounds the bias: sampling only
    report = (run / "report.md").read_text()
    assert "Model-error checks that ran: none." in report
    assert "reference-date self-check (needed for a yes): not run" in report
    assert report.count("| *not assessed* |") == 2 and "| yes | yes |" not in report
    header = next(line for line in out.splitlines() if line.startswith("verdict "))
    assert "trust" in header
    checks_line = [line for line in out.splitlines() if line.startswith("Model-error checks")]   # report.md: each
    assert out.count("not assessed") >= 2 and len(checks_line) == 1 and "noise.path" in checks_line[0]
    assert checks_line[0].endswith(": trust is not assessed (report.md lists the checks)"), checks_line


def test_too_few_reference_segments_are_said_by_validate_and_named_by_the_run(two_dates, capsys):
    """A reference date of 5 segments: validate warns that the self-check needs 8 (trust not assessed), and the
    run's status names that cause, not noise.reference (which is given)."""
    import shutil

    few = two_dates / "few"
    for kind in ("track", "accelerations"):
        (few / kind).mkdir(parents=True, exist_ok=True)
        for f in sorted((two_dates / "reference" / kind).glob("*.csv"))[:5]:
            shutil.copy(f, few / kind / f.name)
    limits = {"c_yaw": {"warning": -25, "alarm": -40}, "c_sec_y": {"warning": -25, "alarm": -40}}
    cfg = _config(two_dates, "linearised", name="few", limits=limits,
                  noise={"reference": {"measurements": "few/accelerations", "track_file": "few/track"}})
    cfg = cfg.rename(two_dates / "few.yaml")
    capsys.readouterr()
    assert _cli("validate", str(cfg)) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"warning: {cfg}: the reference date has 5 segments ({few / 'accelerations'}); the "
                   f"reference-date self-check needs 8, so trust will be 'not assessed' (record more kilometres at "
                   f"constant speed on the reference date, or cut shorter segments)"]
    assert _cli("run", str(cfg), "--quiet") == 0
    result = json.loads((two_dates / "runs" / "few" / "result.json").read_text())
    assert result["model_error"]["checks"]["self_check"]["status"] == (
        "not run: the reference date has 5 segments, the self-check needs 8 (record more kilometres at constant "
        "speed on the reference date, or cut shorter segments)")
    out = capsys.readouterr().out
    assert "the reference date has 5 segments, the self-check needs 8" in out and "give noise.reference" not in out


def test_measured_data_without_limits_are_warned_of(two_dates, capsys):
    cfg = _config(two_dates)
    capsys.readouterr()
    assert _cli("validate", str(cfg)) == 0
    assert capsys.readouterr().err.strip().splitlines() == [
        f"warning: {cfg}: no limits: for c_sec_y, c_yaw: their maintenance verdict will be 'not assessable' (give "
        f"warning and alarm levels in % of nominal under limits:, e.g. c_sec_y: {{warning: -25, alarm: -40}})"]

