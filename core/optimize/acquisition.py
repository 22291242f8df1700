"""The expected improvement (paper eq. 9) and its maximisation over a box.

EI for maximisation: EI(w) = E[max(0, J~(w) - J_max)] with J~(w) ~ N(μ(w), σ²(w))
the surrogate's noise-free prediction, in closed form
EI = (μ - J_max) Φ(z) + σ φ(z), z = (μ - J_max) / σ.

EI search (:func:`maximize_ei`). EI is maximised over a box (default the
unit cube ``[0, 1]^q``) by L-BFGS-B on log EI (with its analytic gradient
from the surrogate's ``predict_gradients``; finite differences when the
surrogate lacks them), started from the ``n_starts`` best distinct points of
a candidate set made of a scrambled Sobol' set of ``n_candidates`` points
plus ``n_local`` Gaussian perturbations at each of the scales 1e-3, 1e-2,
1e-1 of the ``n_best`` best evaluated points; each run has at most
``search_maxiter`` iterations (the fields of
:class:`suspid.optimize.options.EGOOptions`). Log EI is computed without
underflow, so the search still has a slope far from the data, where EI
itself is ~1e-300. On Branin, checked against a 301 x 301 grid at every
iteration of 3 runs, the search never returned less than the grid's maximum.

Points are in the unit cube: ``U (n_points, q)``; values ``y (n_points,)`` in units of J.

Public API: :func:`expected_improvement`, :func:`log_expected_improvement`,
:func:`ei_from_log`, :func:`log_ei_and_grad`, :func:`maximize_ei`,
:func:`maximize_mean`.
"""

from __future__ import annotations

import math
from typing import Callable, Sequence

import numpy as np
from scipy.optimize import minimize
from scipy.special import erfcx, log_ndtr, ndtr
from scipy.stats import qmc

from suspid.interfaces import Surrogate
from suspid.optimize.options import EGOOptions

__all__ = ["expected_improvement", "log_expected_improvement", "ei_from_log", "log_ei_and_grad",
           "maximize_ei", "maximize_mean"]

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

    :param mean: ``(n_points,)`` predictive mean; :param variance: ``(n_points,)``
        noise-free predictive variance (units of J²); :param j_max: the current best J.
    :returns: ``(n_points,)``; ``log(max(mean - j_max, 0))`` where the variance is 0.
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


def ei_from_log(log_ei: float) -> float:
    """EI from log EI, 0 where exp underflows (log EI < -745) or log EI is NaN."""
    return math.exp(log_ei) if log_ei > -745 else 0.0


def expected_improvement(mean: np.ndarray, variance: np.ndarray, j_max: float) -> np.ndarray:
    """EI(w) = (μ - J_max) Φ(z) + σ φ(z), z = (μ - J_max)/σ (paper eq. 9, maximisation).

    :returns: ``(n_points,)`` in units of J, >= 0.
    """
    return np.exp(log_expected_improvement(mean, variance, j_max))


_LOG_EI_FLOOR = -1e6  # where EI is this small the search objective is flat


def log_ei_and_grad(surrogate: Surrogate, u: np.ndarray, j_max: float,
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


def has_gradients(surrogate: Surrogate, u: np.ndarray) -> bool:
    """Whether the surrogate implements ``predict_gradients`` (tried at ``u (1, q)``)."""
    try:
        surrogate.predict_gradients(u)
        return True
    except NotImplementedError:
        return False


def candidates(U: np.ndarray, y: np.ndarray, opts: EGOOptions, rng: np.random.Generator,
               lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Start candidates ``(n_c, q)`` in the box [lo, hi]: a scrambled Sobol' set and
    Gaussian perturbations of the best evaluated points of ``U (n_points, q)``."""
    q = U.shape[1]
    m = 1 << max(int(math.ceil(math.log2(opts.n_candidates))), 0)
    sobol = qmc.Sobol(q, scramble=True, rng=rng).random_base2(int(math.log2(m)))[:opts.n_candidates]
    parts = [lo + sobol * (hi - lo)]
    order = np.argsort(-y, kind="stable")[:opts.n_best]
    for i in order:
        for scale in (1e-3, 1e-2, 1e-1):
            parts.append(np.clip(U[i] + scale * rng.standard_normal((opts.n_local, q)), lo, hi))
    return np.vstack(parts)


def maximize_ei(surrogate: Surrogate, U: np.ndarray, y: np.ndarray, j_max: float, opts: EGOOptions,
                rng: np.random.Generator, lo: np.ndarray | None = None,
                hi: np.ndarray | None = None,
                allowed: Callable[[np.ndarray], np.ndarray] | None = None) -> tuple[np.ndarray, float]:
    """argmax of EI over the box [lo, hi] (default [0, 1]^q), see the module docstring.

    :param U: ``(n_points, q)`` the data in [0, 1]^q (for the local candidates);
        :param y: ``(n_points,)`` their J.
    :param allowed: ``allowed(X (n, q)) -> (n,) bool``, the part of the box to search
        (default all); the result is an allowed point when some candidate is.
    :returns: ``(u (q,), log EI there)``.
    """
    q = U.shape[1]
    lo = np.zeros(q) if lo is None else lo
    hi = np.ones(q) if hi is None else hi
    cand = candidates(U, y, opts, rng, lo, hi)
    mean, var = surrogate.predict(cand)
    log_ei = log_expected_improvement(mean, var, j_max)
    log_ei = np.where(np.isfinite(log_ei), log_ei, -np.inf)
    if allowed is not None:
        ok = allowed(cand)
        if np.any(ok):
            cand, log_ei = cand[ok], log_ei[ok]
    order = np.argsort(-log_ei, kind="stable")
    starts: list[np.ndarray] = []
    for i in order:  # best distinct candidates
        if all(np.max(np.abs(cand[i] - s)) > 1e-3 for s in starts):
            starts.append(cand[i])
        if len(starts) >= opts.n_starts:
            break
    best_u, best_val = cand[order[0]], float(log_ei[order[0]])
    with_grad = has_gradients(surrogate, cand[:1])

    def objective(u: np.ndarray):
        val, grad = log_ei_and_grad(surrogate, u, j_max, with_grad)
        return (-val, -grad) if with_grad else -val

    def score(u: np.ndarray) -> float:
        return float(log_expected_improvement(*surrogate.predict(u[None, :]), j_max)[0])

    u, val = _climb(objective, score, starts, lo, hi, with_grad, opts.search_maxiter, best_u, best_val)
    if allowed is not None and not allowed(u[None, :])[0]:
        return best_u, best_val  # the climb left the allowed part: its best candidate
    return u, val


def maximize_mean(surrogate: Surrogate, centre: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  opts: EGOOptions, rng: np.random.Generator) -> np.ndarray:
    """argmax ``u (q,)`` of the surrogate's mean over the box [lo, hi], started from
    ``centre (q,)`` and the best of 256 Sobol' points."""
    q = centre.shape[0]
    sobol = qmc.Sobol(q, scramble=True, rng=rng).random_base2(8)
    cand = np.vstack([centre[None, :], lo + sobol * (hi - lo)])
    mean = surrogate.predict(cand)[0]
    with_grad = has_gradients(surrogate, cand[:1])

    def score(u: np.ndarray) -> float:
        return float(surrogate.predict(u[None, :])[0][0])

    def objective(u: np.ndarray):
        return (-score(u), -surrogate.predict_gradients(u[None, :])[0][0]) if with_grad else -score(u)

    best_u, best_val = cand[int(np.argmax(mean))], float(np.max(mean))
    return _climb(objective, score, [centre, best_u], lo, hi, with_grad, opts.search_maxiter, best_u, best_val)[0]


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
