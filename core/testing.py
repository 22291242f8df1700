"""Conformance checks for plugin authors (in the spirit of scikit-learn's ``check_estimator``).

Call them from your plugin's test suite::

    from suspid.testing import check_simulator
    def test_conformance():
        check_simulator(MySimulator, {"fs_hz": 100})

Each check raises ``AssertionError`` with a message saying which part of the
contract in :mod:`suspid.interfaces` is broken. (``assert`` is right here:
these are tests, not user-input validation.)
"""

from __future__ import annotations

import math
import os
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
from pydantic import BaseModel, ValidationError

from suspid.elements import group_parameters
from suspid.interfaces import (IRREGULARITY_CHANNELS, Executor, Objective, Parameter, Response, Simulator, Surrogate,
                               TrackSegment)


def _build(cls: type, base: type, options: Mapping[str, Any] | None) -> Any:
    """An instance of plugin class ``cls`` (a subclass of ``base``) from ``options`` validated by its
    ``Options`` model, which must reject unknown keys (one validation pass: a typo is an error)."""
    return cls(**_validated(cls, base, options))


def _validated(cls: type, base: type, options: Mapping[str, Any] | None) -> dict[str, Any]:
    """``options`` validated by ``cls.Options`` (see :func:`_build`)."""
    assert isinstance(cls, type) and issubclass(cls, base), f"{cls!r} must subclass {base.__name__}"
    name = getattr(cls, "name", None)
    assert isinstance(name, str) and name, f"{cls.__name__}.name must be a non-empty string"
    options = dict(options or {})
    model = getattr(cls, "Options", None)
    if model is not None:
        assert isinstance(model, type) and issubclass(model, BaseModel), f"{cls.__name__}.Options must be a pydantic model"
        try:
            model.model_validate({**options, "no_such_option_xyz": 1})
        except ValidationError:
            pass
        else:
            raise AssertionError(f"{cls.__name__}.Options must reject unknown keys (extra='forbid')")
        validated = model.model_validate(options)
        options = {k: getattr(validated, k) for k in model.model_fields}
    return options


def sample_segments(n: int = 2, length_m: float = 600.0, speed_mps: float = 50.0, dx_m: float = 0.25,
                    seed: int = 0) -> list[TrackSegment]:
    """Short track segments with millimetre-scale random irregularities, for checks.

    Each row of ``irregularities`` (4, n_x) in m is smoothed white noise with an
    rms of about 1 mm, so that a linear model gives accelerations well above zero.
    """
    rng = np.random.default_rng(seed)
    x = np.arange(0.0, length_m + dx_m / 2, dx_m)
    kernel = np.hanning(41)
    kernel /= kernel.sum()
    out = []
    for i in range(n):
        raw = rng.standard_normal((len(IRREGULARITY_CHANNELS), len(x)))
        smooth = np.array([np.convolve(r, kernel, mode="same") for r in raw])
        smooth *= 1e-3 / smooth.std(axis=1, keepdims=True)
        out.append(TrackSegment(f"check-{i}", x, smooth, speed_mps))
    return out


def check_simulator(cls: type, options: Mapping[str, Any] | None = None,
                    segments: list[TrackSegment] | None = None) -> None:
    """Check a simulator class against :class:`suspid.interfaces.Simulator`.

    Checks: name and options; parameters well formed (lower < upper, nominal
    inside, finite, unique names) and the default set among them; channels;
    ``simulate`` returns one finite ``Response`` per segment with the declared
    channels and a duration matching the segment; results are deterministic;
    every default parameter, moved to a bound, changes the output.
    """
    sim = _build(cls, Simulator, options)
    params = sim.parameters()
    assert params, "parameters() must declare at least one parameter"
    names = [p.name for p in params]
    assert len(set(names)) == len(names), f"duplicate parameter names in {names}"
    for p in params:
        assert isinstance(p, Parameter), f"parameters() must return Parameter objects, got {p!r}"
        assert all(math.isfinite(v) for v in (p.nominal, p.lower, p.upper)), f"{p.name}: non-finite values"
        assert p.lower < p.upper, f"{p.name}: lower {p.lower} must be below upper {p.upper}"
        assert p.lower <= p.nominal <= p.upper, f"{p.name}: nominal {p.nominal} outside [{p.lower}, {p.upper}]"
        assert isinstance(p.unit, str), f"{p.name}: unit must be a string"
    defaults = sim.default_parameters()
    assert defaults and set(defaults) <= set(names), f"default_parameters() {defaults} not among {names}"
    channels = sim.channels()
    assert channels and len(set(channels)) == len(channels), f"channels() must be unique names, got {channels}"

    segments = segments or sample_segments()
    first = sim.simulate({}, segments)
    assert isinstance(first, list) and len(first) == len(segments), "simulate() must return one Response per segment"
    for seg, r in zip(segments, first):
        assert isinstance(r, Response), f"simulate() must return Response objects, got {type(r).__name__}"
        assert list(r.channels) == list(channels), f"response channels {r.channels} != channels() {channels}"
        assert r.fs > 0, "fs must be positive"
        a = np.asarray(r.accelerations)
        assert a.ndim == 2 and a.shape[0] == len(channels), f"accelerations must be (n_channels, n_t), got {a.shape}"
        assert np.all(np.isfinite(a)), f"segment {seg.name}: non-finite accelerations"
        assert np.std(a) > 0, f"segment {seg.name}: accelerations are constant"
        expected = seg.duration()
        assert abs(r.duration - expected) <= max(0.05 * expected, 2 / r.fs), (
            f"segment {seg.name}: record of {r.duration:.3f} s, expected about {expected:.3f} s")
    again = sim.simulate({}, segments)
    for r1, r2 in zip(first, again):
        assert np.allclose(r1.accelerations, r2.accelerations), "simulate() must be deterministic"
    nominal = {p.name: p.nominal for p in params}
    explicit = sim.simulate(nominal, segments[:1])[0]
    assert np.allclose(explicit.accelerations, first[0].accelerations), \
        "parameters not named in w must keep their nominal values"
    by_name = {p.name: p for p in params}
    for name in defaults:
        p = by_name[name]
        moved = sim.simulate({name: p.upper}, segments[:1])[0].accelerations
        assert not np.allclose(moved, first[0].accelerations, rtol=1e-6, atol=0), \
            f"moving parameter {name} to its upper bound does not change the output"


def check_elements(cls: type, options: Mapping[str, Any] | None = None,
                   segments: list[TrackSegment] | None = None, kind: str | None = None) -> None:
    """Check a simulator's :class:`suspid.interfaces.ElementSimulator` declaration.

    Checks: elements declared, each kind among ``parameters()``, tags unique within a kind; for ``kind``
    (default: the first declared), every element set through its finest group at the kind's nominal value
    gives exactly the kind-level output, and the first element's group moved to the kind's lower bound
    changes it.
    """
    from suspid.elements import finest_groups
    from suspid.interfaces import ElementSimulator

    sim = _build(cls, Simulator, options)
    assert isinstance(sim, ElementSimulator), f"{cls.__name__} must subclass ElementSimulator"
    elements = sim.elements()
    assert elements, "elements() must declare at least one element"
    params = {p.name: p for p in sim.parameters()}
    for e in elements:
        assert e.kind in params, f"element kind {e.kind!r} is not among parameters()"
    pairs = [(e.kind, tuple(sorted(e.tags))) for e in elements]
    assert len(set(pairs)) == len(pairs), "two elements of one kind carry the same tags"
    kind = kind or elements[0].kind
    finest = finest_groups(elements, [kind])
    assert finest, f"no element of kind {kind!r}"
    segments = segments or sample_segments()[:1]
    nominal = params[kind].nominal
    base = sim.simulate({}, segments)
    tied = sim.simulate({g.name: nominal for g in finest}, segments)
    for a, b in zip(base, tied):
        assert np.array_equal(a.accelerations, b.accelerations), \
            f"every element of {kind} at its nominal value through groups must give the kind-level output"
    moved = sim.simulate({finest[0].name: params[kind].lower}, segments)
    assert any(not np.allclose(a.accelerations, b.accelerations) for a, b in zip(base, moved)), \
        f"{finest[0].name} at {params[kind].lower:g} does not change the output"


def check_differentiable(cls: type, options: Mapping[str, Any] | None = None,
                         segments: list[TrackSegment] | None = None, names: list[str] | None = None,
                         w: Mapping[str, float] | None = None, rtol: float = 1e-4,
                         rel_step: float = 1e-3) -> dict[str, float]:
    """Check a :class:`suspid.interfaces.DifferentiableSimulator` against central finite differences.

    Checks: ``differentiable`` returns a subset of the names asked, in their order;
    ``simulate_jacobian`` (called first at another point, so that whatever it keeps between calls is
    exercised) returns, per segment, the records ``simulate`` returns and
    derivatives ``(n_p, n_channels, n_t)``; for every parameter p and segment,
    ||dA_p - (A(w + h e_p) - A(w - h e_p)) / 2h|| <= ``rtol`` ||(A(w + h e_p) - A(w - h e_p)) / 2h||
    (2-norm over channels and samples), h = ``rel_step`` |w_p|: the difference's error is
    O(h²) plus the simulator's rounding over h.

    :param names: the parameters to check (default: every declared parameter the simulator differentiates).
    :returns: name -> the largest relative error over the segments.
    """
    from suspid.interfaces import DifferentiableSimulator

    sim = _build(cls, Simulator, options)
    assert isinstance(sim, DifferentiableSimulator), f"{cls.__name__} must subclass DifferentiableSimulator"
    declared = {p.name: p.nominal for p in sim.parameters()}
    asked = list(names) if names is not None else list(declared)
    declared |= {p.name: p.nominal for p in group_parameters(sim) if p.name in asked}   # element groups asked for
    offered = sim.differentiable(asked)
    assert isinstance(offered, list) and all(n in asked for n in offered), \
        f"differentiable() must return names among those asked, got {offered}"
    assert offered == [n for n in asked if n in offered], "differentiable() must keep the order of the names asked"
    assert offered, f"{cls.__name__} differentiates none of {asked}"
    segments = segments or sample_segments()
    point = {n: float(declared[n]) for n in declared} | dict(w or {})
    # a first call elsewhere: what a simulator keeps between calls (caches, sparsity patterns) must not change
    # the derivatives at the point checked
    sim.simulate_jacobian({n: point[n] * 1.05 for n in offered} | {n: v for n, v in point.items() if n not in offered},
                          segments, offered)
    pairs = sim.simulate_jacobian(point, segments, offered)
    plain = sim.simulate(point, segments)
    assert isinstance(pairs, list) and len(pairs) == len(segments), "simulate_jacobian() must return one pair per segment"
    for (r, g), ref in zip(pairs, plain):
        assert isinstance(r, Response), "simulate_jacobian() must return (Response, derivatives) pairs"
        assert np.allclose(r.accelerations, ref.accelerations, rtol=1e-9, atol=0), \
            "simulate_jacobian()'s records must be those of simulate()"
        assert np.shape(g) == (len(offered),) + np.shape(r.accelerations), \
            f"derivatives of shape {np.shape(g)}, expected {(len(offered),) + np.shape(r.accelerations)}"
    errors: dict[str, float] = {}
    for k, name in enumerate(offered):
        x = point[name]
        h = rel_step * abs(x) if x != 0 else rel_step
        up = sim.simulate({**point, name: x + h}, segments)
        down = sim.simulate({**point, name: x - h}, segments)
        worst = 0.0
        for (_, g), a, b in zip(pairs, up, down):
            fd = (np.asarray(a.accelerations) - np.asarray(b.accelerations)) / (2 * h)
            scale = np.linalg.norm(fd)
            assert scale > 0, f"{name}: the finite difference is zero (step {h:g} too small, or no effect)"
            worst = max(worst, float(np.linalg.norm(np.asarray(g)[k] - fd) / scale))
        errors[name] = worst
    bad = {n: e for n, e in errors.items() if not e <= rtol}
    assert not bad, "derivatives differ from central finite differences by more than " \
        f"{rtol:g} relative: " + ", ".join(f"{n} {e:.2e}" for n, e in bad.items())
    return errors


def check_objective(cls: type, options: Mapping[str, Any] | None = None) -> None:
    """Check an objective class against :class:`suspid.interfaces.Objective`.

    Checks: ``psi`` returns ``(n_channels,)`` finite values; samples from the
    measured distribution score higher than shifted ones on every channel;
    the result does not depend on the order of the samples.
    """
    obj = _build(cls, Objective, options)
    rng = np.random.default_rng(0)
    n, n_ch, n_f = 60, 3, 25
    freqs = np.linspace(0.5, 20.0, n_f)
    y_mes = rng.normal(0.0, 2.0, (n, n_ch, n_f))
    same = rng.normal(0.0, 2.0, (n, n_ch, n_f))
    shifted = same + 6.0
    psi_same = np.asarray(obj.psi(y_mes, same, freqs))
    psi_shift = np.asarray(obj.psi(y_mes, shifted, freqs))
    assert psi_same.shape == (n_ch,), f"psi must return shape (n_channels,) = ({n_ch},), got {psi_same.shape}"
    assert np.all(np.isfinite(psi_same)) and np.all(np.isfinite(psi_shift)), "psi must be finite"
    assert np.all(psi_same > psi_shift), "matching distributions must score higher than shifted ones (J is maximised)"
    permuted = np.asarray(obj.psi(y_mes[::-1], same[rng.permutation(n)], freqs))
    assert np.allclose(permuted, psi_same, rtol=1e-6, atol=1e-9), "psi must not depend on sample order"


def check_surrogate(cls: type, options: Mapping[str, Any] | None = None) -> None:
    """Check a surrogate class against :class:`suspid.interfaces.Surrogate`.

    Checks: ``fit`` returns self; ``predict`` gives ``(n,)`` means and
    non-negative variances; it reproduces a smooth 2-d function at held-out
    points to a few per cent of its range; its variance is smaller at a
    training point than far from the data.
    """
    model = _build(cls, Surrogate, options)
    rng = np.random.default_rng(1)
    X = rng.random((40, 2))

    def f(x):
        return np.sin(3 * x[:, 0]) + np.cos(2 * x[:, 1]) + x[:, 0] * x[:, 1]

    y = f(X)
    assert model.fit(X, y) is model, "fit() must return self"
    Xt = rng.random((50, 2))
    mean, var = model.predict(Xt)
    mean, var = np.asarray(mean), np.asarray(var)
    assert mean.shape == (50,) and var.shape == (50,), f"predict must return (n,), (n,); got {mean.shape}, {var.shape}"
    assert np.all(var >= 0), "predictive variances must be non-negative"
    err = np.max(np.abs(mean - f(Xt))) / np.ptp(y)
    assert err < 0.05, f"held-out error {err:.3f} of the range is too large for a smooth function"
    _, v_in = model.predict(X[:1])
    _, v_out = model.predict(np.array([[3.0, 3.0]]))
    assert v_in[0] < v_out[0], "variance at a training point must be below the variance far from the data"


# -- optimisers ------------------------------------------------------------------------------------
OPTIMIZER_BOX = np.array([[-2.0, 3.0], [10.0, 20.0]])
"""``(2, 2)`` the box of :func:`check_optimizer`, SI-like bounds that are not the unit square."""


class _CheckedLoop:
    """The optimiser under test as the one loop sees it, every ask checked against the contract."""

    def __init__(self, opt: Any, budget: int, asynchronous: bool) -> None:
        self.opt, self.budget, self.is_async = opt, budget, asynchronous
        self.waiting: set[int] = set()   # trials asked, not told
        self.n_told = 0
        self.n_asks = 0

    @property
    def done(self) -> bool:
        return self.opt.done

    def asynchronous(self, n_workers: int) -> bool:
        return self.is_async

    def ask_trials(self, n: int = 1, beside: bool = False) -> list[Any]:
        self.n_asks += 1
        assert self.n_asks <= 10 * self.budget, f"not done after {10 * self.budget} ask/tell rounds"
        trials = self.opt.ask_trials(n=n, beside=beside)
        X = np.array([t.x for t in trials], dtype=float).reshape(-1, 2)
        least = 0 if beside else 1
        assert len(trials) >= least, f"ask_trials() must hand out at least {least} trials here, got {len(trials)}"
        assert len({t.id for t in trials}) == len(trials), "ask_trials() handed out two trials with one id"
        assert np.all(X >= OPTIMIZER_BOX[:, 0] - 1e-9) and np.all(X <= OPTIMIZER_BOX[:, 1] + 1e-9), \
            f"ask_trials() handed out points outside the bounds: {X.tolist()}"
        if beside:
            assert len(trials) <= 1, f"ask_trials(1, beside=True) must hand out at most one trial, got {len(trials)}"
            assert not {t.id for t in trials} & self.waiting, "ask_trials(1, beside=True) handed out a trial in flight"
        self.waiting |= {t.id for t in trials}
        assert self.n_told + len(self.waiting) <= self.budget, \
            f"asked {self.n_told + len(self.waiting)} points for a budget of {self.budget}"
        return trials

    def tell_trials(self, ids: Any, values: Any, eval_seconds: Any = None) -> None:
        self.opt.tell_trials(ids, values)
        self.waiting -= set(ids)
        self.n_told += len(ids)


def _run_optimizer(cls: type, options: dict[str, Any], budget: int, seed: int,
                   fail_every: int, asynchronous: bool = False) -> tuple[list[np.ndarray], Any]:
    """Drive one optimiser through its trials on the one loop (:func:`suspid.optimize.driver.run_trials`, two
    workers) on a concave quadratic (maximiser (1, 16)) whose every ``fail_every``-th evaluation fails; returns
    the points in the order told and the result. ``asynchronous``: with two trials in flight, on the loop's
    schedule."""
    from suspid.optimize.design import DesignOptions  # the conformance kit only
    from suspid.optimize.driver import Evaluator, Flight, Outcome, run_trials

    opt = cls(OPTIMIZER_BOX, budget=budget, seed=seed, design=DesignOptions(n_initial=6, seed=seed), **options)
    told: list[np.ndarray] = []

    class Quadratic(Evaluator):
        n_workers = 2

        def evaluate(self, trials: list[Any]) -> list[Outcome]:
            out = [Outcome(None if (len(told) + i + 1) % fail_every == 0 else
                           float(-((t.x[0] - 1.0) / 5.0) ** 2 - ((t.x[1] - 16.0) / 10.0) ** 2))
                   for i, t in enumerate(trials)]
            told.extend(np.array(t.x, dtype=float) for t in trials)   # trials are told in the order evaluated
            return out

        def start(self, trial: Any) -> Flight:
            return Flight(trial, outcome=self.evaluate([trial])[0])

    run_trials(_CheckedLoop(opt, budget, asynchronous), Quadratic())
    return told, opt.result()


def check_optimizer(cls: type, options: Mapping[str, Any] | None = None, budget: int = 24) -> None:
    """Check an optimiser class against :class:`suspid.interfaces.Optimizer`.

    Checks, on a 2-d concave quadratic over a box that is not the unit square,
    with every 5th evaluation failing (told as None), through the trial interface the
    driver uses: ``ask_trials`` hands out at least one trial, with distinct ids and points
    inside the bounds, while not ``done``; no more than ``budget`` points in all; a point
    not asked is refused by the array ``tell``; ``result()`` holds every point told, in
    order, with NaN where it failed, and its best point; it improves on the first point
    told; the same seed gives the same points. An optimiser whose ``asynchronous(2)`` is
    True is also driven with two trials in flight (``ask_trials(1, beside=True)``, oldest
    told first): at most one new trial per ask, never one in flight, the budget kept, the
    same points for the same seed.
    """
    from suspid.interfaces import Optimizer  # the conformance kit only

    opts = _validated(cls, Optimizer, options)
    opts.pop("seed", None)  # an option ``seed`` is the constructor's seed, which the check sets
    told, res = _run_optimizer(cls, opts, budget, seed=3, fail_every=5)
    assert told, "the optimiser asked no point"
    X, y = np.asarray(res.X), np.asarray(res.y, dtype=float)
    assert X.shape == (len(told), 2) and y.shape == (len(told),), \
        f"result() must hold every point told: X {X.shape}, y {y.shape} for {len(told)} points"
    assert np.allclose(X, np.array(told), rtol=1e-12, atol=0), "result().X must be the points in the order told"
    assert res.n_evaluations == len(told) <= budget, f"n_evaluations {res.n_evaluations} for {len(told)} told"
    assert np.all(np.isnan(y[4::5])), "result().y must be NaN where the evaluation failed"
    assert res.y_opt == np.nanmax(y) and np.any(np.all(np.isclose(X, res.x_opt), axis=1)), \
        "result() must give the best evaluated point and its J"
    assert res.y_opt > y[0] or y[0] == np.nanmax(y), "the optimiser never improved on its first point"
    assert isinstance(res.stop_reason, str) and res.stop_reason != "running", "stop_reason must say why it stopped"
    again, _ = _run_optimizer(cls, opts, budget, seed=3, fail_every=5)
    assert len(again) == len(told) and np.array_equal(np.array(again), np.array(told)), \
        "the same seed must give the same points"
    if cls(OPTIMIZER_BOX, budget=budget, seed=3, **opts).asynchronous(2):
        runs = [_run_optimizer(cls, opts, budget, seed=3, fail_every=5, asynchronous=True) for _ in range(2)]
        for points, res in runs:
            assert np.allclose(np.asarray(res.X), np.array(points), rtol=1e-12, atol=0), \
                "asynchronous: result().X must be the points in the order told"
        assert np.array_equal(np.array(runs[0][0]), np.array(runs[1][0])), \
            "asynchronous: the same seed must give the same points"
    opt = cls(OPTIMIZER_BOX, budget=budget, seed=3, **opts)
    X = np.asarray(opt.ask(), dtype=float)
    try:
        opt.tell(X + 0.123, [0.0] * len(X))
    except Exception:
        pass
    else:
        raise AssertionError("tell() must refuse points that ask() did not return")


# -- executors: module-level task functions, so that every executor can pickle them by reference --
def square(x: Any) -> Any:
    """``x * x``: a number, or a numpy array element-wise."""
    return x * x


def fail_on_odd(x: int) -> int:
    """``x`` for even ``x``; odd ``x`` raises ``ValueError('task input <x> is odd')``."""
    if x % 2:
        raise ValueError(f"task input {x} is odd")
    return x


def sleep_then_square(item: tuple[float, Any]) -> Any:
    """Item ``(delay_s, x)``: sleep ``delay_s`` seconds, then return ``x * x``."""
    delay_s, x = item
    time.sleep(delay_s)
    return x * x


class DieOnce:
    """A task wrapper that ends its worker process once, for the item numbered ``victim``.

    Called with ``(number, value)``; returns ``fn(value)``, except that the
    first call for ``number == victim`` anywhere (the marker file does not
    exist yet) creates the marker and then ends its process with
    ``os._exit(1)``, as a segmentation fault would. The retry finds the marker
    and succeeds. Only for executors that run tasks in other processes: in the
    calling process it would end the caller.

    :param fn: the wrapped task, picklable.
    :param victim: the item number whose first run dies.
    :param marker: a path that must not exist yet, visible to every worker
        (a local temporary directory for a LocalCluster).
    :param delay_s: seconds the victim waits before dying, so that other tasks
        are in flight when it dies.
    """

    def __init__(self, fn: Callable[[Any], Any], victim: int, marker: str | os.PathLike, delay_s: float = 0.2):
        self.fn, self.victim, self.marker, self.delay_s = fn, victim, str(marker), delay_s

    def __call__(self, item: tuple[int, Any]) -> Any:
        number, value = item
        if number == self.victim and not os.path.exists(self.marker):
            try:
                with open(self.marker, "x"):
                    pass
            except FileExistsError:  # another attempt got here first: it is the one to die
                return self.fn(value)
            time.sleep(self.delay_s)
            os._exit(1)
        return self.fn(value)


def collect(executor: Executor, fn: Callable[[Any], Any], items: list[Any]) -> dict[int, Any]:
    """``{index: result or exception}`` of ``executor.map_unordered(fn, items)``, checking each index once."""
    out: dict[int, Any] = {}
    for pair in executor.map_unordered(fn, items):
        assert isinstance(pair, tuple) and len(pair) == 2, f"map_unordered must yield (index, result), got {pair!r}"
        index, result = pair
        assert isinstance(index, int) and 0 <= index < len(items), f"index {index!r} is not one of the items'"
        assert index not in out, f"index {index} was yielded twice"
        out[index] = result
    assert sorted(out) == list(range(len(items))), f"indices missing: {sorted(set(range(len(items))) - set(out))}"
    return out


def check_submit(executor: Executor) -> None:
    """The asynchronous API of an entered executor: ``submit`` then ``wait_first`` until every task is back.

    Every handle comes back exactly once with its own result; a task's
    exception is returned, not raised; ``wait_first`` on unfinished tasks with
    a short timeout returns at once (possibly empty) rather than waiting for all.

    :raises AssertionError: saying which part of the contract is broken.
    """
    values = list(range(6))
    handles = {executor.submit(sleep_then_square, (0.02 * (len(values) - v), v)): v for v in values}
    bad = executor.submit(fail_on_odd, 3)
    waiting, got = list(handles) + [bad], {}
    deadline = time.monotonic() + 120
    while waiting:
        assert time.monotonic() < deadline, f"wait_first never returned {len(waiting)} handle(s)"
        t0 = time.monotonic()
        done = executor.wait_first(waiting, timeout=5.0)
        assert time.monotonic() - t0 < 30, "wait_first overran its timeout"
        for h, outcome in done:
            assert h in waiting, "wait_first returned a handle twice, or one it was not given"
            waiting.remove(h)
            got[h] = outcome
    for h, v in handles.items():
        assert got[h] == v * v, f"submit: task of {v} gave {got[h]!r}"
    assert isinstance(got[bad], ValueError) and "task input 3 is odd" in str(got[bad]), (
        f"submit: a task's exception must be returned with its message, got {got[bad]!r}")
    slow = executor.submit(sleep_then_square, (1.5, 2))
    t0 = time.monotonic()
    early = executor.wait_first([slow], timeout=0.2)
    assert time.monotonic() - t0 < 1.4 or early, "wait_first waited past its timeout"
    while not early:
        early = executor.wait_first([slow], timeout=5.0)
    assert early == [(slow, 4)], f"submit: the slow task gave {early!r}"


def check_executor(cls: type, options: Mapping[str, Any] | None = None, *, worker_death: bool = False) -> None:
    """Check an executor class against :class:`suspid.interfaces.Executor`.

    Checks: name and options (unknown keys rejected); the context manager
    returns the executor; ``n_workers`` is a positive int; every item's result
    comes back once under its index, whatever the completion order; numpy
    arrays come back intact; a task's exception is yielded with its index
    (type and message kept) and the other tasks still finish; no items yield
    nothing; several calls work within one ``with`` block; ``submit`` and
    ``wait_first`` (:func:`check_submit`).

    :param cls: the executor class.
    :param options: its options (as in ``executor.options``).
    :param worker_death: also check that a task whose worker process dies is
        run again and the call still gives every result. Only for executors
        that run tasks in other processes (never ``serial``: the dying task
        would end the caller).
    :raises AssertionError: saying which part of the contract is broken.
    """
    executor = _build(cls, Executor, options)
    with executor as entered:
        assert entered is executor, "__enter__ must return the executor itself"
        n = executor.n_workers
        assert isinstance(n, int) and n >= 1, f"n_workers must be a positive int, got {n!r}"

        assert collect(executor, square, []) == {}, "no items must yield nothing"

        values = list(range(12))
        got = collect(executor, square, values)
        assert got == {i: v * v for i, v in enumerate(values)}, f"wrong results: {got}"

        # later items finish first on a parallel executor: results must follow the index, not the order
        items = [(0.01 * (len(values) - i), v) for i, v in enumerate(values)]
        got = collect(executor, sleep_then_square, items)
        assert got == {i: v * v for i, v in enumerate(values)}, f"wrong results with out-of-order completion: {got}"

        arrays = [np.arange(5.0) * k for k in range(4)]
        got = collect(executor, square, arrays)
        for i, a in enumerate(arrays):
            assert isinstance(got[i], np.ndarray) and np.array_equal(got[i], a * a), f"array {i} came back as {got[i]!r}"

        got = collect(executor, fail_on_odd, values)
        for i, v in enumerate(values):
            if v % 2:
                assert isinstance(got[i], ValueError), f"task {i} raised ValueError; yielded {got[i]!r}"
                assert f"task input {v} is odd" in str(got[i]), f"task {i}: message lost: {got[i]}"
            else:
                assert got[i] == v, f"task {i}: expected {v}, got {got[i]!r}"

        check_submit(executor)

        if worker_death:
            with tempfile.TemporaryDirectory(prefix="suspid-check-executor-") as tmp:
                marker = Path(tmp) / "died"
                task = DieOnce(sleep_then_square, victim=3, marker=marker)
                items = [(i, (0.1, v)) for i, v in enumerate(values)]
                got = collect(executor, task, items)
                assert marker.exists(), "the victim task never ran"
                assert got == {i: v * v for i, v in enumerate(values)}, (
                    f"after a worker died, the results are not all there: {got}")
                marker = Path(tmp) / "died-submit"
                task = DieOnce(sleep_then_square, victim=1, marker=marker)
                handles = [executor.submit(task, (i, (0.1, v))) for i, v in enumerate(values[:4])]
                got = {}
                while len(got) < len(handles):
                    for h, outcome in executor.wait_first([h for h in handles if h not in got], timeout=60):
                        got[h] = outcome
                assert marker.exists(), "the victim task never ran"
                assert [got[h] for h in handles] == [v * v for v in values[:4]], (
                    f"submit: after a worker died, the results are not all there: {list(got.values())}")
