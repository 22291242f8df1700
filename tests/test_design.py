"""Initial designs: maximin LHS yardstick, named designs, scaling."""

import numpy as np
import pytest
from pydantic import ValidationError
from scipy.stats import qmc

from suspid.optimize.design import (DESIGNS, DesignOptions, check_bounds, default_n_initial, from_unit,
                           make_design, maximin_lhs, min_distance, phi_p, to_unit)
from suspid.errors import ConfigError


def is_centred_lhs(X):
    n = X.shape[0]
    centres = (np.arange(n) + 0.5) / n
    return all(np.allclose(np.sort(X[:, k]), centres) for k in range(X.shape[1]))


@pytest.fixture(scope="module")
def yardstick_design():
    return make_design(DesignOptions(n_initial=50, seed=0), 5)


def test_maximin_lhs_meets_the_yardstick(yardstick_design):
    # 50 points in [0, 1]^5: best-of-1000 random LHS ~0.30, ESE ~0.49; we require >= 0.45
    X = yardstick_design
    assert X.shape == (50, 5)
    assert is_centred_lhs(X)
    assert min_distance(X) >= 0.45


def test_maximin_lhs_beats_best_of_random_draws(yardstick_design):
    rng = np.random.default_rng(3)
    draws = [qmc.LatinHypercube(5, rng=rng).random(50) for _ in range(200)]
    assert min_distance(yardstick_design) > max(min_distance(X) for X in draws) + 0.1
    assert phi_p(yardstick_design) < min(phi_p(X) for X in draws)


def test_design_is_deterministic_for_a_seed():
    a = maximin_lhs(8, 3, np.random.default_rng(7), iterations=20)
    b = maximin_lhs(8, 3, np.random.default_rng(7), iterations=20)
    c = maximin_lhs(8, 3, np.random.default_rng(8), iterations=20)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


@pytest.mark.parametrize("method", sorted(DESIGNS))
def test_every_named_design_fills_the_unit_cube(method):
    X = make_design(DesignOptions(method=method, n_initial=20, seed=0), 4)
    assert X.shape == (20, 4)
    assert np.all((X >= 0) & (X <= 1))
    assert min_distance(X) > 0


def test_small_designs():
    assert make_design(DesignOptions(n_initial=2), 1).shape == (2, 1)
    X = make_design(DesignOptions(n_initial=5), 1)
    np.testing.assert_allclose(np.sort(X[:, 0]), [0.1, 0.3, 0.5, 0.7, 0.9])


def test_default_n_initial_rule():
    assert default_n_initial(2) == make_design(None, 2).shape[0]
    assert all(default_n_initial(q) >= q + 1 for q in range(1, 12))
    with pytest.raises(ConfigError):
        default_n_initial(0)


def test_unknown_design_lists_the_available_ones():
    with pytest.raises(ConfigError, match="maximin-lhs") as info:
        make_design(DesignOptions(method="latin-square"), 2)
    assert "design.method" in str(info.value)


def test_design_options_reject_unknown_keys():
    with pytest.raises(ValidationError):
        DesignOptions(n_inital=10)
    with pytest.raises(ValidationError):
        DesignOptions(n_initial=1)


def test_criteria_on_known_points():
    X = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 2.0]])
    assert min_distance(X) == pytest.approx(1.0)
    d = np.array([1.0, 2.0, np.sqrt(5.0)])
    assert phi_p(X, p=2) == pytest.approx(np.sum(d ** -2.0) ** 0.5)
    assert min_distance(X[:1]) == np.inf


def test_scaling_round_trip_and_bounds_checks():
    bounds = check_bounds([[1e5, 3e5], [-2.0, 2.0]])
    U = np.array([[0.0, 0.5], [1.0, 0.25]])
    X = from_unit(U, bounds)
    np.testing.assert_allclose(X, [[1e5, 0.0], [3e5, -1.0]])
    np.testing.assert_allclose(to_unit(X, bounds), U)
    for bad in ([[1.0, 1.0]], [[0.0, np.inf]], [1.0, 2.0], [[2.0, 1.0], [0.0, 1.0]]):
        with pytest.raises(ConfigError):
            check_bounds(bad)
