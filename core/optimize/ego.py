"""Efficient Global Optimization (EGO) of an expensive objective J (paper §3.2, eq. 9).

The loop is the paper's pseudo code, for maximisation::

    fit J~ on the m0 initial points (w_j, J(w_j))
    for l = m0 + 1 .. m0 + m1:
        J_max = max_j J(w_j)
        w_l   = argmax_w EI(w),  EI(w) = E[max(0, J~(w) - J_max)]   (closed form)
        if EI(w_l) < eps: break           eps = tol * (max J - min J), current data
        evaluate J(w_l); refit J~ with it
    return w_opt = the best evaluated point

Everything happens in the unit cube ``[0, 1]^q``; the objective is called with
points of the parameter box ``bounds (q, 2)`` (SI units): ``func(w (q,)) -> float``.
A caller who prefers unit coordinates passes ``bounds = [[0, 1]] * q``.

EI search. The expected improvement is maximised over the box by L-BFGS-B on
log EI (with its analytic gradient from the surrogate's
``predict_gradients``; finite differences when the surrogate lacks them),
started from the ``n_starts`` (8) best distinct points of a candidate set made
of a scrambled Sobol' set of ``n_candidates`` (2000) points plus ``n_local``
(30) Gaussian perturbations at each of the scales 1e-3, 1e-2, 1e-1 of the
``n_best`` (3) best evaluated points; each run has at most ``search_maxiter``
(200) iterations. Log EI is computed without underflow, so the search still
has a slope far from the data, where EI itself is ~1e-300. On Branin, checked
against a 301 x 301 grid at every iteration of 3 runs, the search never
returned less than the grid's maximum of EI.

Choices tuned on the standard functions (``benchmarks/RESULTS.md``): m0 =
:func:`suspid.optimize.design.default_n_initial` = min(2^q, 10 q); the surrogate's
defaults (Matérn 5/2 ARD, length-scales <= 2 box widths).

API for the end-to-end pipeline
-------------------------------
:func:`run_ego` takes validated options (:class:`EGOOptions` for the ``ego:``
section, :class:`suspid.optimize.design.DesignOptions` for ``design:``) and a surrogate
instance (``suspid.registry.get("surrogate", name)(**options)``); :func:`maximize`
is the same with plain keyword arguments.

(a) Own objective and own initial data: ``func(w) -> float`` is any callable
    on SI points; ``X_init (n0, q)`` (SI) replaces the design, and ``y_init
    (n0,)`` gives values already known (NaN where still to be evaluated), so
    cached evaluations are not recomputed.
(b) Ledger: ``callback(record)`` is called once per initial point (phase
    ``"initial"``), after each EGO iteration (phase ``"ego"``), for the
    iteration that stops on EI < eps (phase ``"stop"``, ``J`` is None) and
    after each point of the optional refinement (phase ``"refine"``) with an
    :class:`IterationRecord` (iteration, point in SI and unit coordinates, J,
    EI, J_max, eps, surrogate hyperparameters, fit/search/evaluation times).
    A callback returning True stops the run (``stop_reason == "callback"``).
(c) Determinism: the design is seeded by ``design.seed``; the EI candidates
    of the iteration that follows the n-th evaluation by ``(ego.seed, n)``
    (by ``(ego.seed, 2, n)`` in the refinement);
    the surrogate by its own ``seed`` option. So a killed run replayed with a
    ``func`` that returns cached J values retraces the same points. (Passing
    every evaluated point back as ``X_init`` also works, but it is a
    different run: the design and the surrogate's warm starts differ.)

Public API: :class:`EGOOptions`, :class:`IterationRecord`, :class:`EGOResult`,
:func:`run_ego`, :func:`maximize`, :func:`make_surrogate`,
:func:`expected_improvement`, :func:`log_expected_improvement`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from scipy.optimize import minimize
from scipy.special import erfcx, log_ndtr, ndtr
from scipy.stats import qmc

from suspid import registry
from suspid.optimize.design import DesignOptions, check_bounds, from_unit, make_design, min_distance, to_unit
from suspid.errors import ConfigError, SuspidError
from suspid.interfaces import Surrogate
from suspid.infra.threads import single_blas_thread

__all__ = ["EGOOptions", "IterationRecord", "EGOResult", "run_ego", "maximize", "make_surrogate",
           "expected_improvement", "log_expected_improvement"]


class RefineOptions(BaseModel):
    """The ``ego.refine:`` section: a local refinement after the paper's loop (beyond the paper).

    Why. The paper's loop fits one Kriging model on every point. After a
    large space-filling design (m0 = 500) that global model cannot resolve J
    near its maximum to the tolerance: its EI falls below eps while w_opt is
    still a few % of the admissible interval from the maximiser of J. On the
    Table 1 analogue the paper's loop stops 0.1 below the maximum of the
    likelihood J, with errors up to 3.6 % (``benchmarks/RESULTS.md``).

    What. A model-based trust-region search (Conn, Scheinberg and Vicente,
    *Introduction to Derivative-Free Optimization*, 2009, ch. 10) whose model
    is a local Kriging fit, as in local approximate GPs (Gramacy and Apley,
    2015). Each step fits a local surrogate (a new instance of the run's
    surrogate class, same options) on the ``n_points`` evaluated points
    nearest to the current best w_opt (Euclidean distance in [0, 1]^q),
    evaluates J at the maximiser of its mean over the box w_opt ± ``radius``
    (clipped to [0, 1]^q), and moves the box to the new point when J improved
    by more than the paper's eps = tol * (max J - min J). When the mean peaks
    at a point already evaluated, the step takes the EI maximiser in the box
    instead; if that too is a known point, the step counts as a failure
    without a simulation. After ``patience`` failures in a row the radius is
    halved (it never grows). The refinement stops when the radius falls below
    ``min_radius`` (``"radius_below_min"``: w_opt is then located to about
    that fraction of each admissible interval) or after ``max_iter`` points
    (``"max_iter"``). The run's global surrogate is not touched by the local
    fits; with ``refit_final`` it is refitted on every point at the end.
    The refinement evaluates one point per step, also with ``ego.batch`` > 1.

    The step maximises the mean, not EI: inside a small box EI prefers the
    corners where the local model is least sure, and on the Table 1 analogue
    EI steps failed four times in a row while mean steps climbed to the
    maximiser found by a Nelder-Mead search on J itself.

    :ivar enabled: run the refinement after the paper's loop stops (on EI < eps or m1).
    :ivar max_iter: largest number of refinement points.
    :ivar n_points: size of the local data set (default 10 q).
    :ivar radius: initial half-width of the trust region in [0, 1] units.
    :ivar min_radius: the refinement stops below this half-width.
    :ivar patience: steps without improvement before the radius is halved.
    """

    model_config = ConfigDict(extra="forbid")

    enabled: bool = False
    max_iter: int = Field(default=30, ge=0)
    n_points: int | None = Field(default=None, ge=3)
    radius: float = Field(default=0.1, gt=0, le=0.5)
    min_radius: float = Field(default=0.01, gt=0)
    patience: int = Field(default=2, ge=1)


class EGOOptions(BaseModel):
    """The ``ego:`` config section.

    :ivar max_iter: m1, the largest number of EGO points after the initial design.
    :ivar tol: the EI stop: eps = tol * (max J - min J) over the current data;
        with tol = 0 (or all J equal) the loop runs to ``max_iter``.
    :ivar seed: seeds the EI candidate sets (one stream per iteration).
    :ivar n_candidates: size of the space-filling (Sobol') candidate set.
    :ivar n_best: how many of the best evaluated points seed local candidates.
    :ivar n_local: Gaussian perturbations per best point and per scale.
    :ivar n_starts: L-BFGS-B starts, the best candidates by EI.
    :ivar search_maxiter: iterations of each L-BFGS-B run.
    :ivar refit_final: refit the surrogate on every point at the end (for
        the sensitivity report) when the last point was not yet in it.
    :ivar batch: points per iteration (kriging believer, see :func:`run_ego`).
    :ivar refine: the local refinement after the loop (:class:`RefineOptions`, off by default).
    """

    model_config = ConfigDict(extra="forbid")

    max_iter: int = Field(default=50, ge=0)
    tol: float = Field(default=1e-4, ge=0)
    seed: int = 0
    n_candidates: int = Field(default=2000, ge=1)
    n_best: int = Field(default=3, ge=0)
    n_local: int = Field(default=30, ge=0)
    n_starts: int = Field(default=8, ge=1)
    search_maxiter: int = Field(default=200, ge=1)
    refit_final: bool = True
    batch: int = Field(default=1, ge=1, description="points per iteration (kriging believer); 1 = the paper's loop")
    refine: RefineOptions = Field(default_factory=RefineOptions)


@dataclass
class IterationRecord:
    """One line of the run ledger, passed to ``callback`` (see the module docstring).

    :ivar iteration: 0 for initial points, then l - m0 = 1, 2, ... for EGO points.
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
        (``eval_seconds`` is None when J came from ``y_init``).
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
class EGOResult:
    """Outcome of an EGO run.

    :ivar x_opt: ``(q,)`` w_opt, the best evaluated point, SI units.
    :ivar y_opt: J(w_opt).
    :ivar X: ``(n, q)`` every point in order (initial design first), SI units.
    :ivar y: ``(n,)`` J at those points.
    :ivar X_unit: ``(n, q)`` the same points in ``[0, 1]^q``.
    :ivar n_initial: m0, the number of initial points.
    :ivar stop_reason: why the paper's loop stopped: ``"ei_below_tol"``,
        ``"max_iter"`` or ``"callback"``.
    :ivar refine_stop_reason: why the refinement stopped (``"radius_below_min"``,
        ``"max_iter"``, ``"callback"``), None without one.
    :ivar n_refine: points evaluated by the refinement (included in ``n_iterations``).
    :ivar history: every :class:`IterationRecord`, in order.
    :ivar surrogate: the surrogate fitted on all points (with
        ``refit_final=False``: its last fit in the paper's loop, without the
        last point and the refinement's points); None if it was never fitted.
    :ivar bounds: ``(q, 2)`` the parameter box.
    :ivar design_min_distance: smallest pairwise distance of the initial
        points in ``[0, 1]^q``.
    :ivar n_function_calls: calls of ``func`` made by this run (values from
        ``y_init`` are not counted).
    """

    x_opt: np.ndarray
    y_opt: float
    X: np.ndarray
    y: np.ndarray
    X_unit: np.ndarray
    n_initial: int
    stop_reason: str
    history: list[IterationRecord]
    surrogate: Surrogate | None
    bounds: np.ndarray
    design_min_distance: float
    n_function_calls: int
    refine_stop_reason: str | None = None
    n_refine: int = 0

    @property
    def n_evaluations(self) -> int:
        """Number of points with a value of J (initial ones included)."""
        return int(self.y.shape[0])

    @property
    def n_iterations(self) -> int:
        """Number of points evaluated after the initial design (EGO and refinement)."""
        return self.n_evaluations - self.n_initial


# -- expected improvement (eq. 9, maximisation) -----------------------------------

_LOG_SQRT_2PI = 0.5 * math.log(2 * math.pi)


def _log_h(z: np.ndarray) -> np.ndarray:
    """log h(z) with h(z) = φ(z) + z Φ(z) = E[max(0, z + N(0, 1))], accurate for z << 0."""
    z = np.asarray(z, dtype=float)
    out = np.empty_like(z)
    hi = z > -1.0
    zh = z[hi]
    out[hi] = np.log(np.exp(-0.5 * zh ** 2 - _LOG_SQRT_2PI) + zh * ndtr(zh))
    t = -z[~hi]  # t >= 1: h = φ(z) (1 - t R(t)), R(t) = Φ(-t) / φ(t) the Mills ratio
    big = t > 1e3
    log_1m_tr = np.empty_like(t)
    ts = t[~big]
    log_1m_tr[~big] = np.log1p(-ts * math.sqrt(math.pi / 2) * erfcx(ts / math.sqrt(2)))
    tb = t[big]  # 1 - t R(t) = t^-2 (1 - 3 t^-2 + 15 t^-4 - ...)
    log_1m_tr[big] = -2 * np.log(tb) + np.log1p(-3 / tb ** 2 + 15 / tb ** 4)
    out[~hi] = -0.5 * t ** 2 - _LOG_SQRT_2PI + log_1m_tr
    return out


def log_expected_improvement(mean: np.ndarray, variance: np.ndarray, j_max: float) -> np.ndarray:
    """log EI for maximisation: log E[max(0, J~ - J_max)] with J~ ~ N(mean, variance).

    :param mean: ``(n,)`` predictive mean; :param variance: ``(n,)`` noise-free
        predictive variance (units of J²); :param j_max: the current best J.
    :returns: ``(n,)``; ``log(max(mean - j_max, 0))`` where the variance is 0.
    """
    mean = np.asarray(mean, dtype=float)
    sigma = np.sqrt(np.maximum(np.asarray(variance, dtype=float), 0.0))
    out = np.empty_like(mean)
    pos = sigma > 0
    with np.errstate(divide="ignore"):
        out[~pos] = np.log(np.maximum(mean[~pos] - j_max, 0.0))
        z = (mean[pos] - j_max) / sigma[pos]
        out[pos] = np.log(sigma[pos]) + _log_h(z)
    return out


def _ei(log_ei: float) -> float:
    """EI from log EI, 0 where exp underflows (log EI < -745) or log EI is NaN."""
    return math.exp(log_ei) if log_ei > -745 else 0.0


def expected_improvement(mean: np.ndarray, variance: np.ndarray, j_max: float) -> np.ndarray:
    """EI(w) = (μ - J_max) Φ(z) + σ φ(z), z = (μ - J_max)/σ (paper eq. 9, maximisation).

    :returns: ``(n,)`` in units of J, >= 0.
    """
    return np.exp(log_expected_improvement(mean, variance, j_max))


_LOG_EI_FLOOR = -1e6  # where EI is this small the search objective is flat


def _log_ei_and_grad(surrogate: Surrogate, u: np.ndarray, j_max: float,
                     with_grad: bool) -> tuple[float, np.ndarray | None]:
    """log EI at one point ``u (q,)`` and its gradient ``(q,)`` (None without gradients)."""
    mean, var = surrogate.predict(u[None, :])
    log_ei = float(log_expected_improvement(mean, var, j_max)[0])
    if not with_grad:
        return max(log_ei, _LOG_EI_FLOOR), None
    if not (log_ei > _LOG_EI_FLOOR) or var[0] <= 0:
        return _LOG_EI_FLOOR, np.zeros_like(u)
    dmean, dvar = surrogate.predict_gradients(u[None, :])
    sigma = math.sqrt(var[0])
    z = (mean[0] - j_max) / sigma
    dsigma = dvar[0] / (2 * sigma)
    ratio = math.exp(float(log_ndtr(z)) - float(_log_h(np.array([z]))[0]))  # Φ(z) / h(z)
    grad = dsigma / sigma + ratio * (dmean[0] - z * dsigma) / sigma
    return log_ei, grad


# -- surrogate construction ---------------------------------------------------------

def _validated(model: type[BaseModel], section: str, values: dict[str, Any]) -> BaseModel:
    try:
        return model(**values)
    except ValidationError as exc:
        first = exc.errors()[0]
        key = ".".join([section, *(str(p) for p in first["loc"])])
        raise ConfigError(first["msg"], key=key) from None


def make_surrogate(surrogate: str | Surrogate = "gpy-kriging",
                   options: dict[str, Any] | None = None, seed: int | None = None) -> Surrogate:
    """A surrogate instance: ``surrogate`` itself, or the registered class of that name
    built with ``options``. ``seed`` is passed when the class's ``Options`` has a
    ``seed`` field that ``options`` does not set.

    :raises UnknownPluginError: no surrogate of that name (listing the available ones).
    """
    if isinstance(surrogate, Surrogate):
        return surrogate
    cls = registry.get("surrogate", surrogate)
    options = dict(options or {})
    fields = getattr(getattr(cls, "Options", None), "model_fields", {})
    if seed is not None and "seed" in fields and "seed" not in options:
        options["seed"] = seed
    if getattr(cls, "Options", None) is not None:
        _validated(cls.Options, "surrogate.options", options)
    return cls(**options)


# -- the loop -------------------------------------------------------------------------

def _candidates(U: np.ndarray, y: np.ndarray, q: int, opts: EGOOptions,
                rng: np.random.Generator, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Space-filling candidates plus perturbations of the best points, ``(n_c, q)`` in the box [lo, hi]."""
    m = 1 << max(int(math.ceil(math.log2(opts.n_candidates))), 0)
    sobol = qmc.Sobol(q, scramble=True, rng=rng).random_base2(int(math.log2(m)))[:opts.n_candidates]
    parts = [lo + sobol * (hi - lo)]
    order = np.argsort(-y, kind="stable")[:opts.n_best]
    for i in order:
        for scale in (1e-3, 1e-2, 1e-1):
            parts.append(np.clip(U[i] + scale * rng.standard_normal((opts.n_local, q)), lo, hi))
    return np.vstack(parts)


def _has_gradients(surrogate: Surrogate, u: np.ndarray) -> bool:
    """Whether the surrogate implements ``predict_gradients`` (tried at ``u (1, q)``)."""
    try:
        surrogate.predict_gradients(u)
        return True
    except NotImplementedError:
        return False


def _search(surrogate: Surrogate, U: np.ndarray, y: np.ndarray, j_max: float, opts: EGOOptions,
            rng: np.random.Generator, lo: np.ndarray | None = None,
            hi: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """argmax of EI over the box [lo, hi] (default [0, 1]^q): ``(u (q,), log EI there)``."""
    q = U.shape[1]
    lo = np.zeros(q) if lo is None else lo
    hi = np.ones(q) if hi is None else hi
    cand = _candidates(U, y, q, opts, rng, lo, hi)
    mean, var = surrogate.predict(cand)
    log_ei = log_expected_improvement(mean, var, j_max)
    log_ei = np.where(np.isfinite(log_ei), log_ei, -np.inf)
    order = np.argsort(-log_ei, kind="stable")
    starts: list[np.ndarray] = []
    for i in order:  # best distinct candidates
        if all(np.max(np.abs(cand[i] - s)) > 1e-3 for s in starts):
            starts.append(cand[i])
        if len(starts) >= opts.n_starts:
            break
    best_u, best_val = cand[order[0]], float(log_ei[order[0]])
    with_grad = _has_gradients(surrogate, cand[:1])

    def objective(u: np.ndarray):
        val, grad = _log_ei_and_grad(surrogate, u, j_max, with_grad)
        return (-val, -grad) if with_grad else -val

    def score(u: np.ndarray) -> float:
        return float(log_expected_improvement(*surrogate.predict(u[None, :]), j_max)[0])

    return _climb(objective, score, starts, lo, hi, with_grad, opts.search_maxiter, best_u, best_val)


def _climb(objective: Callable, score: Callable[[np.ndarray], float], starts: Sequence[np.ndarray],
           lo: np.ndarray, hi: np.ndarray, with_grad: bool, maxiter: int, best_u: np.ndarray,
           best_val: float) -> tuple[np.ndarray, float]:
    """Multi-start L-BFGS-B of ``objective`` (minimised; ``(value, gradient)`` when ``with_grad``)
    over the box [lo, hi]; returns the highest-``score`` point and its score, ``best_u`` if none beats it."""
    for u0 in starts:
        with np.errstate(all="ignore"):
            res = minimize(objective, u0, jac=with_grad, method="L-BFGS-B", bounds=list(zip(lo, hi)),
                           options={"maxiter": maxiter})
        u = np.clip(res.x, lo, hi)
        val = score(u)
        if val > best_val:
            best_u, best_val = u, val
    return best_u, best_val


def _search_mean(surrogate: Surrogate, centre: np.ndarray, lo: np.ndarray, hi: np.ndarray, opts: EGOOptions,
                 rng: np.random.Generator) -> np.ndarray:
    """argmax of the surrogate's mean over the box [lo, hi], started from ``centre`` and Sobol' points."""
    q = centre.shape[0]
    sobol = qmc.Sobol(q, scramble=True, rng=rng).random_base2(8)
    cand = np.vstack([centre[None, :], lo + sobol * (hi - lo)])
    mean = surrogate.predict(cand)[0]
    with_grad = _has_gradients(surrogate, cand[:1])

    def score(u: np.ndarray) -> float:
        return float(surrogate.predict(u[None, :])[0][0])

    def objective(u: np.ndarray):
        return (-score(u), -surrogate.predict_gradients(u[None, :])[0][0]) if with_grad else -score(u)

    best_u, best_val = cand[int(np.argmax(mean))], float(np.max(mean))
    return _climb(objective, score, [centre, best_u], lo, hi, with_grad, opts.search_maxiter, best_u, best_val)[0]


def _evaluate(func: Callable[[np.ndarray], float], x: np.ndarray) -> tuple[float, float]:
    t0 = time.perf_counter()
    value = func(x.copy())
    try:
        J = float(value)
    except (TypeError, ValueError):
        raise SuspidError(f"the objective returned {value!r} at w={x.tolist()}; expected a number") from None
    if not math.isfinite(J):
        raise SuspidError(f"the objective returned {J} at w={x.tolist()}; EGO needs finite values")
    return J, time.perf_counter() - t0


def run_ego(func: Callable[[np.ndarray], float], bounds, *, ego: EGOOptions | None = None,
            design: DesignOptions | None = None, surrogate: Surrogate | None = None,
            X_init: np.ndarray | None = None, y_init: np.ndarray | None = None,
            callback: Callable[[IterationRecord], bool | None] | None = None,
            func_batch: Callable[[np.ndarray], Sequence[float]] | None = None) -> EGOResult:
    """Maximise ``func`` over the box ``bounds`` by EGO (see the module docstring).

    Batch EGO (``ego.batch = k > 1``): each iteration chooses k points by the
    *kriging believer* heuristic — maximise EI, pretend J there equals the
    surrogate's mean, refit, maximise EI again, k times — then evaluates the
    k points together through ``func_batch(X (k, q)) -> k values`` (so that k
    workers stay busy), or one by one through ``func`` when it is None. The
    EI stop applies to the first point of a batch; later points whose EI
    falls below ε are not evaluated. ``batch = 1`` is the paper's loop exactly.

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
        return _run_ego(func, bounds, ego, design, surrogate, X_init, y_init, callback, func_batch)


def _run_ego(func, bounds, ego, design, surrogate, X_init, y_init, callback, func_batch) -> EGOResult:
    opts = ego or EGOOptions()
    b = check_bounds(bounds)
    q = b.shape[0]
    model = surrogate if surrogate is not None else make_surrogate("gpy-kriging", seed=opts.seed)

    if X_init is None:
        if y_init is not None:
            raise ConfigError("y_init was given without X_init")
        U = make_design(design, q)
    else:
        X0 = np.asarray(X_init, dtype=float)
        if X0.ndim != 2 or X0.shape[1] != q:
            raise ConfigError(f"X_init must have shape (n0, {q}), got {X0.shape}")
        U = to_unit(X0, b)
        if np.any(U < -1e-9) or np.any(U > 1 + 1e-9) or not np.all(np.isfinite(U)):
            raise ConfigError("X_init has points outside the bounds")
        U = np.clip(U, 0.0, 1.0)
    if U.shape[0] < 2:
        raise ConfigError(f"EGO needs at least 2 initial points, got {U.shape[0]}")
    y0 = np.full(U.shape[0], np.nan)
    if y_init is not None:
        y0 = np.asarray(y_init, dtype=float).reshape(-1)
        if y0.shape[0] != U.shape[0]:
            raise ConfigError(f"y_init has {y0.shape[0]} values for {U.shape[0]} points of X_init")

    history: list[IterationRecord] = []
    n_calls = 0
    stop_reason = "max_iter"
    ys: list[float] = []

    def report(record: IterationRecord) -> bool:
        history.append(record)
        return bool(callback(record)) if callback is not None else False

    for i, u in enumerate(U):
        x = from_unit(u, b)
        if np.isfinite(y0[i]):
            J, dt = float(y0[i]), None
        else:
            J, dt = _evaluate(func, x)
            n_calls += 1
        ys.append(J)
        if report(IterationRecord(iteration=0, index=i, phase="initial", x=x, x_unit=u.copy(), J=J,
                                  J_max=max(ys[:-1]) if i else None, eval_seconds=dt)):
            stop_reason = "callback"
            break
    n_initial = len(ys)
    U_all = [u.copy() for u in U[:n_initial]]
    fitted_on = 0

    for it in range(1, opts.max_iter + 1):
        if stop_reason == "callback":
            break
        Ua, ya = np.array(U_all), np.array(ys)
        t0 = time.perf_counter()
        model.fit(Ua, ya)
        fitted_on = len(ys)
        t_fit = time.perf_counter() - t0
        j_max = float(ya.max())
        eps = opts.tol * float(ya.max() - ya.min())
        rng = np.random.default_rng([opts.seed, 1, len(ys)])
        t0 = time.perf_counter()
        u_new, log_ei = _search(model, Ua, ya, j_max, opts, rng)
        t_search = time.perf_counter() - t0
        ei = _ei(log_ei)
        hyper = dict(model.hyperparameters_ or {})
        x_new = from_unit(u_new, b)
        if eps > 0 and log_ei < math.log(eps):  # EI(w_l) < eps, compared in log space
            stop_reason = "ei_below_tol"
            report(IterationRecord(iteration=it, index=len(ys), phase="stop", x=x_new, x_unit=u_new,
                                   J=None, EI=ei, log_EI=log_ei, J_max=j_max, epsilon=eps,
                                   hyperparameters=hyper, fit_seconds=t_fit,
                                   search_seconds=t_search))
            break
        if opts.batch == 1:
            J, dt = _evaluate(func, x_new)
            n_calls += 1
            U_all.append(u_new)
            ys.append(J)
            if report(IterationRecord(iteration=it, index=len(ys) - 1, phase="ego", x=x_new,
                                      x_unit=u_new, J=J, EI=ei, log_EI=log_ei, J_max=j_max, epsilon=eps,
                                      hyperparameters=hyper, fit_seconds=t_fit, search_seconds=t_search,
                                      eval_seconds=dt)):
                stop_reason = "callback"
                break
            continue
        # batch EGO, kriging believer: the next points as if J were the mean at the chosen ones
        chosen = [(u_new, ei, log_ei)]
        budget = opts.max_iter - (len(ys) - n_initial)
        U_b, y_b = list(Ua), list(ya)
        while len(chosen) < min(opts.batch, budget):
            u_prev = chosen[-1][0]
            U_b.append(u_prev)
            y_b.append(float(model.predict(u_prev[None, :])[0][0]))
            model.fit(np.array(U_b), np.array(y_b))
            rng_j = np.random.default_rng([opts.seed, 1, len(ys), len(chosen)])
            u_j, log_ei_j = _search(model, np.array(U_b), np.array(y_b), j_max, opts, rng_j)
            if eps > 0 and log_ei_j < math.log(eps):
                break
            chosen.append((u_j, _ei(log_ei_j), log_ei_j))
        t_search = time.perf_counter() - t0
        X_batch = np.array([from_unit(u, b) for u, _, _ in chosen])
        t0 = time.perf_counter()
        if func_batch is not None:
            values = [float(v) for v in func_batch(X_batch)]
            if len(values) != len(chosen) or not all(math.isfinite(v) for v in values):
                raise SuspidError(f"func_batch returned {values!r} for {len(chosen)} points")
        else:
            values = [_evaluate(func, x)[0] for x in X_batch]
        dt = (time.perf_counter() - t0) / len(chosen)
        n_calls += len(chosen)
        for (u_j, ei_j, log_ei_j), x_j, J in zip(chosen, X_batch, values):
            U_all.append(u_j)
            ys.append(J)
            if report(IterationRecord(iteration=it, index=len(ys) - 1, phase="ego", x=x_j, x_unit=u_j, J=J,
                                      EI=ei_j, log_EI=log_ei_j, J_max=j_max, epsilon=eps,
                                      hyperparameters=hyper, fit_seconds=t_fit, search_seconds=t_search,
                                      eval_seconds=dt)):
                stop_reason = "callback"
        if len(ys) - n_initial >= opts.max_iter:
            break

    refine_reason, n_refine = None, 0
    if opts.refine.enabled and opts.refine.max_iter > 0 and stop_reason != "callback":
        first = max((r.iteration for r in history if r.phase == "ego"), default=0) + 1
        refine_reason, n_refine = _refine(func, b, opts, model, U_all, ys, first, report)
        n_calls += n_refine

    Ua, ya = np.array(U_all), np.array(ys)
    if opts.refit_final and fitted_on != len(ys) and len(ys) >= 2:
        model.fit(Ua, ya)
        fitted_on = len(ys)
    best = int(np.argmax(ya))
    return EGOResult(x_opt=from_unit(Ua[best], b), y_opt=float(ya[best]), X=from_unit(Ua, b), y=ya,
                     X_unit=Ua, n_initial=n_initial, stop_reason=stop_reason, history=history,
                     surrogate=model if fitted_on else None, bounds=b, design_min_distance=min_distance(Ua[:n_initial]),
                     n_function_calls=n_calls, refine_stop_reason=refine_reason, n_refine=n_refine)


def _refine(func, b: np.ndarray, opts: EGOOptions, model: Surrogate, U_all: list[np.ndarray], ys: list[float],
            first_iteration: int, report: Callable[[IterationRecord], bool]) -> tuple[str, int]:
    """The local refinement of :class:`RefineOptions`; appends to ``U_all`` and ``ys`` in place.

    The local fits use a new instance of the surrogate's class with the same
    options, so the global model (its fit and its warm starts) is left as the
    paper's loop made it.

    :param first_iteration: the ``iteration`` number of the first refinement record.
    :returns: ``(stop reason, number of points evaluated)``.
    """
    ro = opts.refine
    q = b.shape[0]
    k = ro.n_points or 10 * q
    local = type(model)(**model.options)
    radius = ro.radius
    n = failures = 0
    iteration = first_iteration
    while n < ro.max_iter:
        Ua, ya = np.array(U_all), np.array(ys)
        best = int(np.argmax(ya))
        centre, j_max = Ua[best], float(ya[best])
        near = np.argsort(np.linalg.norm(Ua - centre, axis=1), kind="stable")[:k]
        eps = opts.tol * float(ya.max() - ya.min())
        lo, hi = np.clip(centre - radius, 0.0, 1.0), np.clip(centre + radius, 0.0, 1.0)
        t0 = time.perf_counter()
        local.fit(Ua[near], ya[near])
        t_fit = time.perf_counter() - t0
        rng = np.random.default_rng([opts.seed, 2, len(ys)])
        t0 = time.perf_counter()
        u_new = _search_mean(local, centre, lo, hi, opts, rng)
        if _is_evaluated(u_new, Ua[near], radius):
            # the local mean peaks at a point already known: explore the box by EI instead
            u_new, _ = _search(local, Ua[near], ya[near], j_max, opts, rng, lo, hi)
        log_ei = float(log_expected_improvement(*local.predict(u_new[None, :]), j_max)[0])
        t_search = time.perf_counter() - t0
        if _is_evaluated(u_new, Ua[near], radius):  # nothing new to learn at this scale: a failure
            failures = ro.patience
        else:
            x_new = from_unit(u_new, b)
            J, dt = _evaluate(func, x_new)
            n += 1
            U_all.append(u_new)
            ys.append(J)
            if report(IterationRecord(
                    iteration=iteration, index=len(ys) - 1, phase="refine", x=x_new, x_unit=u_new, J=J,
                    EI=_ei(log_ei), log_EI=log_ei, J_max=j_max, epsilon=eps,
                    hyperparameters=dict(local.hyperparameters_ or {}), fit_seconds=t_fit,
                    search_seconds=t_search, eval_seconds=dt)):
                return "callback", n
            iteration += 1
            failures = 0 if J > j_max + eps else failures + 1
        if failures >= ro.patience:
            radius, failures = radius / 2, 0
            if radius < ro.min_radius:
                return "radius_below_min", n
    return "max_iter", n


def _is_evaluated(u: np.ndarray, U: np.ndarray, radius: float) -> bool:
    """Whether ``u (q,)`` is one of the points ``U (n, q)``, to 1e-3 of the trust-region radius."""
    return bool(np.min(np.max(np.abs(U - u), axis=1)) <= 1e-3 * radius)


def maximize(func: Callable[[np.ndarray], float], bounds, *, n_initial: int | None = None,
             max_iter: int = 50, tol: float = 1e-4, seed: int = 0,
             surrogate: str | Surrogate = "gpy-kriging",
             surrogate_options: dict[str, Any] | None = None, design: str = "maximin-lhs",
             X_init: np.ndarray | None = None, y_init: np.ndarray | None = None,
             callback: Callable[[IterationRecord], bool | None] | None = None,
             **search: Any) -> EGOResult:
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
    :param search: other :class:`EGOOptions` fields (``n_candidates``, ``n_starts``, ...).
    :raises ConfigError: invalid options.
    """
    ego = _validated(EGOOptions, "ego", dict(max_iter=max_iter, tol=tol, seed=seed, **search))
    design_opts = _validated(DesignOptions, "design",
                             dict(method=design, n_initial=n_initial, seed=seed))
    model = make_surrogate(surrogate, surrogate_options, seed)
    return run_ego(func, bounds, ego=ego, design=design_opts, surrogate=model, X_init=X_init,
                   y_init=y_init, callback=callback)
