"""Surrogate `sklearn-gp`: the conformance kit, seeding from the config, EGO on Branin."""

import numpy as np

import suspid.registry as registry
from suspid.config import load_config
from suspid.infra.seeds import seed_for
from suspid.optimize.design import default_n_initial
from suspid.optimize.ego import maximize
from suspid.optimize.testfunctions import FUNCTIONS
from suspid.plugins.surrogates.sklearn_gp import SklearnGP
from suspid.testing import check_surrogate


def test_registered_and_conformant():
    registry.reset()
    assert registry.get("surrogate", "sklearn-gp") is SklearnGP
    check_surrogate(SklearnGP)


def test_noise_free_variance_vanishes_at_the_data_and_fits_are_seeded():
    rng = np.random.default_rng(0)
    X = rng.random((15, 3))
    y = np.sin(4 * X[:, 0]) + X[:, 1] ** 2
    a, b = SklearnGP(seed=3).fit(X, y), SklearnGP(seed=3).fit(X, y)
    assert a.hyperparameters_ == b.hyperparameters_
    mean, var = a.predict(X)
    np.testing.assert_allclose(mean, y, atol=1e-2 * np.ptp(y))
    assert np.all(var <= 1e-3 * np.var(y)) and a.lengthscales_.shape == (3,)


def test_seed_derives_from_the_run_seed(tmp_path):
    cfg = load_config({"seed": 11, "surrogate": {"plugin": "sklearn-gp"},
                       "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency"}},
                       "output": {"dir": str(tmp_path)}})
    assert cfg.surrogate.options["seed"] == seed_for(11, "surrogate")


def test_ego_reaches_the_branin_minimum_within_one_percent_in_40_calls():
    """As gpy-kriging does (tests/test_ego.py): EGO with tol 0 stops once the best point is within 1 %."""
    f = FUNCTIONS["branin"]
    best = [np.inf]

    def reached(record):
        best[0] = min(best[0], -record.J) if record.J is not None else best[0]
        return abs(best[0] - f.f_min) / abs(f.f_min) <= 0.01

    res = maximize(lambda x: -f.func(x), f.bounds, max_iter=40 - default_n_initial(f.q), tol=0.0, seed=0,
                   surrogate="sklearn-gp", callback=reached)
    assert res.stop_reason == "callback" and res.n_evaluations <= 40
    assert abs(f.func(res.X).min() - f.f_min) / abs(f.f_min) <= 0.01
