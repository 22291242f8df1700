"""The diagnosis's own fit of the suspension and of the effects (least squares on D), its relevance margin, and
the correction of a tilted sensor in the measured records.

Known answers: a numerical experiment's w_ref recovered from a biased start (with and without an effect fitted
with it), the sandwich covariance against its dense formula, the p-value of the margin in closed form, a tilt
rotated back exactly.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import yaml

from conftest import run_cli

KMH = 1 / 3.6


def _experiment(tmp_path: Path, hidden: list, n_segments: int = 16) -> Path:
    cfg = {
        "name": "joint", "seed": 5,
        "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 100.0}},
        "parameters": {"k_sec_z": {}, "c_sec_z": {}, "k_prim_z": {}},
        "data": {"source": "experiment",
                 "track": {"spectrum": "german-low", "n_segments": n_segments, "length_m": 600.0, "speed_kmh": 300.0},
                 "w_ref": {"k_sec_z": 340.0e3, "c_sec_z": 14.0e3, "k_prim_z": 1.30e6},
                 "reference": {"n_segments": 24, "model_error_scatter_db": 0.5},
                 "measurement": {"errors": "noise-model", "simulator_options": {"effects": hidden}}},  # eq. 10
        "spectra": {"f_min_hz": 0.4, "f_max_hz": 30.0, "n_freqs": 120},
        "diagnose": {"n_bootstrap": 0},
    }
    path = tmp_path / "joint.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def _problem(path: Path):
    from suspid.config import load_config
    from suspid.infra.ledger import Ledger
    from suspid.workflows.diagnose import make_cells
    from suspid.workflows.diagnose.fit import Discrepancy
    from suspid.workflows.diagnose.null import analytic_null
    from suspid.workflows.problem import build_problem

    cfg = load_config(path)
    problem = build_problem(cfg, Ledger(path.parent / "ledger.sqlite"))
    grid = make_cells(problem.channels, problem.freqs, problem.speeds)
    null = analytic_null(grid, problem.noise_model)
    disc = Discrepancy(grid, null, problem.y_mes, problem.noise_model, np.zeros(grid.n_cells, bool),
                       problem.y_mes)
    return cfg, problem, disc


def _errors(problem, w: dict) -> dict:
    return {n: 100 * (w[n] - problem.w_ref[n]) / (hi - lo) for n, (lo, hi) in zip(problem.names, problem.bounds)}


def test_least_squares_on_d_recovers_the_suspension_from_a_biased_start(tmp_path):
    from suspid.workflows.diagnose.joint import fit_jointly

    cfg, problem, disc = _problem(_experiment(tmp_path, []))
    start = {n: problem.w_ref[n] + s * (hi - lo) for n, (lo, hi), s in zip(problem.names, problem.bounds,
                                                                          (-0.2, 0.15, 0.1))}
    fit = fit_jointly(cfg, problem, disc, start, max_evaluations=80)
    err = _errors(problem, fit.w)
    assert max(abs(e) for e in err.values()) < 2.0, err                 # % of the interval; started 10-20 % off
    assert fit.D < fit.D_start and fit.n_simulations <= 80
    # the sampling half-widths (2 sd) hold the error of every component (they are not inflated to do so)
    assert all(abs(err[n]) <= fit.half_width_percent[n] for n in problem.names), (err, fit.half_width_percent)
    assert all(fit.half_width_percent[n] < 5.0 for n in problem.names)


def test_an_effect_and_the_suspension_are_fitted_together(tmp_path):
    """A hidden bending mode: from a wrong frequency and damping and a biased suspension, both recovered."""
    from suspid.workflows.diagnose.joint import fit_jointly

    cfg, problem, disc = _problem(_experiment(tmp_path, [{"name": "carbody-bending", "frequency_hz": 9.5,
                                                          "damping": 0.02}]))
    start = {n: problem.w_ref[n] + s * (hi - lo) for n, (lo, hi), s in zip(problem.names, problem.bounds,
                                                                          (0.1, 0.15, 0.1))}
    fit = fit_jointly(cfg, problem, disc, start, [("carbody-bending", {"frequency_hz": 9.0, "damping": 0.04,
                                                                       "length_m": 26.0})], max_evaluations=120)
    (name, params), = fit.effects
    assert name == "carbody-bending" and params["length_m"] == 26.0
    assert params["frequency_hz"] == pytest.approx(9.5, rel=0.01)
    assert params["damping"] == pytest.approx(0.02, rel=0.15)
    err = _errors(problem, fit.w)
    assert max(abs(e) for e in err.values()) < 2.0, err
    assert set(fit.half_width_percent) == set(problem.names) | {"carbody-bending/frequency_hz",
                                                                "carbody-bending/damping"}


def test_sandwich_half_widths_match_the_dense_formula():
    from suspid.method.noise import NoiseModel
    from suspid.workflows.diagnose.joint import _half_widths

    rng = np.random.default_rng(1)
    K, F, G = 3, 20, 2
    b = rng.normal(size=(40, K, F)) + np.cumsum(rng.normal(size=(40, K, F)), axis=2) * 0.3
    nm = NoiseModel().fit(b)
    J = rng.normal(size=(G * K * F, 2))
    disc = SimpleNamespace(target=np.zeros((G, K, F)))
    sd = np.sqrt(nm.variance_.ravel())
    R = nm.covariance() / np.outer(sd, sd)
    meat = sum(J[g * K * F:(g + 1) * K * F].T @ R @ J[g * K * F:(g + 1) * K * F] for g in range(G))
    bread = np.linalg.inv(J.T @ J)
    expected = 200 * np.sqrt(np.diag(bread @ meat @ bread))
    got = _half_widths(J, disc, nm, ["a", "b"])
    assert [got["a"], got["b"]] == pytest.approx(expected, rel=1e-3)


def test_relevance_margin_in_closed_form_and_on_a_map():
    from suspid.workflows.diagnose import calibrate_null, locate, make_cells
    from suspid.workflows.diagnose.locate import _two_sided

    # P(|N(δ, s)| >= x): δ = 0 is the usual two-sided p; x = δ gives 1/2 + a tail
    assert _two_sided(np.array(1.96), 0.0, 1.0) == pytest.approx(0.05, abs=1e-4)
    assert _two_sided(np.array(0.5), 0.5, 0.1) == pytest.approx(0.5, abs=1e-6)
    from suspid.method.noise import NoiseModel

    rng = np.random.default_rng(3)
    f = np.linspace(0.5, 30.0, 60)
    nm = NoiseModel().fit(0.3 * rng.normal(size=(200, 2, f.size)), freqs=f, channels=["a", "b"])
    grid = make_cells(["a", "b"], f, [80.0] * 200)
    null = calibrate_null(grid, nm, 0, rng)
    y_sim = np.zeros((200, 2, f.size))
    y_mes = nm.sample(200, rng)                                       # Y_mod = y_sim + B, y_sim = 0
    y_mes[:, 0] += 0.3                 # a broad 0.3 dB discrepancy on channel a: significant with 200 segments
    y_mes[:, 1, 30:40] += 1.5          # a 1.5 dB one on channel b
    strict = locate(grid, null, y_mes, y_sim, nm.mean_, min_db=0.0)
    relevant = locate(grid, null, y_mes, y_sim, nm.mean_, min_db=0.5)
    on_a = np.array([grid.index(c)[1] == 0 for c in range(grid.n_cells)])
    assert strict.flagged[on_a].mean() > 0.8 and not relevant.flagged[on_a].any()
    assert relevant.flagged[~on_a].sum() >= 2                       # the 1.5 dB one stays


# ------------------------------------------------------------------------------------------ sensor corrections
def test_untilt_rotates_a_tilted_lateral_back_exactly():
    from suspid.data.corrections import untilt
    from suspid.interfaces import Response
    from suspid.sections import SensorCorrection

    rng = np.random.default_rng(0)
    lat, vert, other = rng.normal(size=(3, 500))
    a = math.radians(6.0)
    channels = ["bogie_front_vertical", "bogie_front_lateral", "x"]
    rec = Response(tuple(channels), 100.0, np.array([vert, math.cos(a) * lat + math.sin(a) * vert, other]), "s1")
    out, = untilt([rec], [SensorCorrection(channel="bogie_front_lateral", tilt_deg=6.0)], channels)
    assert np.allclose(out.accelerations[1], lat) and np.array_equal(out.accelerations[0], vert)
    assert np.array_equal(rec.accelerations[1], math.cos(a) * lat + math.sin(a) * vert)   # the input is kept
    with pytest.raises(Exception, match=r"data.corrections.0.vertical"):
        untilt([rec], [SensorCorrection(channel="x", tilt_deg=2.0)], channels)


def test_data_corrections_change_the_measured_spectra_and_bad_ones_are_one_line_errors(tmp_path):
    """On the independent train's files: the corrected lateral spectrum differs, the vertical does not; a
    channel that does not exist is refused naming its key, exit code 2."""
    from independent import effects as HE

    from suspid.config import load_config
    from suspid.infra.ledger import Ledger
    from suspid.workflows.problem import build_problem

    path = HE.prepare(tmp_path / "tilt", HE.CASES["tilt"].hidden, seed=3, n_segments=6, n_reference=8)
    cfg = yaml.safe_load(path.read_text())
    plain = build_problem(load_config(path), Ledger(tmp_path / "a.sqlite"))
    cfg["data"]["corrections"] = [{"channel": "bogie_front_lateral", "tilt_deg": 6.0}]
    path.write_text(yaml.safe_dump(cfg))
    corrected = build_problem(load_config(path), Ledger(tmp_path / "b.sqlite"))
    k, kv = plain.channels.index("bogie_front_lateral"), plain.channels.index("bogie_front_vertical")
    assert np.array_equal(plain.y_mes[:, kv], corrected.y_mes[:, kv])
    assert np.abs(plain.y_mes[:, k] - corrected.y_mes[:, k]).max() > 0.5
    assert plain.data_identity != corrected.data_identity
    cfg["data"]["corrections"] = [{"channel": "bogie_front_lateral"}, {"channel": "no_such", "tilt_deg": 1.0}]
    path.write_text(yaml.safe_dump(cfg))
    r = run_cli("validate", str(path))
    assert r.returncode == 2 and "data.corrections.0.tilt_deg" in r.stderr and "Traceback" not in r.stderr
    cfg["data"]["corrections"] = [{"channel": "no_such", "tilt_deg": 1.0}]
    path.write_text(yaml.safe_dump(cfg))
    for command in ("validate", "run"):
        r = run_cli(command, str(path))
        assert r.returncode == 2 and "data.corrections.0.channel" in r.stderr and "no_such" in r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr


def test_corrected_problem_keeps_everything_but_the_measurements(tmp_path):
    from independent import effects as HE

    from suspid.config import load_config
    from suspid.infra.ledger import Ledger
    from suspid.workflows.diagnose.workflow import _corrected_problem
    from suspid.workflows.problem import build_problem, read_measurements

    path = HE.prepare(tmp_path / "tilt", HE.CASES["tilt"].hidden, seed=3, n_segments=6, n_reference=8)
    cfg = load_config(path)
    problem = build_problem(cfg, Ledger(tmp_path / "a.sqlite"))
    _, records = read_measurements(cfg.data.measurements, cfg.data.track_file, problem.channels)
    tilt = {"sensor-tilt": [{"channel": "bogie_front_lateral", "tilt_deg": 6.0, "vertical": "bogie_front_vertical"}]}
    fixed = _corrected_problem(cfg, problem, records, tilt)
    assert fixed.segments == problem.segments and fixed.b is problem.b and fixed.noise_model is problem.noise_model
    assert fixed.data_identity != problem.data_identity
    k = problem.channels.index("bogie_front_lateral")
    changed = np.abs(fixed.y_mes - problem.y_mes).max(axis=(0, 2))            # dB, per channel
    assert changed[k] > 0.5 and np.all(np.delete(changed, k) == 0.0)


def test_at_nominal_with_reidentify_fits_the_suspension_from_the_nominal_values(tmp_path):
    """No identification run (``at: nominal``): the joint fit starts from the simulator's nominal values."""
    import suspid
    from test_diagnose import _config

    path = _config(tmp_path, "nominal_joint", [{"name": "carbody-bending", "frequency_hz": 9.5, "damping": 0.02}],
                   n_segments=16, n_reference=24, f_max=30.0, n_freqs=120, at="nominal", reidentify=True)
    d = suspid.diagnose(path).diagnosis
    assert d["named"] == "carbody-bending" and d["gap_before"]["w"] == {}
    fit = d["steps"][0]["joint_fit"]
    assert fit["mode"].startswith("together") and fit["D"] < fit["D_start"]
    assert set(d["gap_after"]["w"]) == {"k_sec_z", "c_sec_z"}
    assert "identified" not in d["gap_after"]                                   # nothing identified
    assert d["effects"][0]["parameters"]["frequency_hz"] == pytest.approx(9.5, rel=0.01)


def test_data_group_check_on_the_models_own_data_and_without_a_jacobian(tmp_path):
    """Data made by the model itself: every group asks for the same suspension up to sampling, so every
    component is identifiable, with a small spread; a fit without a Jacobian (failed) measures nothing, so
    nothing is identifiable; a subset fit reads its own columns."""
    from dataclasses import replace as dc_replace

    from suspid.workflows.diagnose.joint import check_groups, fit_jointly

    cfg, problem, disc = _problem(_experiment(tmp_path, [], n_segments=24))
    fit = fit_jointly(cfg, problem, disc, dict(problem.w_ref), max_evaluations=60)
    me = check_groups(cfg, problem, disc, fit, max_evaluations=40)
    assert set(me["groups"]) >= {"below 3.5 Hz", "above 3.5 Hz", "vertical channels"}   # sqrt(0.4 x 30) Hz
    assert all(me["identifiable"].values()), me
    assert max(me["spread_percent"].values()) < 5.0 and fit.identifiable == me["identifiable"]
    assert me["max_spread_percent"] == pytest.approx(6.0) and not any(me["groups_disagree"].values())
    failed = dc_replace(fit, jacobian=None, model_error=None)
    assert not any(check_groups(cfg, problem, disc, failed)["identifiable"].values())
    sub = fit_jointly(cfg, problem, disc, dict(problem.w_ref), max_evaluations=30, suspension=["c_sec_z"])
    assert sub.fitted == ["c_sec_z"] and sub.w["k_sec_z"] == pytest.approx(problem.w_ref["k_sec_z"])
    assert set(check_groups(cfg, problem, disc, sub, max_evaluations=20)["identifiable"]) == {"c_sec_z"}
