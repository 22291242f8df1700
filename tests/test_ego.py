"""EGO loop: EI in closed form, the paper's stop rule, determinism, quality."""

import math

import numpy as np
import pytest
from scipy.stats import norm

from suspid.optimize.ego import (EGOOptions, expected_improvement,
                        log_expected_improvement, maximize, run_ego)
from suspid.optimize.acquisition import log_ei_and_grad as _log_ei_and_grad
from suspid.errors import ConfigError, SuspidError, UnknownPluginError
from suspid.interfaces import Surrogate
from suspid.plugins.surrogates.gpy_kriging import GPyKriging
from suspid.optimize.testfunctions import FUNCTIONS

BOX = [[-1.0, 2.0], [0.0, 1.0]]


def bowl(w):
    """Concave, maximum 1 at (0.5, 0.3)."""
    return 1.0 - (w[0] - 0.5) ** 2 - 4 * (w[1] - 0.3) ** 2


def counting_cache(f):
    """``f`` behind a cache, as a ledger replay serves it: ``(cached f, list of the points computed)``."""
    cache, calls = {}, []

    def cached(w):
        key = tuple(np.round(w, 12))
        if key not in cache:
            calls.append(key)
            cache[key] = f(w)
        return cache[key]

    return cached, calls


def relative_error(name, X):
    f = FUNCTIONS[name]
    return abs(f.func(X).min() - f.f_min) / abs(f.f_min)


# -- expected improvement -------------------------------------------------------------

def test_ei_closed_form_known_values():
    # at mean == J_max the improvement is sigma * phi(0)
    assert expected_improvement(np.array([1.0]), np.array([4.0]), 1.0)[0] == pytest.approx(
        2.0 * norm.pdf(0.0))
    # no uncertainty: EI is the plain improvement
    np.testing.assert_allclose(expected_improvement(np.array([3.0, 0.0]), np.zeros(2), 1.0), [2.0, 0.0])
    mean, var, jmax = np.array([0.3, -2.0, 5.0]), np.array([0.5, 0.1, 2.0]), 0.7
    s = np.sqrt(var)
    z = (mean - jmax) / s
    expected = (mean - jmax) * norm.cdf(z) + s * norm.pdf(z)
    np.testing.assert_allclose(expected_improvement(mean, var, jmax), expected, rtol=1e-12)


def test_ei_matches_monte_carlo_for_maximisation():
    rng = np.random.default_rng(0)
    mean, sd, jmax = 1.2, 0.7, 1.5
    samples = mean + sd * rng.standard_normal(2_000_000)
    mc = np.mean(np.maximum(samples - jmax, 0.0))
    assert expected_improvement(np.array([mean]), np.array([sd ** 2]), jmax)[0] == pytest.approx(mc, rel=5e-3)


def test_log_ei_does_not_underflow():
    # z = -40: EI ~ 1e-350 underflows, its log does not and decreases smoothly
    logs = log_expected_improvement(np.array([-40.0, -41.0, -1e4]), np.ones(3), 0.0)
    assert np.all(np.isfinite(logs)) and logs[0] > logs[1] > logs[2]
    z = -30.0
    direct = math.log(norm.pdf(z) + z * norm.cdf(z)) if norm.pdf(z) + z * norm.cdf(z) > 0 else None
    approx = log_expected_improvement(np.array([z]), np.ones(1), 0.0)[0]
    if direct is not None:
        assert approx == pytest.approx(direct, rel=1e-6)


class Quadratic(Surrogate):
    """A fake surrogate with analytic mean, variance and gradients."""

    name = "quadratic-test"

    def fit(self, X, y):
        return self

    def predict(self, X):
        return -np.sum((X - 0.3) ** 2, axis=1), 0.01 + np.sum(X ** 2, axis=1) * 0.05

    def predict_gradients(self, X):
        return -2 * (X - 0.3), 0.1 * X


@pytest.mark.parametrize("u", [[0.2, 0.9], [0.9, 0.1], [0.95, 0.95]])
def test_log_ei_gradient_matches_finite_differences(u):
    model, u, jmax = Quadratic(), np.array(u), 0.05
    val, grad = _log_ei_and_grad(model, u, jmax, with_grad=True)
    h = 1e-6
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        fd = (_log_ei_and_grad(model, u + e, jmax, False)[0] - _log_ei_and_grad(model, u - e, jmax, False)[0]) / (2 * h)
        assert grad[k] == pytest.approx(fd, rel=1e-5, abs=1e-7)


# -- the loop -----------------------------------------------------------------------------

def test_max_iter_caps_the_new_points():
    res = maximize(bowl, BOX, n_initial=5, max_iter=3, tol=0.0, seed=1)
    assert res.n_initial == 5 and res.n_evaluations == 8 and res.n_iterations == 3
    assert res.stop_reason == "max_iter"
    assert res.X.shape == (8, 2) and res.y.shape == (8,)
    np.testing.assert_allclose(res.y, [bowl(x) for x in res.X])
    assert res.y_opt == res.y.max() and np.array_equal(res.x_opt, res.X[np.argmax(res.y)])


def test_stops_when_max_ei_falls_below_epsilon():
    records = []
    res = maximize(bowl, BOX, n_initial=6, max_iter=40, tol=1e-3, seed=0, callback=records.append)
    assert res.stop_reason == "ei_below_tol"
    assert res.n_evaluations < 6 + 40
    stop = records[-1]
    assert stop.phase == "stop" and stop.J is None
    ego = [r for r in records if r.phase == "ego"]
    assert len(ego) == res.n_iterations
    # eps = tol * (max J - min J) over the data at that iteration
    y_then = res.y[:stop.index]
    assert stop.epsilon == pytest.approx(1e-3 * (y_then.max() - y_then.min()))
    assert stop.EI < stop.epsilon
    assert all(r.EI >= r.epsilon for r in ego)
    assert res.y_opt > 1.0 - 1e-3


def test_records_for_the_ledger():
    records = []
    res = maximize(bowl, BOX, n_initial=4, max_iter=2, tol=0.0, seed=2, callback=records.append)
    assert [r.phase for r in records] == ["initial"] * 4 + ["ego"] * 2
    assert [r.index for r in records] == list(range(6))
    assert [r.iteration for r in records] == [0, 0, 0, 0, 1, 2]
    for r in records[4:]:
        assert r.EI > 0 and r.J_max == pytest.approx(max(res.y[:r.index]))
        assert r.hyperparameters["kernel"] == "matern52" and len(r.hyperparameters["lengthscales"]) == 2
        assert r.fit_seconds >= 0 and r.search_seconds >= 0 and r.eval_seconds >= 0
        np.testing.assert_allclose(r.x, res.X[r.index])
        np.testing.assert_allclose(r.x_unit, res.X_unit[r.index])


def test_callback_can_stop_during_the_initial_design():
    res = maximize(bowl, BOX, n_initial=5, max_iter=3, seed=0, callback=lambda r: r.index == 0)
    assert res.stop_reason == "callback" and res.n_evaluations == 1 and res.surrogate is None
    assert res.y_opt == res.y[0]


def test_same_seed_same_points_and_replay_of_a_killed_run():
    fast = dict(n_initial=5, max_iter=4, tol=0.0, n_candidates=256, n_starts=3,
                surrogate_options={"n_restarts": 1})
    a = maximize(bowl, BOX, seed=3, **fast)
    c = maximize(bowl, BOX, seed=4, **fast)
    assert not np.array_equal(a.X, c.X)

    # a run killed after 2 EGO points, replayed with cached values, retraces the
    # points of the uninterrupted run with the same seed
    cached, calls = counting_cache(bowl)
    killed = maximize(cached, BOX, seed=3, callback=lambda r: r.phase == "ego" and r.iteration == 2,
                      **fast)
    assert killed.stop_reason == "callback" and killed.n_evaluations == 7
    replay = maximize(cached, BOX, seed=3, **fast)
    np.testing.assert_array_equal(replay.X, a.X)
    np.testing.assert_array_equal(replay.y, a.y)
    assert len(calls) == 9  # 7 before the kill, 2 new ones


# -- local refinement (ego.refine, beyond the paper) ----------------------------------

U_STAR = np.array([0.62, 0.35, 0.48])
RIDGE = np.array([[30.0, 27.0, 0.0], [27.0, 30.0, 0.0], [0.0, 0.0, 10.0]])  # condition number 19


def ridge(u):
    """Concave quadratic with a correlated, flat direction (like k_sec_z with k_prim_z); max 0 at U_STAR."""
    d = np.asarray(u) - U_STAR
    return -float(d @ RIDGE @ d)


def test_refinement_climbs_the_ridge_to_the_maximiser():
    records = []
    res = maximize(ridge, [[0.0, 1.0]] * 3, n_initial=12, max_iter=0, seed=1, callback=records.append,
                   refine={"enabled": True, "max_iter": 40})
    start = res.X[np.argmax(res.y[:12])]
    assert np.max(np.abs(start - U_STAR)) > 0.05  # the design alone is far off
    assert res.refine_stop_reason in ("radius_below_min", "max_iter") and res.n_refine == res.n_iterations
    assert np.max(np.abs(res.x_opt - U_STAR)) < 0.01
    refine = [r for r in records if r.phase == "refine"]
    assert len(refine) == res.n_refine and [r.index for r in refine] == list(range(12, 12 + res.n_refine))
    assert all(r.J_max == pytest.approx(max(res.y[:r.index])) for r in refine)


@pytest.mark.parametrize("patience, expected", [(1, 4), (2, 8)])
def test_refinement_halves_the_radius_after_failures(patience, expected):
    # the best point is the maximiser itself: every step fails, the radius goes
    # 0.1 -> 0.05 -> 0.025 -> 0.0125 -> 0.00625 < 0.01 after 4 halvings
    X = np.vstack([U_STAR, np.random.default_rng(0).random((9, 3))])
    res = maximize(ridge, [[0.0, 1.0]] * 3, X_init=X, y_init=[ridge(x) for x in X], max_iter=0, seed=1,
                   refine={"enabled": True, "patience": patience})
    assert res.refine_stop_reason == "radius_below_min" and res.n_refine == expected
    np.testing.assert_array_equal(res.x_opt, U_STAR)
    assert np.max(np.abs(res.X[10:] - U_STAR)) <= 0.1 + 1e-12  # inside the first trust region


def test_refinement_leaves_the_papers_loop_unchanged():
    fast = dict(n_initial=6, max_iter=6, tol=0.0, n_candidates=256, n_starts=3, seed=2,
                surrogate_options={"n_restarts": 1})
    paper = maximize(ridge, [[0.0, 1.0]] * 3, **fast)
    refined = maximize(ridge, [[0.0, 1.0]] * 3, refine={"enabled": True, "max_iter": 5}, **fast)
    n = paper.n_evaluations
    np.testing.assert_array_equal(refined.X[:n], paper.X)
    assert refined.stop_reason == paper.stop_reason and paper.n_refine == 0 and paper.refine_stop_reason is None
    assert refined.n_refine == refined.n_evaluations - n == refined.n_function_calls - paper.n_function_calls > 0
    # the global surrogate is not the local one: refit on every point at the end
    assert refined.surrogate.model_.X.shape[0] == refined.n_evaluations


def test_refinement_after_the_ei_stop_and_its_records():
    records = []
    res = maximize(ridge, [[0.0, 1.0]] * 3, n_initial=8, max_iter=30, tol=1e-2, seed=3, callback=records.append,
                   refine={"enabled": True, "max_iter": 4}, n_candidates=256, n_starts=3)
    assert res.stop_reason == "ei_below_tol"
    phases = [r.phase for r in records if r.phase != "initial"]
    n_ego = phases.index("stop")
    assert phases == ["ego"] * n_ego + ["stop"] + ["refine"] * res.n_refine and res.n_refine >= 1
    refine = [r for r in records if r.phase == "refine"]
    assert [r.iteration for r in refine] == list(range(n_ego + 1, n_ego + 1 + res.n_refine))
    assert [r.index for r in refine] == list(range(8 + n_ego, 8 + n_ego + res.n_refine))
    assert all(r.J_max == pytest.approx(max(res.y[:r.index])) and r.hyperparameters for r in refine)


def test_refinement_without_final_refit_keeps_the_global_surrogate():
    res = maximize(ridge, [[0.0, 1.0]] * 3, n_initial=8, max_iter=3, tol=0.0, seed=3, refit_final=False,
                   refine={"enabled": True, "max_iter": 3, "n_points": 5})
    assert res.n_refine == 3
    assert res.surrogate.model_.X.shape[0] == 8 + 2  # the last fit of the paper's loop


def test_refinement_never_simulates_a_known_point_again():
    # all J equal: the local mean is flat and peaks at the centre, which is known
    calls = []

    def flat(w):
        calls.append(np.array(w))
        return 1.0

    res = maximize(flat, [[0.0, 1.0]] * 2, n_initial=5, max_iter=0, seed=0,
                   refine={"enabled": True, "max_iter": 20})
    X = np.array(calls)
    gaps = [np.max(np.abs(X[i] - X[j])) for i in range(len(X)) for j in range(i)]
    assert min(gaps) > 1e-6 and res.refine_stop_reason == "radius_below_min"


def test_refinement_killed_and_replayed_retraces_the_same_points():
    fast = dict(n_initial=6, max_iter=2, tol=0.0, n_candidates=256, n_starts=3, seed=5,
                refine={"enabled": True, "max_iter": 5})
    full = maximize(ridge, [[0.0, 1.0]] * 3, **fast)
    cached, calls = counting_cache(ridge)
    killed = maximize(cached, [[0.0, 1.0]] * 3, callback=lambda r: r.phase == "refine" and r.index == 9, **fast)
    assert killed.refine_stop_reason == "callback"
    assert killed.n_evaluations == 10
    replay = maximize(cached, [[0.0, 1.0]] * 3, **fast)
    np.testing.assert_array_equal(replay.X, full.X)
    assert len(calls) == full.n_evaluations  # nothing evaluated twice


def test_own_initial_points_and_known_values():
    X0 = np.array([[-1.0, 0.0], [2.0, 1.0], [0.0, 0.5], [1.5, 0.2], [0.5, 0.9]])
    y0 = np.array([bowl(X0[0]), np.nan, bowl(X0[2]), np.nan, bowl(X0[4])])
    calls = []
    res = maximize(lambda w: calls.append(w) or bowl(w), BOX, max_iter=2, tol=0.0, seed=0,
                   X_init=X0, y_init=y0)
    np.testing.assert_array_equal(res.X[:5], X0)
    np.testing.assert_allclose(res.y[:5], [bowl(x) for x in X0])
    assert res.n_function_calls == 4 == len(calls)  # 2 missing initial values + 2 EGO points
    assert res.n_evaluations == 7


def test_objective_in_unit_coordinates_and_a_surrogate_without_gradients():
    class NoGradients(GPyKriging):
        name = "no-gradients"

        def predict_gradients(self, X):
            raise NotImplementedError

    res = run_ego(lambda u: -np.sum((u - 0.4) ** 2), [[0.0, 1.0]] * 2,
                  ego=EGOOptions(max_iter=3, tol=0.0, n_candidates=256, n_starts=2),
                  surrogate=NoGradients(seed=0))
    assert res.n_evaluations == res.n_initial + 3
    assert np.all((res.X >= 0) & (res.X <= 1))


def test_global_random_state_is_left_alone():
    np.random.seed(99)
    state = np.random.get_state()
    maximize(bowl, BOX, n_initial=4, max_iter=1, tol=0.0, seed=0)
    assert np.array_equal(np.random.get_state()[1], state[1])


def test_user_errors_are_suspid_errors():
    with pytest.raises(ConfigError):
        maximize(bowl, [[1.0, 0.0]], max_iter=1)
    with pytest.raises(ConfigError, match="outside"):
        maximize(bowl, BOX, X_init=np.array([[5.0, 0.5], [0.0, 0.5]]), max_iter=1)
    with pytest.raises(ConfigError, match="ego.max_iter"):
        maximize(bowl, BOX, max_iter=-1)
    with pytest.raises(ConfigError, match="ego.n_startz"):
        maximize(bowl, BOX, max_iter=1, n_startz=3)
    with pytest.raises(UnknownPluginError, match="gpy-kriging"):
        maximize(bowl, BOX, max_iter=1, surrogate="no-such-model")
    with pytest.raises(SuspidError, match="finite"):
        maximize(lambda w: float("nan"), BOX, n_initial=3, max_iter=1)


# -- quality on standard functions (paper-independent) -------------------------------------

def solve_to_one_percent(name, budget, seed):
    """EGO with the defaults (tol = 0 so that only the target or the budget ends it);
    the callback stops the run once the best point is within 1 %."""
    f = FUNCTIONS[name]
    best = [np.inf]

    def reached(record):
        best[0] = min(best[0], -record.J) if record.J is not None else best[0]
        return abs(best[0] - f.f_min) / abs(f.f_min) <= 0.01

    from suspid.optimize.design import default_n_initial

    return maximize(lambda x: -f.func(x), f.bounds, max_iter=budget - default_n_initial(f.q),
                    tol=0.0, seed=seed, callback=reached)


def test_branin_minimum_within_one_percent():
    res = solve_to_one_percent("branin", budget=40, seed=0)
    assert res.stop_reason == "callback"
    assert relative_error("branin", res.X) <= 0.01


@pytest.mark.slow
def test_hartmann6_minimum_within_one_percent():
    res = solve_to_one_percent("hartmann6", budget=130, seed=0)
    assert res.stop_reason == "callback"
    assert relative_error("hartmann6", res.X) <= 0.01


# -- exploration instead of a step that teaches nothing (budget mode) ------------------------

def test_stalled_steps_are_recognised():
    from suspid.optimize.loop import EIProposer

    p = EIProposer(None, EGOOptions(explore_tol=1e-4, explore_distance=1e-3))
    U, y = np.array([[0.2, 0.2], [0.8, 0.5]]), np.array([0.0, 2.0])
    assert p.stalled(np.array([0.8005, 0.5]), 0.0, U, y)  # next to an evaluated point
    assert p.stalled(np.array([0.5, 0.5]), math.log(1e-4 * 2.0) - 0.1, U, y)  # EI < 1e-4 (max J - min J)
    assert not p.stalled(np.array([0.5, 0.5]), math.log(1e-4 * 2.0) + 0.1, U, y)
    off = EIProposer(None, EGOOptions(explore_tol=0.0, explore_distance=0.0))
    assert not off.stalled(np.array([0.8, 0.5]), -1e3, U, y)


def test_budget_mode_never_evaluates_a_known_point_again():
    # tol = 0 runs to max_iter: once the bowl's maximum is found EI keeps pointing at it;
    # with the exploration options on, those steps become random points instead of copies
    res = maximize(bowl, BOX, n_initial=5, max_iter=25, tol=0.0, seed=0, n_candidates=256, n_starts=3,
                   explore_tol=1e-4, explore_distance=1e-3)
    U = res.X_unit
    gaps = np.max(np.abs(U[:, None] - U[None]), axis=-1)[np.triu_indices(len(U), 1)]
    assert gaps.min() >= 1e-3
    assert res.y_opt > 1.0 - 1e-3


def test_set_aside_searches_outside_the_incumbents_basin():
    from suspid.optimize.loop import EIProposer

    U = np.random.default_rng(0).random((12, 2))
    y = np.array([bowl([3 * u[0] - 1, u[1]]) for u in U])
    model = GPyKriging(seed=0).fit(U, y)
    p = EIProposer(model, EGOOptions())
    p._set_aside(U, y, model)
    centre, ls = p.basins[0]
    np.testing.assert_array_equal(centre, U[np.argmax(y)])
    np.testing.assert_allclose(ls, model.hyperparameters_["lengthscales"])
    p.basins = [(centre, np.full(2, 0.2))]  # a basin that leaves part of the box to search
    u, _ = p._search(model, U, y, y, float(y.max()), np.random.default_rng(1))
    assert p._outside(u[None, :])[0] and np.sqrt(np.sum(((u - centre) / 0.2) ** 2)) >= 1.0


# -- budget mode: warped J and a cycle of exploitation steps ---------------------------

def test_warp_values_keeps_the_order_and_removes_a_long_tail():
    from scipy.stats import skew

    from suspid.optimize.loop import warp_values

    y = -np.exp(np.random.default_rng(0).standard_normal(400))  # J with a long tail of poor values
    w = warp_values(y)
    np.testing.assert_array_equal(np.argsort(w), np.argsort(y))
    assert skew(y) < -4.0 and abs(skew(w)) < 0.5
    np.testing.assert_array_equal(warp_values(np.full(5, 3.0)), np.zeros(5))


def _bowl_state(n):
    from suspid.optimize.loop import LoopState

    state = LoopState(q=2)
    for u in np.random.default_rng(0).random((n, 2)):
        state.add(u, bowl([3 * u[0] - 1, u[1]]))  # maximum 1 at u = (0.5, 0.3)
    return state


def test_budget_mode_exploits_every_third_step():
    from suspid.optimize.loop import EXPLOIT_PERIOD, EIBelowTolerance, EIProposer

    p = EIProposer(GPyKriging(seed=0), EGOOptions(tol=0.0))
    state = _bowl_state(8)
    steps = [p.propose(state, 10, EIBelowTolerance(0.0)).points[0][0] for _ in range(EXPLOIT_PERIOD)]
    slope = [np.abs(p._warped.predict_gradients(u[None, :])[0]).max() for u in steps]
    # EI steps go where the model is unsure; the third step is a stationary point of the mean
    assert min(slope[:-1]) > 0.1 and slope[-1] < 1e-3
    assert np.allclose(steps[-1], [0.5, 0.3], atol=0.15)  # near the bowl's maximum, from 8 points


def test_near_miss_is_a_cycle_exploitation_step_that_missed_by_less_than_explore_tol():
    from suspid.optimize.loop import EIProposer

    p = EIProposer(None, EGOOptions(tol=0.0))  # budget mode, explore_tol = 1e-4
    U = np.array([[0.1, 0.1], [0.5, 0.5], [0.9, 0.9]])
    assert not p.near_miss(U, np.array([0.0, 1.0, 1.0 - 1e-5]))  # no exploitation step yet
    p._exploited = (U[2].copy(), 1.0)  # (0.9, 0.9) was proposed when J_max was 1; range of J: 1
    assert p.near_miss(U, np.array([0.0, 1.0, 1.0 - 0.5e-4]))  # missed by 0.5e-4 < 1e-4 * 1
    assert not p.near_miss(U, np.array([0.0, 1.0, 1.0 - 2e-4]))  # missed by more
    assert not p.near_miss(U, np.array([0.0, 1.0, 1.0 + 1e-5]))  # improved
    assert not p.near_miss(U[:2], np.array([0.0, 1.0]))  # its evaluation failed


@pytest.mark.parametrize("miss, exploits", [(0.5e-4, True), (0.1, False)])
def test_budget_mode_exploits_again_after_a_near_miss(miss, exploits):
    from suspid.optimize.loop import EXPLOIT_PERIOD, EIBelowTolerance, EIProposer

    p = EIProposer(GPyKriging(seed=0), EGOOptions(tol=0.0))
    state = _bowl_state(8)
    for _ in range(EXPLOIT_PERIOD):  # the last one is the cycle's exploitation step
        u = p.propose(state, 10, EIBelowTolerance(0.0)).points[0][0]
    y = state.y_array
    state.add(u, float(y.max()) - miss * float(y.max() - y.min()))
    u_next = p.propose(state, 10, EIBelowTolerance(0.0)).points[0][0]
    slope = np.abs(p._warped.predict_gradients(u_next[None, :])[0]).max()
    # after a near miss a stationary point of the mean again; after a clear miss, EI's choice
    assert (slope < 1e-3) == exploits


def test_paper_mode_never_exploits():
    from suspid.optimize.acquisition import maximize_ei
    from suspid.optimize.loop import EXPLOIT_PERIOD, EIBelowTolerance, EIProposer

    opts = EGOOptions()  # tol = 1e-4 = explore_tol: the paper's loop
    p = EIProposer(GPyKriging(seed=0), opts)
    p.n_steps = EXPLOIT_PERIOD - 1
    state = _bowl_state(15)
    u = p.propose(state, 10, EIBelowTolerance(0.0)).points[0][0]
    rng = np.random.default_rng([opts.seed, 1, state.n_points])
    u_ei, _ = maximize_ei(p.surrogate, state.U_array, state.y_array, float(state.y_array.max()), opts, rng)
    np.testing.assert_array_equal(u, u_ei)
