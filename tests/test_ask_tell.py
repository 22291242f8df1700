"""The EGO loop driven from outside by ask/tell: the same run as ``maximize``, bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from suspid.errors import SuspidError
from suspid.optimize.ego import EGO, maximize, options_for
from suspid.optimize.testfunctions import FUNCTIONS

BRANIN = FUNCTIONS["branin"]


def neg_branin(x):
    return -float(BRANIN.func(np.asarray(x)))


CASES = {
    "paper loop, EI stop": dict(n_initial=6, max_iter=30, tol=1e-3, seed=0),
    "paper loop, max_iter": dict(n_initial=5, max_iter=6, tol=0.0, seed=1),
    "refine": dict(n_initial=6, max_iter=4, tol=0.0, seed=2, refine={"enabled": True, "max_iter": 5}),
    "batch 3": dict(n_initial=6, max_iter=7, tol=0.0, seed=3, batch=3),
    "batch 2 and refine": dict(n_initial=5, max_iter=4, tol=0.0, seed=4, batch=2,
                               refine={"enabled": True, "max_iter": 3}),
}


def drive(kwargs, *, reverse=False, records=None):
    """The outside process: ask for points, evaluate them all, tell the values (in reverse order if asked)."""
    ego, design, surrogate = options_for(**kwargs)
    opt = EGO(BRANIN.bounds, ego=ego, design=design, surrogate=surrogate,
              callback=records.append if records is not None else None)
    n_asks = 0
    while not opt.done:
        X = opt.ask()
        assert X.ndim == 2 and X.shape[1] == 2 and len(X) >= 1
        np.testing.assert_array_equal(opt.ask(), X)  # asking again before telling changes nothing
        order = np.arange(len(X))[::-1] if reverse else np.arange(len(X))
        opt.tell(X[order], [neg_branin(x) for x in X[order]])
        n_asks += 1
    assert opt.ask().shape == (0, 2)
    return opt.result(), n_asks


@pytest.mark.parametrize("case", list(CASES))
def test_ask_tell_reproduces_maximize_bit_for_bit(case):
    kwargs = CASES[case]
    rec_a, rec_b = [], []
    ref = maximize(neg_branin, BRANIN.bounds, callback=rec_a.append, **kwargs)
    res, n_asks = drive(kwargs, reverse="batch" in case, records=rec_b)
    np.testing.assert_array_equal(res.X, ref.X)
    np.testing.assert_array_equal(res.y, ref.y)
    np.testing.assert_array_equal(res.x_opt, ref.x_opt)
    assert res.y_opt == ref.y_opt
    assert (res.stop_reason, res.refine_stop_reason, res.n_refine) == \
        (ref.stop_reason, ref.refine_stop_reason, ref.n_refine)
    assert (res.n_initial, res.n_evaluations, res.n_function_calls) == \
        (ref.n_initial, ref.n_evaluations, ref.n_function_calls)
    assert [(r.phase, r.index, r.iteration, r.J, r.log_EI, r.J_max, r.epsilon) for r in rec_b] == \
        [(r.phase, r.index, r.iteration, r.J, r.log_EI, r.J_max, r.epsilon) for r in rec_a]
    assert [r.hyperparameters for r in rec_b] == [r.hyperparameters for r in rec_a]
    np.testing.assert_array_equal(res.surrogate.model_.X, ref.surrogate.model_.X)
    if "batch" in case:  # whole batches were asked at once
        assert n_asks < 1 + res.n_iterations
    if case == "paper loop, EI stop":
        assert res.stop_reason == "ei_below_tol" and rec_b[-1].phase == "stop"


def test_same_seed_same_run_other_seed_other_run():
    kwargs = dict(n_initial=5, max_iter=4, tol=0.0, n_candidates=256, n_starts=3)
    a, _ = drive(dict(kwargs, seed=7))
    b, _ = drive(dict(kwargs, seed=7))
    c, _ = drive(dict(kwargs, seed=8))
    np.testing.assert_array_equal(a.X, b.X)
    np.testing.assert_array_equal(a.y, b.y)
    assert not np.array_equal(a.X, c.X)


def test_failed_points_are_kept_out_and_not_asked_again():
    ego, design, surrogate = options_for(n_initial=6, max_iter=5, tol=0.0, seed=5, n_candidates=256, n_starts=3)
    opt = EGO(BRANIN.bounds, ego=ego, design=design, surrogate=surrogate)
    X0 = opt.ask()
    assert opt.phase == "initial" and len(X0) == 6
    values = [neg_branin(x) for x in X0]
    values[2] = float("nan")
    opt.tell(X0, values)
    X1 = opt.ask()
    assert opt.phase == "ego" and len(X1) == 1
    opt.tell(X1, [None])  # the simulation of the first EGO point failed
    while not opt.done:
        X = opt.ask()
        assert np.min(np.abs(X - X1).max(axis=1)) > 1e-6  # not proposed again
        opt.tell(X, [neg_branin(x) for x in X])
    res = opt.result()
    assert res.n_initial == 5 and res.n_evaluations == 5 + 4  # the failed EGO point used the budget
    assert res.n_function_calls == 6 + 5 and res.stop_reason == "max_iter"
    np.testing.assert_array_equal(res.X_failed, np.vstack([X0[2], X1[0]]))
    assert not any(np.array_equal(x, X0[2]) for x in res.X)


def test_known_values_partial_tells_and_wrong_points():
    X_init = np.array([[-5.0, 0.0], [10.0, 15.0], [0.0, 5.0], [5.0, 10.0], [2.0, 2.0]])
    y_init = [neg_branin(X_init[0]), math.nan, neg_branin(X_init[2]), math.nan, math.nan]
    records = []
    ego, _, surrogate = options_for(max_iter=2, tol=0.0, seed=0, n_candidates=256, n_starts=3)
    opt = EGO(BRANIN.bounds, ego=ego, surrogate=surrogate, X_init=X_init, y_init=y_init, callback=records.append)
    X = opt.ask()
    np.testing.assert_array_equal(X, X_init[[1, 3, 4]])  # the points without a value
    assert [r.index for r in records] == [0]  # index 1 still missing: records wait
    with pytest.raises(SuspidError, match="not one that ask"):
        opt.tell([[1.0, 1.0]], [0.0])
    with pytest.raises(SuspidError, match="not one that ask"):   # no tolerance: a point is the one ask returned
        opt.tell([np.nextafter(X[0], np.inf)], [0.0])
    with pytest.raises(SuspidError, match="expected a number"):
        opt.tell(X[:1], ["abc"])
    opt.tell(X[2:], [neg_branin(X[2])])
    assert [r.index for r in records] == [0]
    opt.tell(X[:2], [neg_branin(x) for x in X[:2]])
    assert [r.index for r in records] == [0, 1, 2, 3, 4]
    assert [r.J_max for r in records][1:] == [max(r.J for r in records[:i]) for i in range(1, 5)]
    opt.stop()
    res = opt.result()
    assert res.stop_reason == "stopped" and res.n_function_calls == 3 and res.n_evaluations == 5


# -- trials: points with an identity --------------------------------------------------------------
def test_trials_are_told_by_id_in_any_order_and_give_the_run_told_by_points():
    """A batch told by trial id, last trial first, gives the run of the points told in order; an id that
    does not wait for a value is refused; every trial keeps its id, phase, status and value."""
    kwargs = CASES["batch 3"]
    reference = drive(kwargs)[0]
    ego, design, surrogate = options_for(**kwargs)
    opt = EGO(BRANIN.bounds, ego=ego, design=design, surrogate=surrogate)
    while not opt.done:
        trials = opt.ask_trials()
        assert [t.id for t in trials] == list(range(trials[0].id, trials[0].id + len(trials)))
        np.testing.assert_array_equal(np.array([t.x for t in trials]), opt.ask())
        for t in reversed(trials):
            opt.tell_trials([t.id], [neg_branin(t.x)])
        with pytest.raises(SuspidError, match=f"trial {trials[0].id} is not one"):
            opt.tell_trials([trials[0].id], [0.0])
    res = opt.result()
    np.testing.assert_array_equal(res.X, reference.X)
    assert res.y_opt == reference.y_opt
    told = [t for t in res.trials if t.told]
    assert [t.status for t in told] == ["ok"] * len(told) and len(told) == res.n_evaluations
    assert [t.J for t in told] == list(res.y) and {t.phase for t in told} == {"initial", "ego"}


def test_stopping_conditions_have_one_signature_and_combine():
    from suspid.optimize.trials import Budget, EIBelowTolerance, MaxIterations, StopState

    stop = EIBelowTolerance(1e-3) | MaxIterations(5) | Budget(20)
    assert not stop(StopState(n_told=10, n_new=2, log_ei=math.log(1e-2), epsilon=1e-3))
    assert stop.reason_for(StopState(n_told=10, n_new=2, log_ei=math.log(1e-4), epsilon=1e-3)) == "ei_below_tol"
    assert stop.reason_for(StopState(n_told=10, n_new=5)) == "max_iter"
    assert stop.reason_for(StopState(n_told=20, n_new=0)) == "budget"
    assert stop.reason_for(StopState(n_told=20, n_new=5)) == "max_iter"   # the first that fires names it
    assert not EIBelowTolerance(0.0)(StopState(log_ei=-1e9, epsilon=0.0))   # tol 0: the rule never fires
