"""Sensitivity from the metamodel: Sobol' indices and length-scales."""

import numpy as np
import pytest

from suspid.optimize.design import DesignOptions, make_design
from suspid.errors import ConfigError
from suspid.plugins.surrogates.gpy_kriging import GPyKriging
from suspid.method.sensitivity import sobol_indices, surrogate_sensitivity
from suspid.optimize.testfunctions import ishigami, ishigami_indices


def test_ishigami_indices_match_the_analytic_values():
    S_ref, ST_ref = ishigami_indices()
    res = sobol_indices(lambda U: ishigami(-np.pi + 2 * np.pi * U), 3, n=2 ** 14, seed=0,
                        n_bootstrap=50)
    np.testing.assert_allclose(res.first_order, S_ref, atol=0.02)
    np.testing.assert_allclose(res.total, ST_ref, atol=0.02)
    assert res.first_order_ci.shape == (3, 2) and res.total_ci.shape == (3, 2)
    assert np.all(res.first_order_ci[:, 0] <= res.first_order_ci[:, 1])
    assert res.n == 2 ** 14


def test_linear_model_has_known_indices():
    # y = w0 + 2 w1 with uniform inputs: variances 1/12 and 4/12, no interaction
    res = sobol_indices(lambda U: U[:, 0] + 2 * U[:, 1], 3, n=1024, seed=1, names=["a", "b", "c"])
    np.testing.assert_allclose(res.first_order, [0.2, 0.8, 0.0], atol=1e-2)
    np.testing.assert_allclose(res.total, [0.2, 0.8, 0.0], atol=1e-2)
    d = res.as_dict()
    assert set(d["parameters"]) == {"a", "b", "c"}
    assert d["parameters"]["c"]["total"] == pytest.approx(0.0, abs=1e-12)


def test_seeded():
    f = lambda U: np.sin(3 * U[:, 0]) * U[:, 1]  # noqa: E731
    a, b = sobol_indices(f, 2, n=256, seed=4), sobol_indices(f, 2, n=256, seed=4)
    np.testing.assert_array_equal(a.total, b.total)


def test_sensitivity_of_a_fitted_surrogate_and_its_lengthscales():
    U = make_design(DesignOptions(n_initial=40, seed=0, iterations=20), 3)
    bounds = np.array([[1e5, 3e5], [0.0, 10.0], [-1.0, 1.0]])
    X = bounds[:, 0] + U * (bounds[:, 1] - bounds[:, 0])
    # additive, Var sin(2 pi U) = 1/2: S = ST = (0.2, 0.8, 0); the third parameter
    # is not identifiable from J
    y = np.sin(2 * np.pi * U[:, 0]) + 2 * np.sin(2 * np.pi * U[:, 1])
    model = GPyKriging(seed=0).fit(X, y)
    res = surrogate_sensitivity(model, 3, bounds=bounds, n=2048, seed=0)
    np.testing.assert_allclose(res.first_order, [0.2, 0.8, 0.0], atol=0.03)
    np.testing.assert_allclose(res.total, [0.2, 0.8, 0.0], atol=0.03)
    # length-scales relative to the box: the irrelevant one is by far the longest
    assert res.lengthscales.shape == (3,)
    assert res.lengthscales[2] > 3 * max(res.lengthscales[:2])
    assert "lengthscale" in res.as_dict()["parameters"]["w2"]


def test_bad_arguments():
    with pytest.raises(ConfigError):
        sobol_indices(lambda U: U[:, 0], 0)
    with pytest.raises(ConfigError):
        sobol_indices(lambda U: U[:, 0], 2, names=["only-one"])
    with pytest.raises(ConfigError):
        surrogate_sensitivity(GPyKriging(), 2, bounds=[[0, 1]])
