"""``objective.weights: efficient``: channel weights chosen as estimating-equation weights at the reference date.

Known answers: for one component the minimiser of the sandwich variance αᵀVα / (αᵀc̄)² is α ∝ V⁻¹c̄ (Godambe's
optimal estimating function); a channel whose gradient is noisy and whose curvature is unstable is down-weighted;
the kept curvature share holds; and on the numerical experiment the weights come from 2q simulations at the
reference date, are recorded, and change J's data identity (the default stays equal weights).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from suspid.cli import main
from suspid.config import load_config
from suspid.infra.ledger import Ledger
from suspid.method.weights import (component_variances, curvature_shares, efficient_weights,
                                   efficient_weights_from_moments)
from suspid.workflows.analysis import _y_sim_key
from suspid.workflows.problem import build_problem
from suspid.workflows.report import weights_line


def test_one_component_closed_form():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(4, 4))
    V = A @ A.T + 4 * np.eye(4)
    expected = np.array([0.1, 0.4, 0.2, 0.3])
    c = -V @ expected                     # then -V⁻¹c̄ ∝ expected, all positive: the constraint α ≥ 0 is not active
    est = efficient_weights_from_moments(V[None], c[None])
    assert est.alpha == pytest.approx(expected, abs=1e-4)
    assert est.variance[0] == pytest.approx(1.0 / (expected @ V @ expected), rel=1e-6)   # (αᵀVα)/(αᵀc)² at α*
    assert est.variance[0] <= est.variance_equal[0]


def test_a_noisy_unstable_channel_is_down_weighted():
    """Three channels, two components: channel 2's gradient is 4x noisier and its curvature scatters with cv 1.2
    (a model-form error along it), the others are alike: channel 2 gets almost no weight, both components'
    sandwich variances fall, and the two like channels share the rest."""
    rng = np.random.default_rng(7)
    R = 400
    g = rng.normal(size=(R, 2, 3)) * np.array([1.0, 1.0, 4.0])
    c = np.array([-2.0, -2.0, -1.0]) + rng.normal(size=(R, 2, 3)) * np.array([0.2, 0.2, 1.2])
    est = efficient_weights(g, c)
    assert est.alpha[2] < 0.03
    assert est.alpha[0] == pytest.approx(est.alpha[1], abs=0.08)
    assert np.all(est.variance < est.variance_equal)
    assert est.alpha.sum() == pytest.approx(1.0) and np.all(est.alpha >= 0)


def test_kept_curvature_share_and_degenerate_cases():
    rng = np.random.default_rng(3)
    R, n = 200, 4
    # component 0 is read from channels 0-1 and disturbed by channel 3's noise; component 1 only from channel 3:
    # the trace (dominated by component 0) starves channel 3, and with it component 1's share of the curvature
    curv = np.array([[-1.0, -1.0, -0.1, -0.1], [-0.01, -0.01, -0.01, -1.0]])
    g = rng.normal(size=(R, 2, n)) * np.array([[1.0, 1.0, 1.0, 10.0], [0.1, 0.1, 0.1, 0.3]])
    c = curv + 0.02 * rng.normal(size=(R, 2, n))
    free = efficient_weights(g, c)
    kept = efficient_weights(g, c, keep_share=0.75)
    eq_share = curvature_shares(np.full(n, 1 / n), c.mean(0))
    assert curvature_shares(free.alpha, c.mean(0))[1] < 0.1 * eq_share[1]       # without it: starved
    assert curvature_shares(kept.alpha, c.mean(0))[1] >= 0.75 * eq_share[1] - 1e-9
    assert kept.variance[0] < kept.variance_equal[0]                             # still narrower where it can be
    # no component with a maximum (positive curvature): equal weights
    flat = efficient_weights(g, -c)
    assert flat.alpha == pytest.approx(np.full(n, 1 / n)) and flat.components == []
    assert np.isinf(component_variances(np.full(n, 1 / n), np.ones((1, n, n)), np.ones((1, n))))[0]
    with pytest.raises(ValueError):
        efficient_weights(g[:2], c[:2])


CONFIG = {
    "name": "efficient", "seed": 4,
    "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 100.0}},
    "parameters": {"k_sec_z": {}, "c_sec_z": {}},
    "data": {"source": "experiment", "w_ref": {"k_sec_z": 330.0e3},
             "track": {"n_segments": 6, "length_m": 600.0, "speed_kmh": 300.0}},
    "spectra": {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 60},
    "identifiability": {"n_redraws": 8},
}


def test_weights_from_the_reference_date(tmp_path):
    plain = build_problem(load_config(CONFIG), Ledger(tmp_path / "a.sqlite"))
    ledger = Ledger(tmp_path / "b.sqlite")
    problem = build_problem(load_config(CONFIG | {"objective": {"plugin": "overlap", "weights": "efficient"}}), ledger)
    rec = problem.weights_record
    n = len(problem.channels)
    assert plain.weights == pytest.approx(np.full(n, 1 / n)) and plain.weights_record is None
    assert rec["method"] == "efficient" and rec["n_simulations"] == 2 * problem.q
    assert list(rec["alpha"]) == problem.channels
    assert np.array(list(rec["alpha"].values())) == pytest.approx(problem.weights)
    assert problem.weights.sum() == pytest.approx(1.0) and not np.allclose(problem.weights, 1 / n)
    assert problem.data_identity != plain.data_identity
    assert problem.objective_function.alpha == pytest.approx(problem.weights)
    # the 2q simulations at w0 ± h on the reference track are cached in the ledger
    ref = replace(problem, segments=problem.reference_segments)
    u0 = problem.to_unit(np.array([problem.w0[k] for k in problem.names]))
    h = problem.config.identifiability.step
    for u in (*(u0 + h * np.eye(problem.q)), *(u0 - h * np.eye(problem.q))):
        assert ledger.get_array(_y_sim_key(ref, u)[0] + ":y").shape == problem.reference["y_sim0"].shape
    line = weights_line({"objective_weights": rec})
    assert line.count("\n") == 2 and "Channel weights α (efficient; " in line and f"{2 * problem.q} simulations" in line
    # the same seed gives the same weights (the replicates' draws come from it)
    again = build_problem(load_config(CONFIG | {"objective": {"plugin": "overlap", "weights": "efficient"}}), ledger)
    assert np.array_equal(again.weights, problem.weights)


def test_validate_needs_a_reference_date(tmp_path, capsys):
    (tmp_path / "b.npz").write_bytes(b"")
    cfg = tmp_path / "run.yaml"
    cfg.write_text("name: e\nseed: 1\nsimulator: {plugin: exudyn-train, options: {solver: frequency}}\n"
                   "parameters: {k_sec_z: {}}\nobjective: {plugin: overlap, weights: efficient}\n"
                   "noise: {path: b.npz}\n")
    with pytest.raises(SystemExit) as exit_:
        main(["validate", str(cfg)])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and len(err.splitlines()) == 1
    assert "objective.weights" in err and "reference date" in err and "Traceback" not in err
