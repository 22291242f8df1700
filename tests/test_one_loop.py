"""The one loop's pieces: the unit cube as the surrogate's input transform, the loop state the analysis reads."""

from __future__ import annotations

import numpy as np

from suspid.optimize.design import to_unit
from suspid.optimize.loop import LoopOutcome
from suspid.optimize.normalize import Normalized
from suspid.optimize.options import make_surrogate

BOUNDS = np.array([[1.0e5, 9.0e5], [2.0e3, 4.0e4], [-3.0, 5.0]])


def _points(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    X = BOUNDS[:, 0] + rng.random((n, 3)) * (BOUNDS[:, 1] - BOUNDS[:, 0])
    U = to_unit(X, BOUNDS)
    return X, np.sin(3 * U[:, 0]) - (U[:, 1] - 0.4) ** 2 + 0.2 * U[:, 2]


def test_normalized_fits_the_plugin_on_the_unit_cube_bit_for_bit():
    """Fitted on SI points, the plugin sees exactly the floats of the caller's own to_unit: the same
    model, the same predictions (==), in SI through the transform and in the cube through ``cube``."""
    X, y = _points(12, 0)
    Xt, _ = _points(5, 1)
    own = make_surrogate("gpy-kriging", {"n_restarts": 0}, 3).fit(to_unit(X, BOUNDS), y)
    boxed = Normalized(make_surrogate("gpy-kriging", {"n_restarts": 0}, 3), BOUNDS).fit(X, y)
    assert boxed.hyperparameters_ == own.hyperparameters_
    for a, b in zip(boxed.predict(Xt), own.predict(to_unit(Xt, BOUNDS))):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(boxed.predict(Xt[0]), boxed.cube.predict(to_unit(Xt[:1], BOUNDS))):
        np.testing.assert_array_equal(a, b)


def test_loop_state_of_points_and_its_fitted_surrogate():
    """The state of a loop without a model: failed points (NaN) left out, the best point, m0 among the points
    with a value; the surrogate the analysis reads is fitted on exactly those points in the cube."""
    X, y = _points(9, 2)
    y[[1, 4]] = np.nan
    best = int(np.nanargmax(y))
    state = LoopOutcome.of_points(X[best], y[best], X, y, 5, "budget", BOUNDS)
    assert state.n_evaluations == 7 and state.n_function_calls == 9 and state.n_initial == 5
    assert state.n_iterations == 2 and state.X_failed.shape == (2, 3) and state.stop_reason == "budget"
    np.testing.assert_array_equal(state.X_unit, to_unit(X[np.isfinite(y)], BOUNDS))
    fitted = state.fitted_surrogate(make_surrogate("gpy-kriging", {"n_restarts": 0}, 1))
    own = make_surrogate("gpy-kriging", {"n_restarts": 0}, 1).fit(state.X_unit, state.y)
    for a, b in zip(fitted.cube.predict(state.X_unit), own.predict(state.X_unit)):
        np.testing.assert_array_equal(a, b)
    assert LoopOutcome.of_points(X[0], y[0], X[:3], np.array([y[0], np.nan, np.nan]), 3, "budget",
                                 BOUNDS).fitted_surrogate(make_surrogate("gpy-kriging")) is None   # < 2 points
