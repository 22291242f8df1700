"""Identifiability and intervals of the identified parameters (paper §3.3, the second component).

A component of w_opt is reported as known only when the data pin it down.
Three symptoms flag a component as **not identifiable**, each from the
metamodel J~ fitted on every evaluation:

- *no influence*: its total Sobol index S_T on J~ (over the whole box) is
  below ``min_total_index``;
- *flat direction*: its interval (below) spans more than ``max_width`` of the
  admissible interval;
- *stuck on a bound*: w_opt lies within ``bound_margin`` of a bound and the
  interval reaches that bound, so the optimum may lie beyond it (the paper's
  second component under the overlap objective).

A strong correlation (|r| > ``max_correlation``) between two components over
the near-optimal set is reported beside them: it is how a flat direction
shared by two parameters shows (the paper's first and second components).

Interval. The threshold δ comes from the noise model: J is a Monte Carlo
estimate made with v noise paths b_i, so redrawing the paths moves J(w_opt)
by its standard deviation σ_J (estimated from ``n_redraws`` redraws, at no
extra simulation cost: y_sim(w_opt) is reused). Points whose metamodel J
stays within δ = ``delta_sigmas`` · σ_J of J_max cannot be told apart from
w_opt at this sample size. The interval of component k is the range of that
near-optimal set, found by sampling J~'s mean on a scrambled Sobol' set of the
box plus a Gaussian cloud around w_opt, in normalised coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from suspid.config import Section


class IdentifiabilityOptions(Section):
    """Thresholds of the identifiability verdict (``identifiability:`` in ``ego:``'s sibling section)."""

    min_total_index: float = Field(default=0.005, ge=0, le=1)
    max_width: float = Field(default=0.5, gt=0, le=1)
    bound_margin: float = Field(default=0.02, ge=0, lt=0.5)
    max_correlation: float = Field(default=0.9, gt=0, le=1)
    n_redraws: int = Field(default=16, ge=2)
    delta_sigmas: float = Field(default=2.0, gt=0)
    n_samples: int = Field(default=8192, ge=256)


@dataclass
class Verdict:
    """Per-component verdicts; arrays are ``(q,)``, intervals ``(q, 2)`` normalised."""

    identifiable: np.ndarray
    reasons: list[list[str]]
    interval_unit: np.ndarray
    total_index: np.ndarray
    first_index: np.ndarray
    lengthscales: np.ndarray | None
    correlated_with: list[list[str]]
    delta: float
    sigma_J: float


def near_optimal_set(mean_fn, u_opt: np.ndarray, j_max: float, delta: float, n: int,
                     rng: np.random.Generator) -> np.ndarray:
    """Points of [0, 1]^q where the metamodel mean is at least J_max - δ, ``(m, q)``; w_opt included."""
    from scipy.stats import qmc

    q = u_opt.size
    m = 1 << int(np.ceil(np.log2(max(n // 2, 2))))
    sobol = qmc.Sobol(q, scramble=True, seed=rng).random(m)
    local = np.concatenate([u_opt + s * rng.standard_normal((n // 6, q)) for s in (0.02, 0.08, 0.25)])
    U = np.clip(np.vstack([sobol, local]), 0.0, 1.0)
    keep = U[np.asarray(mean_fn(U)) >= j_max - delta]
    return np.vstack([u_opt[None, :], keep])


def assess(names: list[str], u_opt: np.ndarray, j_max: float, sigma_J: float, surrogate,
           options: IdentifiabilityOptions, rng: np.random.Generator) -> Verdict:
    """The identifiability verdict of every component (see the module docstring).

    :param u_opt: ``(q,)`` w_opt in [0, 1]^q.
    :param surrogate: a fitted surrogate whose inputs are normalised points.
    """
    from suspid.sensitivity import sobol_indices

    q = len(names)
    mean_fn = lambda U: surrogate.predict(np.atleast_2d(U))[0]  # noqa: E731
    first, total = sobol_indices(mean_fn, q, seed=int(rng.integers(2**31)))
    first, total = np.clip(np.asarray(first), 0, 1), np.clip(np.asarray(total), 0, 1)
    delta = options.delta_sigmas * sigma_J
    S = near_optimal_set(mean_fn, u_opt, j_max, delta, options.n_samples, rng)
    interval = np.stack([S.min(axis=0), S.max(axis=0)], axis=1)
    corr = np.corrcoef(S.T) if S.shape[0] > q + 2 else np.eye(q)
    identifiable = np.ones(q, dtype=bool)
    reasons: list[list[str]] = [[] for _ in range(q)]
    correlated: list[list[str]] = [[] for _ in range(q)]
    for k in range(q):
        width = interval[k, 1] - interval[k, 0]
        if total[k] < options.min_total_index:
            reasons[k].append(f"no influence on J (total Sobol index {total[k]:.3g})")
        if width > options.max_width:
            reasons[k].append(f"flat direction: near-optimal set spans {100 * width:.0f} % of the interval")
        for side, bound in (("lower", 0.0), ("upper", 1.0)):
            if abs(u_opt[k] - bound) <= options.bound_margin and abs(interval[k, int(bound)] - bound) <= 1e-9:
                reasons[k].append(f"stuck on the {side} bound")
        for j in range(q):
            if j != k and np.isfinite(corr[k, j]) and abs(corr[k, j]) > options.max_correlation:
                correlated[k].append(f"{names[j]} (r = {corr[k, j]:+.2f})")
        identifiable[k] = not reasons[k]
    lengthscales = getattr(surrogate, "lengthscales_", None)
    return Verdict(identifiable, reasons, interval, total, first,
                   None if lengthscales is None else np.asarray(lengthscales, float), correlated, float(delta),
                   float(sigma_J))
