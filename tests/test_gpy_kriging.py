"""The ``gpy-kriging`` surrogate plugin."""

import warnings

import numpy as np
import pytest

from suspid import registry
from suspid.errors import ConfigError
from suspid.interfaces import Surrogate
from suspid.plugins.surrogates import gpy_kriging
from suspid.plugins.surrogates.gpy_kriging import ConditioningWarning, GPyKriging


def smooth(X):
    return np.sin(3 * X[:, 0]) + 0.5 * np.cos(2 * X[:, 1])


@pytest.fixture(scope="module")
def data():
    rng = np.random.default_rng(0)
    X = rng.random((25, 2))
    return X, smooth(X)


@pytest.fixture(scope="module")
def fitted(data):
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConditioningWarning)  # clean data: no jitter needed
        return GPyKriging(seed=0).fit(*data)


def test_registered_through_the_entry_point():
    assert registry.get("surrogate", "gpy-kriging") is GPyKriging
    assert issubclass(GPyKriging, Surrogate)
    registered = []
    gpy_kriging.suspid_register_surrogates(register=registered.append)
    assert registered == [GPyKriging]


def test_constructor_only_stores_and_fit_validates_options(data):
    model = GPyKriging(kernel="cubic", bogus=1)  # no error yet: constructors store
    assert model.options == {"kernel": "cubic", "bogus": 1}
    with pytest.raises(ConfigError, match="surrogate.options"):
        model.fit(*data)
    with pytest.raises(ConfigError, match="noise_bounds"):
        GPyKriging(noise_bounds=(1.0, 0.1)).fit(*data)


def test_fit_returns_self_and_interpolates(fitted, data):
    X, y = data
    mean, var = fitted.predict(X)
    assert mean.shape == var.shape == (25,)
    np.testing.assert_allclose(mean, y, atol=1e-6)
    assert np.all(var >= 0) and np.all(var < 1e-8 * np.var(y))
    Xt = np.random.default_rng(1).random((200, 2))
    mean_t, var_t = fitted.predict(Xt)
    assert np.sqrt(np.mean((mean_t - smooth(Xt)) ** 2)) < 0.05
    assert np.all(var_t > 0)


def test_predictions_match_gpy_and_gradients_match_finite_differences(fitted):
    Xt = np.random.default_rng(2).random((5, 2))
    Xs = (Xt - fitted.x_lower_) / fitted.x_range_
    mu, var = fitted.model_.predict_noiseless(Xs)
    mean, variance = fitted.predict(Xt)
    # same GP formulas; they differ by ~cond(K) * 1e-16 (GPy inverts K explicitly, we use Cholesky)
    scale = fitted.y_std_
    np.testing.assert_allclose(mean, mu[:, 0] * scale + fitted.y_mean_, atol=1e-4 * scale)
    np.testing.assert_allclose(variance, var[:, 0] * scale ** 2, rtol=1e-3, atol=1e-6 * scale ** 2)
    dmean, dvar = fitted.predict_gradients(Xt)
    assert dmean.shape == dvar.shape == (5, 2)
    h = 1e-5  # the fit is ill-conditioned (cond ~1e11): rounding limits finite differences
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        (mp, vp), (mm, vm) = fitted.predict(Xt + e), fitted.predict(Xt - e)
        np.testing.assert_allclose(dmean[:, k], (mp - mm) / (2 * h), rtol=1e-4, atol=1e-6)
        np.testing.assert_allclose(dvar[:, k], (vp - vm) / (2 * h), rtol=1e-3, atol=1e-7)


@pytest.mark.parametrize("kernel", ["matern52", "rbf"])
def test_inputs_and_outputs_in_any_units(kernel):
    rng = np.random.default_rng(3)
    U = rng.random((20, 2))
    X = np.column_stack([1e5 + 2e5 * U[:, 0], -3e-3 + 6e-3 * U[:, 1]])  # SI-like scales
    y = 1e3 * smooth(U) + 7.0
    model = GPyKriging(kernel=kernel, seed=1).fit(X, y)
    mean, _ = model.predict(X)
    np.testing.assert_allclose(mean, y, atol=1e-3 * np.std(y))
    assert model.lengthscales_.shape == (2,)
    # length-scales are reported in the units of X
    assert model.lengthscales_[0] > 1e3 and model.lengthscales_[1] < 1.0
    hp = model.hyperparameters_
    assert hp["kernel"] == kernel and len(hp["lengthscales"]) == 2 and hp["variance"] > 0


def test_irrelevant_input_gets_a_long_lengthscale():
    rng = np.random.default_rng(4)
    X = rng.random((30, 3))
    y = np.sin(4 * X[:, 0]) + np.cos(5 * X[:, 1])
    model = GPyKriging(seed=0).fit(X, y)
    assert model.lengthscales_[2] > 2 * max(model.lengthscales_[0], model.lengthscales_[1])
    # the irrelevant one sits at the upper bound, 2 scaled units (x its data range)
    x_range = X[:, 2].max() - X[:, 2].min()
    assert model.lengthscales_[2] == pytest.approx(2.0 * x_range, rel=1e-3)


def test_same_seed_same_fit_and_global_random_state_untouched(data):
    np.random.seed(1234)
    before = np.random.get_state()
    a = GPyKriging(seed=5).fit(*data)
    after = np.random.get_state()
    assert before[0] == after[0] and np.array_equal(before[1], after[1]) and before[2:] == after[2:]
    b = GPyKriging(seed=5).fit(*data)
    np.testing.assert_array_equal(a.lengthscales_, b.lengthscales_)
    assert a.variance_ == b.variance_


def test_duplicate_points_fit_without_crashing():
    rng = np.random.default_rng(5)
    X = rng.random((12, 2))
    X = np.vstack([X, X[:4], X[:2] + 1e-12])  # exact and near duplicates
    y = smooth(X)
    with pytest.warns(ConditioningWarning, match="near-duplicate"):
        model = GPyKriging(seed=0).fit(X, y)
    mean, var = model.predict(X)
    assert np.all(np.isfinite(mean)) and np.all(var >= 0)
    np.testing.assert_allclose(mean, y, atol=1e-3)


def test_conflicting_duplicates_raise_the_noise_floor():
    X = np.array([[0.1, 0.2], [0.1, 0.2], [0.5, 0.5], [0.9, 0.1], [0.3, 0.8], [0.7, 0.7]])
    y = np.array([1.0, 2.0, 0.0, 0.5, -0.5, 0.3])  # two values at one point
    with pytest.warns(ConditioningWarning, match="noise floor raised"):
        model = GPyKriging(seed=0).fit(X, y)
    mean, var = model.predict(X[:1])
    assert np.isfinite(mean[0]) and 0.5 < mean[0] < 2.5
    assert model.noise_variance_ > 1e-3


def test_cluster_of_nearly_coincident_points_is_handled():
    rng = np.random.default_rng(6)
    X = np.vstack([rng.random((8, 3)), 0.5 + 1e-9 * rng.random((15, 3))])
    y = X.sum(axis=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConditioningWarning)
        model = GPyKriging(seed=0).fit(X, y)
    mean, var = model.predict(rng.random((10, 3)))
    assert np.all(np.isfinite(mean)) and np.all(np.isfinite(var))


def test_a_failing_restart_does_not_kill_the_fit(data, monkeypatch):
    import GPy

    calls = {"n": 0}
    original = GPy.models.GPRegression.optimize

    def flaky(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] % 2 == 1:
            raise np.linalg.LinAlgError("not positive definite")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(GPy.models.GPRegression, "optimize", flaky)
    model = GPyKriging(seed=0, n_restarts=3).fit(*data)
    assert model.n_failed_restarts_ == 2
    np.testing.assert_allclose(model.predict(data[0])[0], data[1], atol=1e-3)


def test_when_every_start_fails_the_fit_still_returns(data, monkeypatch):
    import GPy

    def broken(self, *args, **kwargs):
        raise FloatingPointError("overflow")

    monkeypatch.setattr(GPy.models.GPRegression, "optimize", broken)
    with pytest.warns(ConditioningWarning, match="failed"):
        model = GPyKriging(seed=0, n_restarts=1).fit(*data)
    mean, _ = model.predict(data[0])
    assert np.all(np.isfinite(mean))


def test_noise_options():
    rng = np.random.default_rng(7)
    X = rng.random((40, 1))
    f = np.sin(6 * X[:, 0])
    y = f + 0.1 * rng.standard_normal(40)
    est = GPyKriging(noise="estimated", seed=0).fit(X, y)
    assert 0.1 ** 2 / 4 < est.noise_variance_ < 0.1 ** 2 * 4
    nug = GPyKriging(noise="nugget", nugget=1e-2).fit(X, y)
    assert nug.noise_variance_ == pytest.approx(1e-2 * np.var(y), rel=1e-6)
    # noise-free predictions: the latent variance is below the noise level at the data
    assert np.all(est.predict(X)[1] < est.noise_variance_)


def test_bad_arrays_are_rejected():
    with pytest.raises(ValueError, match="shape"):
        GPyKriging().fit(np.zeros(5), np.zeros(5))
    with pytest.raises(ValueError, match="finite"):
        GPyKriging().fit(np.zeros((3, 1)), np.array([0.0, np.nan, 1.0]))
    with pytest.raises(RuntimeError, match="fit"):
        GPyKriging().predict(np.zeros((1, 2)))
