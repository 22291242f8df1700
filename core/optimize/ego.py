"""Efficient Global Optimization (EGO) of an expensive objective J (paper §3.2, eq. 9).

The paper's loop (see :mod:`suspid.optimize.loop`) on the one ask/tell state
machine (:class:`suspid.optimize.trials.TrialLoop`), so that an outside process
(a batch of simulations on another machine, a queue) can drive it::

    opt = EGO(bounds, ego=EGOOptions(max_iter=40), design=DesignOptions(n_initial=10))
    while not opt.done:
        trials = opt.ask_trials()                          # the initial design first; t.x SI, t.u in [0, 1]^q
        opt.tell_trials([t.id for t in trials], values)    # their J by trial id; None or NaN where it failed
    result = opt.result()                                  # an EGOResult

``ask()`` and ``tell(X, values)`` are the same with arrays of SI points, for a caller
that holds points rather than trials.

:func:`run_ego` and :func:`maximize` run the same object through the one loop
(:func:`suspid.optimize.driver.run_trials`), which calls ``func(w (q,)) -> float``
(or ``func_batch(X (k, q)) -> k values`` for a batch). Everything happens in the unit cube ``[0, 1]^q``; ``ask``
returns and ``tell`` takes points of the parameter box ``bounds (q, 2)``
(SI units). A caller who prefers unit coordinates passes ``bounds = [[0, 1]] * q``.

The pieces: :class:`suspid.optimize.loop.LoopState` (points, values,
records), :class:`suspid.optimize.loop.EIProposer` (fit J~, maximise EI;
batches by kriging believer), the stopping rules
:class:`~suspid.optimize.trials.MaxIterations` | :class:`~suspid.optimize.trials.EIBelowTolerance`
(and :class:`~suspid.optimize.trials.Budget` with a ``budget``), and the optional local
refinement :class:`suspid.optimize.refine.TrustRegionRefiner` with its
radius rule. EI and its search: :mod:`suspid.optimize.acquisition`.

Using it in a pipeline
----------------------
(a) Own initial data: ``X_init (n0, q)`` (SI) replaces the design, and
    ``y_init (n0,)`` gives values already known (NaN where still to be
    evaluated), so cached evaluations are not recomputed.
(b) Ledger: ``callback(record)`` is called once per initial point (phase
    ``"initial"``), per EGO point (phase ``"ego"``), for the iteration that
    stops on EI < eps (phase ``"stop"``, ``J`` is None) and per point of the
    optional refinement (phase ``"refine"``) with an
    :class:`~suspid.optimize.loop.IterationRecord`, in index order, whatever
    the order of ``tell``. A callback returning True stops the run
    (``stop_reason == "callback"``; in the refinement
    ``refine_stop_reason``); the other points of the same ``tell`` of an EGO
    batch are still recorded, the rest of an initial design is dropped.
(c) Determinism: the design is seeded by ``design.seed``; the EI candidates
    of the iteration that follows the n-th evaluation by ``(ego.seed, 1, n)``
    (``(ego.seed, 2, n)`` in the refinement); the surrogate by its own
    ``seed`` option. So a killed run replayed with a ``func`` that returns
    cached J values retraces the same points, and the ask/tell loop gives
    exactly the points of :func:`run_ego`.
(d) Failures: a point told with None, NaN or ±inf is kept out of the data
    (``EGOResult.X_failed``); it counts against the budget, and later fits
    see it with the worst J so far, so that EI does not return to it.
(e) Budget mode (``tol`` < ``explore_tol`` = 1e-4, e.g. tol = 0): when EI
    falls below explore_tol * (max J - min J) the loop sets the incumbent's
    basin aside and goes on against the best J outside it, so that it does not
    spend the budget at a local maximum; EI is maximised on a model of the warped J
    and every third step maximises the model's mean (:class:`suspid.optimize.loop.EIProposer`).
    With the default tol the paper's stop fires first: the paper's loop is unchanged.

Public API: :class:`EGO`, :func:`run_ego`, :func:`maximize`,
:func:`make_surrogate`, and, re-exported, :class:`EGOOptions`,
:class:`RefineOptions`, :class:`IterationRecord`, :class:`EGOResult`,
:func:`expected_improvement`, :func:`log_expected_improvement`.
"""

from __future__ import annotations

import time
from typing import Any, Callable, Sequence

import numpy as np

from suspid.errors import ConfigError, SimulatorError, SuspidError
from suspid.infra.threads import single_blas_thread
from suspid.interfaces import Surrogate
from suspid.optimize.acquisition import (ei_from_log, expected_improvement, log_ei_and_grad,
                                         log_expected_improvement)
from suspid.optimize.driver import FunctionEvaluator, run_trials
from suspid.optimize.design import DesignOptions, check_bounds, from_unit, make_design, min_distance, to_unit
from suspid.optimize.loop import EGOResult, EIProposer, IterationRecord, LoopState
from suspid.optimize.trials import Budget, EIBelowTolerance, MaxIterations, StopState, Trial, TrialBook, TrialLoop
from suspid.optimize.options import EGOOptions, RefineOptions, make_surrogate
from suspid.options import parse_options
from suspid.optimize.refine import TrustRegionRefiner

__all__ = ["EGO", "EGOOptions", "RefineOptions", "IterationRecord", "EGOResult", "run_ego", "maximize",
           "make_surrogate", "expected_improvement", "log_expected_improvement", "log_ei_and_grad"]

Callback = Callable[[IterationRecord], "bool | None"]

BELIEVED = -1
"""``EIProposer.fitted_on`` after :meth:`EGO.ask_beside`: the surrogate's last fit saw believed values."""


class EGO(TrialLoop):
    """The EGO loop as an ask/tell object (see the module docstring).

    The constructor only stores its arguments; the bounds, the initial points
    and the options are checked at the first :meth:`ask`, :meth:`tell` or
    :attr:`done`.

    :param bounds: ``(q, 2)`` lower and upper bounds, SI units.
    :param ego: the ``ego:`` options (defaults when None).
    :param design: the ``design:`` options, used when ``X_init`` is None.
    :param surrogate: a surrogate instance (default: ``gpy-kriging`` seeded by ``ego.seed``).
    :param X_init: ``(n0, q)`` initial points in SI units, instead of the design.
    :param y_init: ``(n0,)`` their J where known, NaN where still to be evaluated.
    :param callback: called with each :class:`IterationRecord`; returning True stops.
    :param budget: the largest number of evaluations of J (initial points included, values of
        ``y_init`` not), None: m0 + m1 and the refinement's. Reaching it stops the run
        (``stop_reason == "budget"``) unless the loop's own rule stops it at the same point.
    :param drop_failed_initial: initial points whose evaluation failed are left out of the loop
        (not seen by the fits), as the pipeline's ``ego`` optimiser has always done; the loop then
        needs 2 initial points with a value (:class:`~suspid.errors.SimulatorError` otherwise).
    """

    def __init__(self, bounds, *, ego: EGOOptions | None = None, design: DesignOptions | None = None,
                 surrogate: Surrogate | None = None, X_init: np.ndarray | None = None,
                 y_init: np.ndarray | None = None, callback: Callback | None = None, budget: int | None = None,
                 drop_failed_initial: bool = False) -> None:
        self.bounds = bounds
        self.ego = ego
        self.design = design
        self.surrogate = surrogate
        self.X_init = X_init
        self.y_init = y_init
        self.callback = callback
        self.budget = budget
        self.drop_failed_initial = drop_failed_initial
        self._started = False

    # -- setup -------------------------------------------------------------------
    def _start(self) -> None:
        if self._started:
            return
        opts = self.ego or EGOOptions()
        b = check_bounds(self.bounds)
        q = b.shape[0]
        if self.X_init is None:
            if self.y_init is not None:
                raise ConfigError("y_init was given without X_init")
            U = make_design(self.design, q)
        else:
            X0 = np.asarray(self.X_init, dtype=float)
            if X0.ndim != 2 or X0.shape[1] != q:
                raise ConfigError(f"X_init must have shape (n0, {q}), got {X0.shape}")
            U = to_unit(X0, b)
            if np.any(U < -1e-9) or np.any(U > 1 + 1e-9) or not np.all(np.isfinite(U)):
                raise ConfigError("X_init has points outside the bounds")
            U = np.clip(U, 0.0, 1.0)
        if self.budget is not None:
            U = U[: self.budget]
        if U.shape[0] < 2:
            raise ConfigError(f"EGO needs at least 2 initial points, got {U.shape[0]}")
        y0 = np.full(U.shape[0], np.nan)
        if self.y_init is not None:
            y0 = np.asarray(self.y_init, dtype=float).reshape(-1)
            if y0.shape[0] != U.shape[0]:
                raise ConfigError(f"y_init has {y0.shape[0]} values for {U.shape[0]} points of X_init")
        self.options_ = opts
        self.bounds_ = b
        self.state_ = LoopState(q=q)
        self.book_ = TrialBook(b, self.budget)
        self.surrogate_ = self.surrogate if self.surrogate is not None else make_surrogate(
            "gpy-kriging", seed=opts.seed)
        self.proposer_ = EIProposer(self.surrogate_, opts)
        self.max_iterations_ = MaxIterations(opts.max_iter)
        self.ei_rule_ = EIBelowTolerance(opts.tol)
        self.paper_stop_ = self.max_iterations_ | self.ei_rule_
        self.refiner_: TrustRegionRefiner | None = None
        self.phase_ = "initial"
        self.stop_reason_: str | None = None
        self.refine_stop_reason_: str | None = None
        self.n_function_calls_ = 0
        self._iteration = 0  # EGO iterations begun
        self._n_new = 0  # points told after the design (failed ones included)
        self._result: EGOResult | None = None
        self._started = True
        X0 = self.X_init if self.X_init is None else np.asarray(self.X_init, dtype=float)[: len(U)]
        trials = [self.book_.new(u.copy(), "initial", x=None if X0 is None else X0[i].copy())
                  for i, u in enumerate(U)]
        for t, v in zip(trials, y0):
            if np.isfinite(v):
                t.counted = False
                self.book_.record([t.id], [float(v)])
        self._commit_told()

    # -- public interface --------------------------------------------------------
    @property
    def phase(self) -> str:
        """Phase of the points :meth:`ask` returns: ``"initial"``, ``"ego"``, ``"refine"`` or ``"done"``."""
        self._start()
        self._advance()
        return self.phase_

    @property
    def done(self) -> bool:
        """True when the run has stopped (computes the next proposal when nothing is pending)."""
        return self.phase == "done"

    @property
    def state(self) -> LoopState:
        """The :class:`LoopState`: evaluated points, values and records so far."""
        self._start()
        return self.state_

    @property
    def trials(self) -> list[Trial]:
        """Every :class:`~suspid.optimize.trials.Trial` handed out so far, by id."""
        self._start()
        return list(self.book_.trials)

    def tell_trials(self, ids: Sequence[int], values: Sequence[float | None],
                    eval_seconds: Sequence[float | None] | None = None) -> list[IterationRecord]:
        """Give J of trials :meth:`ask_trials` handed out (all of them or some, in any order).

        :param ids: the trials' ids.
        :param values: ``(k,)`` J there; None, NaN or ±inf for a failed evaluation.
        :param eval_seconds: ``(k,)`` evaluation wall times for the records (optional).
        :returns: the records made (in index order; a trial waits for those asked before it).
        :raises SuspidError: an id that is not waiting for a value, or a value that is not a number.
        """
        self._start()
        n_before = len(self.state_.records)
        super().tell_trials(ids, values, eval_seconds)
        spent = Budget(self.budget) if self.budget is not None else None
        if spent is not None and self.phase_ != "done" and spent(StopState(n_told=self._told_count())) \
                and not self.done:   # the loop's own stop (its next proposal) first
            self.stop(spent.reason)
        return self.state_.records[n_before:]

    def ask(self) -> np.ndarray:
        """The SI points of :meth:`ask_trials`, ``(n_points, q)`` (empty when done)."""
        return np.array([t.x for t in self.ask_trials()]).reshape(-1, self.state_.q)

    def tell(self, X: np.ndarray, values: Sequence[float | None], eval_seconds: Sequence[float | None] | None = None
             ) -> list[IterationRecord]:
        """:meth:`tell_trials` for callers that hold the points :meth:`ask` returned, not the trials
        (deprecated: tell trials by id; kept for the array form of the optimiser contract).

        :param X: ``(n_points, q)`` SI points, each exactly one of those :meth:`ask` returned.
        :param values: ``(n_points,)`` J there; None, NaN or ±inf for a failed evaluation.
        :raises SuspidError: a point that is not waiting for a value, or a value that is not a number.
        """
        self._start()
        X = np.atleast_2d(np.asarray(X, dtype=float))
        values = list(values)
        if X.shape[0] != len(values) or (X.size and X.shape[1] != self.state_.q):
            raise SuspidError(f"tell: {X.shape[0]} points of shape {X.shape} for {len(values)} values; "
                              f"expected (n_points, {self.state_.q}) and n_points values")
        ids = self.book_.ids_of(X) if X.size else []
        return self.tell_trials(ids, values, eval_seconds)

    def ask_beside(self, pending: np.ndarray | None = None) -> list[Trial]:
        """One more EGO trial while the trials waiting for a value are being evaluated (asynchronous drivers).

        The kriging believer (:class:`suspid.optimize.loop.EIProposer`): the waiting
        points (``pending (p, q)`` SI when given, else those of the waiting trials) enter the
        fit with the surrogate's mean as their J, so EI looks elsewhere. The trial joins the
        waiting ones (tell it like any other) and counts as one EGO iteration. No trial is added
        outside the ``"ego"`` phase, once m1 points are asked, beyond the budget, or when the
        point's EI is below the paper's eps (as a later point of a batch): the caller then waits
        for a waiting trial, tells it and asks again; with nothing waiting, :meth:`ask_trials`
        takes the paper's step, and its stop. EI candidates of the p-th waiting point after n
        evaluations come from ``default_rng([seed, 3, n, p])``.

        :returns: one trial, or none when no trial can be added now.
        """
        self._start()
        if self.phase != "ego" or self._iteration >= self.options_.max_iter:
            return []
        if self.budget is not None and len([t for t in self.book_.trials if t.counted]) >= self.budget:
            return []
        st, model, opts = self.state_, self.surrogate_, self.options_
        if pending is None:
            pending = np.array([t.x for t in self.book_.waiting]).reshape(-1, st.q)
        U_p = to_unit(np.atleast_2d(np.asarray(pending, dtype=float)), self.bounds_)
        U, y = self.proposer_._data(st)
        t0 = time.perf_counter()
        model.fit(U, y)
        U_b, y_b = np.vstack([U, U_p]), np.concatenate([y, model.predict(U_p)[0]])
        model.fit(U_b, y_b)
        self.proposer_.fitted_on = BELIEVED  # not a fit on the data: result() refits
        t_fit = time.perf_counter() - t0
        j_max = float(st.y_array.max())
        rng = np.random.default_rng([opts.seed, 3, st.n_points, len(U_p)])
        t0 = time.perf_counter()
        u, log_ei = self.proposer_._search(model, U_b, y_b, st.y_array, j_max, rng)
        epsilon = self.ei_rule_.epsilon(st.y_array)
        if self.ei_rule_.below(log_ei, epsilon):
            return []
        self._iteration += 1
        return [self.book_.new(u, "ego", iteration=self._iteration, log_ei=log_ei, j_max=j_max, epsilon=epsilon,
                               hyperparameters=dict(model.hyperparameters_ or {}), fit_seconds=t_fit,
                               search_seconds=time.perf_counter() - t0)]

    def stop(self, reason: str = "stopped") -> None:
        """End the run now (trials still waiting for a value are dropped)."""
        self._start()
        if self.phase_ == "initial":
            self.state_.n_initial = self.state_.n_points
        if self.phase_ == "refine":
            self.refine_stop_reason_ = reason
        elif self.phase_ != "done":
            self.stop_reason_ = reason
        self.book_.drop_waiting()
        self.phase_ = "done"

    def result(self) -> EGOResult:
        """The :class:`EGOResult` (a snapshot with ``stop_reason == "running"`` before the end).

        At the end the surrogate is refitted on every point when ``refit_final``
        is set and its last fit did not see them all.
        """
        self._start()
        st, b, opts = self.state_, self.bounds_, self.options_
        if st.n_points == 0:
            raise SuspidError("no point has a value yet")
        if self._result is not None:
            return self._result
        finished = self.phase_ == "done"
        Ua, ya = st.U_array, st.y_array
        model = self.proposer_
        refit = opts.refit_final or model.fitted_on == BELIEVED  # a fit on believed values is no result
        if finished and refit and model.fitted_on not in (0, st.n_points) and st.n_points >= 2:
            self.surrogate_.fit(Ua, ya)
            model.fitted_on = st.n_points
        best = int(np.argmax(ya))
        failed = from_unit(np.array(st.U_failed).reshape(-1, st.q), b)
        res = EGOResult(x_opt=from_unit(Ua[best], b), y_opt=float(ya[best]), X=from_unit(Ua, b), y=ya, X_unit=Ua,
                        n_initial=st.n_initial if self.phase_ != "initial" else st.n_points,
                        stop_reason=self.stop_reason_ or "running", history=list(st.records),
                        surrogate=self.surrogate_ if model.fitted_on else None, bounds=b,
                        design_min_distance=min_distance(Ua[:st.n_initial or st.n_points]),
                        n_function_calls=self.n_function_calls_, refine_stop_reason=self.refine_stop_reason_,
                        n_refine=self.refiner_.n if self.refiner_ is not None else 0, X_failed=failed,
                        trials=list(self.book_.trials))
        if finished:
            self._result = res
        return res

    # -- internals ---------------------------------------------------------------
    def _report(self, record: IterationRecord) -> bool:
        self.state_.records.append(record)
        return bool(self.callback(record)) if self.callback is not None else False

    # -- the loop's hooks (suspid.optimize.trials.TrialLoop) ----------------------------
    def _loop_start(self) -> None:
        self._start()

    def _finished(self) -> bool:
        return self.phase_ == "done"

    def _beside(self) -> list[Trial]:
        return self.ask_beside()

    def _commit_trials(self, trials: list[Trial]) -> None:
        """Commit told trials, in id order, with their records."""
        st, b = self.state_, self.bounds_
        for s in trials:
            d = s.details
            if s.counted:
                self.n_function_calls_ += 1
            if s.phase != "initial":
                self._n_new += 1
            if s.J is None:
                if s.phase == "initial" and self.drop_failed_initial:
                    continue
                st.U_failed.append(s.u)
                if s.phase == "refine":
                    self.refiner_.update(d["step"], None)
                continue
            j_before = st.j_max()
            index = st.add(s.u, s.J)
            s.details["index"] = index
            if s.phase == "initial":
                record = IterationRecord(iteration=0, index=index, phase="initial", x=from_unit(s.u, b),
                                         x_unit=s.u.copy(), J=s.J, J_max=j_before,
                                         eval_seconds=s.eval_seconds if s.counted else None)
            else:
                record = IterationRecord(iteration=d["iteration"], index=index, phase=s.phase, x=from_unit(s.u, b),
                                         x_unit=s.u, J=s.J, EI=ei_from_log(d["log_ei"]), log_EI=d["log_ei"],
                                         J_max=d["j_max"], epsilon=d["epsilon"],
                                         hyperparameters=dict(d["hyperparameters"]), fit_seconds=d["fit_seconds"],
                                         search_seconds=d["search_seconds"], eval_seconds=s.eval_seconds)
            stop = self._report(record)
            if s.phase == "refine":
                if stop:
                    self.refiner_.n += 1
                    self.stop("callback")
                    return
                self.refiner_.update(d["step"], s.J)
            elif stop:
                if s.phase == "initial":  # the rest of the design is not evaluated
                    self.stop("callback")
                    return
                self.stop_reason_ = "callback"  # the rest of the batch is already evaluated
        if self.stop_reason_ == "callback" and not self.book_.queue and self.phase_ != "done":
            self.phase_ = "done"

    def _propose_trials(self, n: int = 1) -> None:
        """With nothing waiting, move on: the next phase, the next trials, or the stop."""
        if self.phase_ == "initial":
            self.state_.n_initial = self.state_.n_points
            if self.state_.n_points < 2:
                n_design = len([t for t in self.book_.trials if t.phase == "initial"])
                if self.drop_failed_initial:
                    raise SimulatorError(f"only {self.state_.n_points} of {n_design} design points could be "
                                         f"simulated; see the failures in the run's ledger")
                raise SuspidError(f"EGO needs at least 2 initial points with a value, got "
                                  f"{self.state_.n_points}")
            self.phase_ = "ego"
        elif self.phase_ == "ego":
            self._propose_ego()
        elif self.phase_ == "refine":
            self._propose_refine()

    def _propose_ego(self) -> None:
        opts = self.options_
        if self.paper_stop_(StopState(n_new=self._n_new)) or self._iteration >= opts.max_iter:
            self.stop_reason_ = self.max_iterations_.reason
            self._begin_refine()
            return
        self._iteration += 1
        p = self.proposer_.propose(self.state_, opts.max_iter - self._n_new, self.ei_rule_)
        common = dict(iteration=self._iteration, j_max=p.j_max, epsilon=p.epsilon, hyperparameters=p.hyperparameters,
                      fit_seconds=p.fit_seconds, search_seconds=p.search_seconds)
        if not p.points:  # the paper's stop: EI(w_l) < eps
            u, log_ei = p.rejected
            self.stop_reason_ = self.paper_stop_.reason_for(StopState(n_new=self._n_new, log_ei=log_ei,
                                                                      epsilon=p.epsilon))
            self._report(IterationRecord(iteration=self._iteration, index=self.state_.n_points, phase="stop",
                                         x=from_unit(u, self.bounds_), x_unit=u, J=None, EI=ei_from_log(log_ei),
                                         log_EI=log_ei, J_max=p.j_max, epsilon=p.epsilon,
                                         hyperparameters=dict(p.hyperparameters), fit_seconds=p.fit_seconds,
                                         search_seconds=p.search_seconds))
            self._begin_refine()
            return
        for u, log_ei in p.points:
            self.book_.new(u, "ego", log_ei=log_ei, **common)

    def _begin_refine(self) -> None:
        ro = self.options_.refine
        if not (ro.enabled and ro.max_iter > 0):
            self.phase_ = "done"
            return
        first = max((r.iteration for r in self.state_.records if r.phase == "ego"), default=0) + 1
        self.refiner_ = TrustRegionRefiner(self.surrogate_, self.options_, first)
        self.phase_ = "refine"

    def _propose_refine(self) -> None:
        step = self.refiner_.propose(self.state_)
        if step is None:
            self.refine_stop_reason_ = self.refiner_.reason
            self.phase_ = "done"
            return
        self.book_.new(step.u, "refine", iteration=step.iteration, log_ei=step.log_ei, j_max=step.j_max,
                       epsilon=step.epsilon, hyperparameters=step.hyperparameters, fit_seconds=step.fit_seconds,
                       search_seconds=step.search_seconds, step=step)



# -- the loops of the pipeline and of the notebook ---------------------------------------

def run_ego(func: Callable[[np.ndarray], float], bounds, *, ego: EGOOptions | None = None,
            design: DesignOptions | None = None, surrogate: Surrogate | None = None,
            X_init: np.ndarray | None = None, y_init: np.ndarray | None = None,
            callback: Callback | None = None,
            func_batch: Callable[[np.ndarray], Sequence[float]] | None = None) -> EGOResult:
    """Maximise ``func`` over the box ``bounds`` by EGO: the ask/tell loop of :class:`EGO`.

    Batch EGO (``ego.batch = k > 1``): each iteration's k points (kriging
    believer, :class:`suspid.optimize.loop.EIProposer`) are evaluated together
    through ``func_batch(X (k, q)) -> k values`` (so that k workers stay
    busy), or one by one through ``func`` when it is None. The EI stop applies
    to the first point of a batch; later points whose EI falls below eps are
    not evaluated. ``batch = 1`` is the paper's loop exactly.

    :param func: ``func(w) -> float`` with ``w (q,)`` in SI units inside ``bounds``.
    :param bounds: ``(q, 2)`` lower and upper bounds, SI units.
    :param ego: the ``ego:`` options (defaults when None).
    :param design: the ``design:`` options, used when ``X_init`` is None.
    :param surrogate: a surrogate instance (default: ``gpy-kriging`` with default options).
    :param X_init: ``(n0, q)`` initial points in SI units, instead of the design.
    :param y_init: ``(n0,)`` their J where known, NaN where still to be evaluated.
    :param callback: called with each :class:`IterationRecord`; returning True stops.
    :param func_batch: evaluates a batch of points ``(k, q)`` SI at once (batch EGO).
    :returns: an :class:`EGOResult`.
    :raises ConfigError: bad bounds, initial points outside the box or fewer than 2.
    :raises SuspidError: ``func`` returned a non-finite value.
    """
    # The fits and the EI search work on small matrices: OpenBLAS threads only contend
    with single_blas_thread():
        opt = EGO(bounds, ego=ego, design=design, surrogate=surrogate, X_init=X_init, y_init=y_init,
                  callback=callback)
        run_trials(opt, FunctionEvaluator(func, func_batch, batch=(ego or EGOOptions()).batch))
        return opt.result()


def maximize(func: Callable[[np.ndarray], float], bounds, *, n_initial: int | None = None,
             max_iter: int = 50, tol: float = 1e-4, seed: int = 0,
             surrogate: str | Surrogate = "gpy-kriging",
             surrogate_options: dict[str, Any] | None = None, design: str = "maximin-lhs",
             X_init: np.ndarray | None = None, y_init: np.ndarray | None = None,
             callback: Callback | None = None, **search: Any) -> EGOResult:
    """Maximise ``func`` over ``bounds`` by EGO: :func:`run_ego` with keyword arguments.

    :param func: ``func(w) -> float``, ``w (q,)`` in SI units.
    :param bounds: ``(q, 2)`` lower and upper bounds, SI units.
    :param n_initial: m0 (None: :func:`suspid.optimize.design.default_n_initial`).
    :param max_iter: m1, the largest number of EGO points.
    :param tol: eps = tol * (max J - min J) stops the loop when max EI < eps.
    :param seed: seeds the design, the EI candidates and (when it has a
        ``seed`` option not given in ``surrogate_options``) the surrogate.
    :param surrogate: a registered surrogate name or an instance.
    :param design: a name in :data:`suspid.optimize.design.DESIGNS`.
    :param search: other :class:`EGOOptions` fields (``n_candidates``, ``batch``, ``refine``, ...).
    :raises ConfigError: invalid options.
    """
    ego, design_opts, model = options_for(n_initial=n_initial, max_iter=max_iter, tol=tol, seed=seed,
                                          surrogate=surrogate, surrogate_options=surrogate_options,
                                          design=design, **search)
    return run_ego(func, bounds, ego=ego, design=design_opts, surrogate=model, X_init=X_init,
                   y_init=y_init, callback=callback)


def options_for(*, n_initial: int | None = None, max_iter: int = 50, tol: float = 1e-4, seed: int = 0,
                surrogate: str | Surrogate = "gpy-kriging", surrogate_options: dict[str, Any] | None = None,
                design: str = "maximin-lhs", **search: Any) -> tuple[EGOOptions, DesignOptions, Surrogate]:
    """The validated ``(EGOOptions, DesignOptions, surrogate)`` that :func:`maximize` uses for its keywords,
    e.g. to build the same run as an :class:`EGO` ask/tell object.

    :raises ConfigError: invalid options.
    """
    ego = parse_options(EGOOptions, dict(max_iter=max_iter, tol=tol, seed=seed, **search), "ego")
    design_opts = parse_options(DesignOptions, dict(method=design, n_initial=n_initial, seed=seed), "design")
    return ego, design_opts, make_surrogate(surrogate, surrogate_options, seed)
