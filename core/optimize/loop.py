"""The pieces of the EGO loop: its state, its records, the EI proposer and the stopping rules.

The loop is the paper's pseudo code (§3.2), for maximisation::

    fit J~ on the m0 initial points (w_j, J(w_j))
    for l = m0 + 1 .. m0 + m1:
        J_max = max_j J(w_j)
        w_l   = argmax_w EI(w),  EI(w) = E[max(0, J~(w) - J_max)]   (closed form)
        if EI(w_l) < eps: break           eps = tol * (max J - min J), current data
        evaluate J(w_l); refit J~ with it
    return w_opt = the best evaluated point

As in emukit's outer loop it is cut into small pieces that
:class:`suspid.optimize.ego.EGO` composes behind an ask/tell interface:

- :class:`LoopState`: the evaluated points ``U (n_points, q)`` in ``[0, 1]^q``,
  their J ``(n_points,)``, the points whose evaluation failed and the
  :class:`IterationRecord` ledger;
- :class:`EIProposer`: fits the surrogate J~, maximises EI
  (:func:`suspid.optimize.acquisition.maximize_ei`) and returns the next
  point, or the next ``batch`` points by the kriging believer heuristic; in
  budget mode (``tol`` < ``explore_tol``) it also warps J (:func:`warp_values`),
  exploits every :data:`EXPLOIT_PERIOD`-th step (and again after a near miss)
  and sets stalled basins aside;
- :class:`~suspid.optimize.trials.MaxIterations` (m1) and
  :class:`~suspid.optimize.trials.EIBelowTolerance` (EI < eps): the paper's stopping
  rules (:mod:`suspid.optimize.trials`, where they combine with ``|``). The refinement's proposer and radius rule are in
  :mod:`suspid.optimize.refine`.

Public API: :class:`IterationRecord`, :class:`LoopOutcome`, :class:`EGOResult`, :class:`LoopState`,
:class:`Proposal`, :class:`EIProposer`, :class:`MaxIterations`,
:class:`EIBelowTolerance`, :func:`warp_values`, :data:`EXPLOIT_PERIOD`.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import yeojohnson

from suspid.interfaces import Surrogate
from suspid.optimize.acquisition import ei_from_log, log_expected_improvement, maximize_ei, maximize_mean
from suspid.optimize.options import EGOOptions
from suspid.optimize.normalize import Normalized
from suspid.optimize.trials import EIBelowTolerance, MaxIterations, Trial

__all__ = ["IterationRecord", "LoopOutcome", "EGOResult", "LoopState", "Proposal", "EIProposer", "MaxIterations",
           "EIBelowTolerance", "warp_values"]

EXPLOIT_PERIOD = 3
"""Budget mode: every EXPLOIT_PERIOD-th EGO step maximises the surrogate's mean instead of EI."""


def warp_values(y: np.ndarray) -> np.ndarray:
    """The budget mode's output warping of ``y (n,)``: standardised, then the Yeo-Johnson
    transform with the maximum-likelihood λ (the λ that makes the values most nearly Gaussian).

    The transform is increasing, so the order of the values (the best point) is kept. It
    compresses a long tail of poor values (Branin: J from -308 to -0.4), which otherwise
    sets the kernel variance and so the predicted spread far from the data.

    :returns: ``(n,)``; zeros when all values are equal, the standardised values when the
        transform is not finite.
    """
    y = np.asarray(y, dtype=float)
    sd = float(y.std())
    if not sd > 0:
        return np.zeros_like(y)
    z = (y - float(y.mean())) / sd
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        w = yeojohnson(z)[0]
    return w if np.all(np.isfinite(w)) else z



@dataclass
class IterationRecord:
    """One line of the run ledger, passed to the ``callback``.

    :ivar iteration: 0 for initial points, then l - m0 = 1, 2, ... for EGO
        iterations (a batch shares its iteration), then on for the refinement.
    :ivar index: position of the point in ``EGOResult.X`` (0-based); for the
        ``"stop"`` record, the position it would have had.
    :ivar phase: ``"initial"``, ``"ego"``, ``"stop"`` (the paper's EI stop),
        or ``"refine"`` (a point of the local refinement).
    :ivar x: ``(q,)`` the point in SI units; :ivar x_unit: the same in ``[0, 1]^q``.
    :ivar J: the objective there (None for ``"stop"``).
    :ivar EI: the expected improvement that chose the point (None for initial
        points); :ivar log_EI: its logarithm, which does not underflow.
    :ivar J_max: best J before this point; :ivar epsilon: the EI threshold then.
    :ivar hyperparameters: the surrogate's ``hyperparameters_`` dict (may be empty).
    :ivar fit_seconds, search_seconds, eval_seconds: wall times in s
        (``eval_seconds`` is None when J came from ``y_init`` or was not timed).
    """

    iteration: int
    index: int
    phase: str
    x: np.ndarray
    x_unit: np.ndarray
    J: float | None
    EI: float | None = None
    log_EI: float | None = None
    J_max: float | None = None
    epsilon: float | None = None
    hyperparameters: dict[str, Any] = field(default_factory=dict)
    fit_seconds: float = 0.0
    search_seconds: float = 0.0
    eval_seconds: float | None = None


@dataclass
class LoopOutcome:
    """The state of an optimisation loop when it ended, whatever the optimiser: the points with a
    value, the best one, why it stopped and the trials. The analysis reads it with the surrogate
    fitted on its points (:meth:`fitted_surrogate`).

    Every optimiser gives it (:meth:`suspid.interfaces.Optimizer.loop_state`): the EGO loop as
    :class:`EGOResult`, which also holds the loop's own surrogate; another optimiser from its
    points (:meth:`of_points`).

    :ivar x_opt: ``(q,)`` w_opt, the best evaluated point, SI units.
    :ivar y_opt: J(w_opt).
    :ivar X: ``(n_points, q)`` every point with a value, in order (initial design first), SI units.
    :ivar y: ``(n_points,)`` J at those points.
    :ivar X_unit: ``(n_points, q)`` the same points in ``[0, 1]^q``.
    :ivar n_initial: m0, the number of initial points.
    :ivar stop_reason: why the loop stopped: ``"ei_below_tol"``, ``"max_iter"``, ``"budget"``,
        ``"callback"`` (a callback returned True), ``"stopped"`` (:meth:`suspid.optimize.ego.EGO.stop`),
        an optimiser's own reason, or ``"running"`` for a snapshot of an unfinished run.
    :ivar refine_stop_reason: why the refinement stopped (``"radius_below_min"``,
        ``"max_iter"``, ``"callback"``, ``"stopped"``), None without one.
    :ivar n_refine: points evaluated by the refinement (included in ``n_iterations``).
    :ivar history: every :class:`IterationRecord`, in order (empty without the EGO loop).
    :ivar bounds: ``(q, 2)`` the parameter box.
    :ivar design_min_distance: smallest pairwise distance of the initial
        points in ``[0, 1]^q``.
    :ivar n_function_calls: evaluations of J made by this run, failed ones
        included (values from ``y_init`` are not counted).
    :ivar X_failed: ``(n_failed, q)`` SI points whose evaluation failed (not in ``X``).
    :ivar trials: every :class:`~suspid.optimize.trials.Trial` the run handed out, by id.
    """

    x_opt: np.ndarray
    y_opt: float
    X: np.ndarray
    y: np.ndarray
    X_unit: np.ndarray
    n_initial: int
    stop_reason: str
    history: list[IterationRecord]
    bounds: np.ndarray
    design_min_distance: float
    n_function_calls: int
    refine_stop_reason: str | None = None
    n_refine: int = 0
    X_failed: np.ndarray | None = None
    trials: list[Trial] = field(default_factory=list)

    @property
    def n_evaluations(self) -> int:
        """Number of points with a value of J (initial ones included)."""
        return int(self.y.shape[0])

    @property
    def n_iterations(self) -> int:
        """Number of points evaluated after the initial design (EGO and refinement)."""
        return self.n_evaluations - self.n_initial

    def fitted_surrogate(self, surrogate: Surrogate | None) -> Normalized | None:
        """The surrogate of J on the loop's points, behind its unit-cube input transform: ``surrogate``
        (an unfitted instance) fitted here on the points with a value (None with fewer than 2)."""
        from suspid.infra.threads import single_blas_thread
        if surrogate is None or self.n_evaluations < 2:
            return None
        with single_blas_thread():
            return Normalized(surrogate, self.bounds).fit(self.X, self.y)

    @classmethod
    def of_points(cls, x_opt: np.ndarray, y_opt: float, X: np.ndarray, y: np.ndarray, n_initial: int,
                  stop_reason: str, bounds: np.ndarray, trials: list[Trial] | None = None) -> "LoopOutcome":
        """The state of an optimiser without a model of its own, from every point it was told.

        :param X: ``(n, q)`` SI points told, in order; :param y: ``(n,)`` their J, NaN where failed.
        """
        from suspid.optimize.design import min_distance, to_unit
        ok = np.isfinite(y)
        U = to_unit(X[ok], bounds)
        return cls(x_opt=np.asarray(x_opt, float), y_opt=float(y_opt), X=X[ok], y=y[ok], X_unit=U,
                   n_initial=int(min(n_initial, ok.sum())), stop_reason=stop_reason, history=[],
                   bounds=bounds, design_min_distance=min_distance(U[:n_initial]),
                   n_function_calls=int(len(y)), X_failed=X[~ok], trials=list(trials or []))


@dataclass
class EGOResult(LoopOutcome):
    """Outcome of an EGO run (:class:`LoopOutcome`, with the EGO loop's own surrogate and records).

    :ivar surrogate: the surrogate fitted on all points, on ``[0, 1]^q`` (with
        ``refit_final=False``: its last fit in the paper's loop, without the
        last point and the refinement's points); None if it was never fitted.
    """

    surrogate: Surrogate | None = None

    def fitted_surrogate(self, surrogate: Surrogate | None = None) -> Normalized | None:
        """The loop's own surrogate behind its unit-cube input transform (``surrogate`` is not used)."""
        return Normalized(self.surrogate, self.bounds) if self.surrogate is not None else None


@dataclass
class LoopState:
    """What the loop knows: the evaluated points, in order, and the ledger.

    :ivar q: number of parameters.
    :ivar U: the points ``(q,)`` in ``[0, 1]^q``, in evaluation order.
    :ivar y: J at those points.
    :ivar U_failed: points whose evaluation failed (kept out of ``U``).
    :ivar records: every :class:`IterationRecord`, in order.
    :ivar n_initial: m0, fixed when the initial design is complete.
    """

    q: int
    U: list[np.ndarray] = field(default_factory=list)
    y: list[float] = field(default_factory=list)
    U_failed: list[np.ndarray] = field(default_factory=list)
    records: list[IterationRecord] = field(default_factory=list)
    n_initial: int = 0

    @property
    def n_points(self) -> int:
        """Number of evaluated points."""
        return len(self.y)

    @property
    def U_array(self) -> np.ndarray:
        """``(n_points, q)`` the evaluated points in [0, 1]^q."""
        return np.array(self.U).reshape(-1, self.q)

    @property
    def y_array(self) -> np.ndarray:
        """``(n_points,)`` J at the evaluated points."""
        return np.array(self.y, dtype=float)

    def j_max(self) -> float | None:
        """The current best J (None before the first value)."""
        return max(self.y) if self.y else None

    def add(self, u: np.ndarray, J: float) -> int:
        """Append a point ``u (q,)`` with its value; returns its index."""
        self.U.append(u)
        self.y.append(J)
        return len(self.y) - 1


@dataclass
class Proposal:
    """What :meth:`EIProposer.propose` returns: the points to evaluate next.

    :ivar points: ``[(u (q,), log EI), ...]`` in [0, 1]^q, in batch order (may be empty).
    :ivar rejected: the first point whose EI fell below eps, with its log EI,
        None if every point was kept. When ``points`` is empty, this is the
        point of the paper's stop record.
    :ivar j_max: J_max of the data the proposal saw; :ivar epsilon: eps then.
    :ivar hyperparameters: the surrogate's hyperparameters after the fit on the data.
    :ivar fit_seconds: time of that fit; :ivar search_seconds: time of the EI
        searches (and of the kriging believer's refits).
    """

    points: list[tuple[np.ndarray, float]]
    rejected: tuple[np.ndarray, float] | None
    j_max: float
    epsilon: float
    hyperparameters: dict[str, Any]
    fit_seconds: float
    search_seconds: float

    @property
    def EIs(self) -> list[float]:
        """EI of each point of ``points``, 0 where it underflows."""
        return [ei_from_log(v) for _, v in self.points]


class EIProposer:
    """Fits J~ on the data and returns the maximiser(s) of EI (the paper's step).

    Batch (``batch = k > 1``), the *kriging believer* heuristic: maximise EI,
    pretend J there equals the surrogate's mean, refit, maximise EI again, k
    times; a later point whose EI falls below eps ends the batch early.
    ``k = 1`` is the paper's loop exactly.

    Failed points (evaluation returned no value) enter the fit with the worst
    J seen, so that EI is not drawn back to them.

    Budget mode (``tol`` < ``explore_tol``): when a step is :meth:`stalled`,
    with ``explore = "set-aside"`` the basin of the incumbent (the ellipsoid of
    one fitted length-scale around it, in [0, 1]^q) is set aside for the rest
    of the run, and this and every later step maximise EI over the rest of the
    box with J_max the best J outside the basins set aside. A stalled step
    there sets the next basin aside. Why: the model's length-scales are those
    of the basin it has explored, so it predicts other basins with confidence
    and wrongly; EI against the global J_max never follows up a second basin
    whose points are below the incumbent. Against the best J outside, it
    does, and climbs it (on Hartmann 6, whose local maximum traps EI otherwise:
    ``benchmarks/RESULTS.md``, "EGO"). ``explore = "random"`` evaluates a
    uniformly random point instead, which did not help there.

    Budget mode also changes the step itself, for a run that must get close
    to the maximum within its budget rather than stop on the paper's EI rule:

    - EI is maximised on a second instance of the surrogate's class fitted to
      :func:`warp_values` of J (the run's surrogate is still fitted to J, for
      the records and the result). Poor values far below the maximum
      (Branin: J from -308 to -0.4) otherwise set the kernel variance, and so
      a predicted spread far from the data that draws EI to corners.
    - Every :data:`EXPLOIT_PERIOD`-th step evaluates the maximiser of the
      model's mean instead of EI's, when it lies outside the basins set aside,
      away from the evaluated points and above the best J there. EI alone
      keeps spending points on other basins and corners once a basin is found,
      and reaches the maximum to 1 % slowly. A fixed cycle of exploration
      steps and a pure exploitation step is also how Regis and Shoemaker's
      CORS-RBF (J. Global Optim., 2005) balances the two.
    - An exploitation step of the cycle that misses J_max by less than
      ``explore_tol`` * (max J - min J) (:meth:`near_miss`) is followed by a
      second one, on the data with its point. A point next to the maximum
      that misses it by a hair shows the model's curvature there wrong, not
      its basin: refitted with that point, the mean's maximiser is usually at
      the top, where the fixed cycle would spend EI steps in other basins first.

    What these rules achieve (evaluations to reach 1 % on standard test
    functions, against peer optimisers) is measured by ``benchmarks/bench_ego.py``:
    ``benchmarks/RESULTS.md``, "EGO".

    The records of a budget-mode step carry EI and eps of the warped J.

    Determinism: the EI candidates of the iteration that follows the n-th
    evaluation are drawn from ``default_rng([seed, 1, n])`` (``[seed, 1, n, j]``
    for the j-th point of a batch), the starts of an exploitation step from
    ``default_rng([seed, 3, n])``.

    :param surrogate: the run's surrogate, refitted in place (warm starts).
    :param opts: the ``ego:`` options (search fields, ``seed``, ``batch``).
    """

    def __init__(self, surrogate: Surrogate, opts: EGOOptions) -> None:
        self.surrogate = surrogate
        self.opts = opts
        self.fitted_on = 0  # number of evaluated points in the last fit on real data
        self.n_explore = 0  # exploration steps taken (see :meth:`stalled`)
        self.basins: list[tuple[np.ndarray, np.ndarray]] = []  # (centre (q,), length-scales (q,)) set aside
        self.n_steps = 0  # EGO steps proposed (for the budget mode's exploitation cycle)
        self._warped: Surrogate | None = None  # budget mode: J~ of the warped J
        self._exploited: tuple[np.ndarray, float] | None = None  # last cycle exploitation point, J_max before it

    @property
    def budget_mode(self) -> bool:
        """``tol`` < ``explore_tol``: the run spends a budget rather than stopping on the paper's EI rule."""
        return self.opts.tol < self.opts.explore_tol

    def _search_model(self, Ua: np.ndarray, ya: np.ndarray) -> tuple[Surrogate, np.ndarray]:
        """The model EI is maximised on and its data ``(n,)``: the run's surrogate on J, or in
        budget mode a second instance of its class on :func:`warp_values` of J."""
        if not self.budget_mode:
            return self.surrogate, ya
        if self._warped is None:
            self._warped = type(self.surrogate)(**self.surrogate.options)
        yw = warp_values(ya)
        self._warped.fit(Ua, yw)
        return self._warped, yw

    def _outside(self, X: np.ndarray) -> np.ndarray:
        """``(n,) bool``: points of ``X (n, q)`` outside every basin set aside."""
        ok = np.ones(X.shape[0], dtype=bool)
        for c, ls in self.basins:
            ok &= np.sqrt(np.sum(((X - c) / ls) ** 2, axis=1)) >= 1.0
        return ok

    def _set_aside(self, U: np.ndarray, y: np.ndarray, model: Surrogate) -> None:
        """Set aside the basin of the best point outside the basins already set aside: the
        ellipsoid of one length-scale of the current model around it."""
        out = self._outside(U)
        if not np.any(out):
            return
        best = np.flatnonzero(out)[int(np.argmax(y[out]))]
        ls = np.asarray((model.hyperparameters_ or {}).get("lengthscales", []), dtype=float)
        if ls.shape != (U.shape[1],) or not np.all(ls > 0):
            ls = np.full(U.shape[1], 0.1)
        self.basins.append((U[best].copy(), ls))

    def stalled(self, u: np.ndarray, log_ei: float, U: np.ndarray, y: np.ndarray) -> bool:
        """Whether the EI maximiser ``u (q,)`` is a step that teaches the model nothing.

        Either EI < ``explore_tol`` * (max J - min J): the model is sure that no
        point improves on J_max by more than that (the paper's stop with
        tol = ``explore_tol``); or ``u`` is within ``explore_distance`` (in each
        unit coordinate) of an evaluated point of ``U (n_points, q)``. In both
        cases EI keeps returning to the incumbent, whose value is already known,
        and the model, unchanged, proposes the same again (on Hartmann 6 with
        tol = 0 such a loop re-evaluated its local maximum or sampled corners
        until the budget was spent).
        """
        opts = self.opts
        threshold = opts.explore_tol * float(y.max() - y.min())
        if threshold > 0 and log_ei < math.log(threshold):
            return True
        return bool(np.min(np.max(np.abs(U - u), axis=1)) < opts.explore_distance)

    def explore(self, model: Surrogate, j_max: float, rng: np.random.Generator, q: int) -> tuple[np.ndarray, float]:
        """An exploration step: a uniformly random point of [0, 1]^q, and its log EI."""
        u = rng.random(q)
        return u, float(log_expected_improvement(*model.predict(u[None, :]), j_max)[0])

    def _search(self, model: Surrogate, Ua: np.ndarray, ya: np.ndarray, y_real: np.ndarray, j_max: float,
                rng: np.random.Generator) -> tuple[np.ndarray, float]:
        """The EI maximiser; with basins set aside, over the rest of the box, against the best J there."""
        if not self.basins:
            return maximize_ei(model, Ua, ya, j_max, self.opts, rng)
        out = self._outside(Ua)
        out_real = out[:len(y_real)]
        j_out = float(y_real[out_real].max()) if np.any(out_real) else float(y_real.min())
        U_out, y_out = (Ua[out], ya[out]) if np.any(out) else (Ua, ya)
        return maximize_ei(model, U_out, y_out, j_out, self.opts, rng, allowed=self._outside)

    def _exploit(self, model: Surrogate, U: np.ndarray, y: np.ndarray,
                 rng: np.random.Generator, again: bool = False) -> tuple[np.ndarray, float] | None:
        """Budget mode, every ``EXPLOIT_PERIOD``-th step and, with ``again``, the step after
        a :meth:`near_miss`: the maximiser of the model's mean, started from the best point
        outside the basins set aside, and its log EI; None when it lies in a basin set aside,
        within ``max(explore_distance, 1e-4)`` (each unit coordinate) of an evaluated point of
        ``U (n_points, q)``, or where the mean does not exceed that best ``y (n_points,)``."""
        if not self.budget_mode or not (again or self.n_steps % EXPLOIT_PERIOD == 0):
            return None
        out = self._outside(U)
        if not np.any(out):
            return None
        best = np.flatnonzero(out)[int(np.argmax(y[out]))]
        q = U.shape[1]
        u = maximize_mean(model, U[best], np.zeros(q), np.ones(q), self.opts, rng)
        mean, var = model.predict(u[None, :])
        if (not self._outside(u[None, :])[0] or float(mean[0]) <= float(y[best])
                or np.min(np.max(np.abs(U - u), axis=1)) < max(self.opts.explore_distance, 1e-4)):
            return None
        return u, float(log_expected_improvement(mean, var, float(y[best]))[0])

    def near_miss(self, U: np.ndarray, y: np.ndarray) -> bool:
        """Whether the last step was a cycle's exploitation step whose point, now among the
        evaluated ``U (n_points, q)`` with J ``y (n_points,)``, did not improve on the J_max
        before it but came within ``explore_tol`` * (max J - min J) of it.

        Such a step reached the top of the incumbent's basin, to the resolution at which
        the loop judges improvements (the scale of :meth:`stalled`), and missed the
        maximum only because the model's curvature there is not yet known: its new
        point, next to the maximum, is the one the model lacked. The next step then
        exploits again, once. A step that misses by more has shown the model wrong
        about the basin on a larger scale, and the cycle goes on with EI.
        """
        if self._exploited is None:
            return False
        u, j_before = self._exploited
        hit = np.flatnonzero(np.max(np.abs(U - u), axis=1) <= 1e-12)
        threshold = self.opts.explore_tol * float(y.max() - y.min())
        return bool(hit.size) and 0.0 <= j_before - float(y[hit[0]]) < threshold

    def _data(self, state: LoopState) -> tuple[np.ndarray, np.ndarray]:
        U, y = state.U_array, state.y_array
        if state.U_failed:
            U = np.vstack([U, np.array(state.U_failed)])
            y = np.concatenate([y, np.full(len(state.U_failed), y.min())])
        return U, y

    def propose(self, state: LoopState, n_max: int, stop: EIBelowTolerance) -> Proposal:
        """Up to ``min(batch, n_max)`` new points for the data of ``state``.

        :param n_max: the budget left (at least 1).
        :param stop: the EI rule: a point with EI < eps is not kept.
        """
        opts, model = self.opts, self.surrogate
        Ua, ya = self._data(state)
        y_real = state.y_array
        t0 = time.perf_counter()
        model.fit(Ua, ya)
        self.fitted_on = state.n_points
        search, ys = self._search_model(Ua, ya)
        t_fit = time.perf_counter() - t0
        ys_real = ys[:len(y_real)]
        j_max = float(ys_real.max())
        eps = stop.epsilon(ys_real)
        rng = np.random.default_rng([opts.seed, 1, state.n_points])
        t0 = time.perf_counter()
        self.n_steps += 1
        hyper = dict(model.hyperparameters_ or {})
        points: list[tuple[np.ndarray, float]] = []
        rejected = None
        again = self.near_miss(Ua[:len(y_real)], y_real)
        exploit = self._exploit(search, Ua[:len(y_real)], ys_real, np.random.default_rng([opts.seed, 3, state.n_points]),
                                again)
        self._exploited = (exploit[0], float(y_real.max())) if exploit is not None and not again else None
        if exploit is not None:
            points.append(exploit)
        else:
            u_new, log_ei = self._search(search, Ua, ys, ys_real, j_max, rng)
            if stop.below(log_ei, eps):
                rejected = (u_new, log_ei)
            else:
                if self.stalled(u_new, log_ei, Ua, ys_real):
                    self.n_explore += 1
                    if opts.explore == "set-aside":
                        self._set_aside(Ua[:len(y_real)], ys_real, search)
                        u_new, log_ei = self._search(search, Ua, ys, ys_real, j_max, rng)
                    if opts.explore == "random" or not np.all(self._outside(u_new[None, :])):
                        u_new, log_ei = self.explore(search, j_max, rng, state.q)
                points.append((u_new, log_ei))
        U_b, y_b = list(Ua), list(ys)
        while rejected is None and len(points) < min(opts.batch, n_max):
            u_prev = points[-1][0]
            U_b.append(u_prev)
            y_b.append(float(search.predict(u_prev[None, :])[0][0]))
            search.fit(np.array(U_b), np.array(y_b))
            rng_j = np.random.default_rng([opts.seed, 1, state.n_points, len(points)])
            u_j, log_ei_j = self._search(search, np.array(U_b), np.array(y_b), ys_real, j_max, rng_j)
            if stop.below(log_ei_j, eps):
                rejected = (u_j, log_ei_j)
                break
            points.append((u_j, log_ei_j))
        return Proposal(points=points, rejected=rejected, j_max=float(y_real.max()), epsilon=eps, hyperparameters=hyper,
                        fit_seconds=t_fit, search_seconds=time.perf_counter() - t0)
