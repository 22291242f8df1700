"""The suspension and the named effects' parameters fitted together, under the diagnosis's own criterion D.

Overview: ``docs/diagnose.md``, "How it works", steps 1 and 5.

D = Σ (m / σ)² over every (speed group, channel, frequency bin), m the group mean of y_mes - y_sim - μ_B and σ
its null sd (:class:`.fit.Discrepancy`), is a weighted least-squares criterion on the mean log-spectra: the
Gaussian likelihood of the mean residual that the tests of the map and the naming rule read (bins taken as
independent). The identification's objective (likelihood or overlap, eq. 6-8) compares the *densities* of
Y_mes and Y_mod at each frequency; on data from a vehicle other than the model its maximiser can sit where the
mean spectrum is not matched (on the independent train, k_sec_z 4-23 % of its interval off with both dates at
the reference suspension, where D's minimiser is within 2 %), and every cell the suspension reads is then
flagged as discrepancy. Fitting the suspension, and the effects with it, by D makes the map, the ranking and
the joint fit answer one question under one criterion (Kennedy and O'Hagan 2001: the parameters and the
discrepancy are calibrated under the same likelihood).

The fit is :func:`scipy.optimize.least_squares` (trust-region reflective, bounds) on the whitened residuals
m / σ, in normalised coordinates: the suspension on its admissible box (linear), each effect's fitted
parameters on theirs (log where the effect declares it); the Jacobian by forward differences (the spectra are
common-random-number simulations, smooth in w). Its sampling covariance is the sandwich
(GᵀG)⁻¹ Gᵀ R G (GᵀG)⁻¹, R the correlation of the whitened residuals under the noise model (low rank plus
diagonal: the bins are not independent).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from scipy.optimize import least_squares

from suspid import registry
from suspid.config import Config, validate_options
from suspid.errors import SimulatorError
from suspid.infra.files import canonical
from suspid.workflows.tasks import simulate_spectra

from .fit import Discrepancy, _Transform

FAILED_RESIDUAL = 1.0e3
"""Whitened residual of every bin where the vehicle cannot be simulated (e.g. unstable): far worse than any fit."""


@dataclass
class JointFit:
    """The suspension (and the named effects) fitted by least squares on D.

    :ivar w: SI values of the identified suspension parameters; :ivar effects: ``[(name, parameters)]`` with
        the fitted values; :ivar y_sim: ``(v, K, F)`` dB spectra at the fit.
    :ivar D, D_start: the criterion at the fit and at the start.
    :ivar half_width_percent: two sampling standard errors of each fitted parameter, in % of its (normalised)
        range (``<effect>/<parameter>`` for the effects'); :ivar start: the starting values (same keys).
    """

    w: dict[str, float]
    effects: list[tuple[str, dict[str, Any]]]
    y_sim: np.ndarray
    D: float
    D_start: float
    n_simulations: int
    half_width_percent: dict[str, float]
    start: dict[str, float]
    status: str
    fitted: list[str] = field(default_factory=list)
    jacobian: np.ndarray | None = None                  # (n_bins, n_fitted) of the whitened residuals, unit coords
    model_error: dict[str, Any] | None = None            # the data-group check (:func:`check_groups`)
    simulator: Any = field(default=None, repr=False)     # the model with the effects (reused by the group fits)

    @property
    def identifiable(self) -> dict[str, bool] | None:
        """Per suspension parameter: its bias-aware half-width within ``max_half_width`` (None: not checked)."""
        return None if self.model_error is None else dict(self.model_error["identifiable"])

    def as_dict(self) -> dict[str, Any]:
        return canonical({"method": "least squares on D (whitened mean residuals), trust-region reflective",
                          "fitted": self.fitted, "w": self.w, "start": self.start,
                          "effects": [{"name": n, "parameters": p} for n, p in self.effects],
                          "D": round(self.D, 3), "D_start": round(self.D_start, 3),
                          "n_simulations": self.n_simulations, "half_width_percent": self.half_width_percent,
                          "status": self.status, "model_error": self.model_error,
                          "identifiable": self.identifiable})


def fit_jointly(config: Config, problem, disc: Discrepancy, w_start: dict[str, float],
                effects: list[tuple[str, dict[str, Any]]] = (), fixed: set[str] = frozenset(), *,
                max_evaluations: int = 120, suspension: list[str] | None = None, simulator=None,
                log: Callable[[str], None] = lambda s: None) -> JointFit:
    """Fit the identified suspension parameters and the continuous parameters of ``effects`` (except those
    named in ``fixed``, kept as given) by least squares on D, from ``w_start`` and the effects' values.

    :param config: the diagnosed config (its simulator options without ``effects``' entries).
    :param problem: the run's problem (segments, bounds, noise model).
    :param disc: the criterion D (its target and scales; :class:`.fit.Discrepancy`; a scale of inf leaves a bin
        out).
    :param effects: ``[(name, parameters)]``: the named effects with their structural choices.
    :param max_evaluations: simulator calls at most (the Jacobians' included).
    :param suspension: the suspension parameters fitted (default: all identified ones; the others stay at
        ``w_start``).
    :param simulator: the config's simulator with ``effects`` already built (an earlier fit's ``simulator``).
    """
    effects = [(n, dict(p)) for n, p in effects]
    sim = simulator if simulator is not None else _with_effects(config, problem, effects)
    names = list(problem.names) if suspension is None else [n for n in problem.names if n in suspension]
    index = [list(problem.names).index(n) for n in names]
    free: list[tuple[str, str, _Transform]] = []          # (effect, parameter, transform) of the fitted effects
    for n, p in effects:
        if n in fixed:
            continue
        cls = registry.get("effect", n)
        free += [(n, q, _Transform(cls, q)) for q in cls.fitted]
    q = len(names)
    w_start = {**dict(getattr(problem, "w0", None) or {}), **dict(w_start)}      # nominal where not given
    u_all = problem.to_unit(np.array([w_start[n] for n in problem.names], float))
    u_start = np.concatenate([u_all[index], [t.to_unit(dict(effects)[n][p]) for n, p, t in free]])
    u_start = np.clip(u_start, 0.0, 1.0)
    labels = names + [f"{n}/{p}" for n, p, _ in free]
    count = [0]
    cache: dict[tuple, tuple[np.ndarray, np.ndarray | None]] = {}

    def w_of(u: np.ndarray) -> dict[str, float]:
        u_w = u_all.copy()
        u_w[index] = u[:q]
        w = problem.w_of(problem.from_unit(u_w))
        w.update({f"{n}/{p}": t.from_unit(ui) for (n, p, t), ui in zip(free, u[q:])})
        return w

    def residual(u: np.ndarray) -> np.ndarray:
        key = tuple(np.round(u, 12))
        if key not in cache:
            count[0] += 1
            try:
                y = simulate_spectra(sim, w_of(u), problem.segments, config.spectra)[0]
                e = ((disc.target - disc.grid.group_means(disc.effective(y))) / disc.scale).ravel()
            except SimulatorError:
                y, e = None, np.full(disc.n_terms, FAILED_RESIDUAL)
            cache[key] = (e, y)
        return cache[key][0]

    e0 = residual(u_start)
    D_start = float(e0 @ e0)
    n_par = u_start.size
    budget = max(1, max_evaluations // (n_par + 1))      # each iteration: a Jacobian (n_par calls) and a step
    status = "fitted"
    try:
        sol = least_squares(residual, u_start, bounds=(0.0, 1.0), method="trf", diff_step=1e-3, x_scale=0.1,
                            xtol=1e-4, ftol=1e-4, max_nfev=budget)
        u = np.clip(sol.x, 0.0, 1.0)
        G = sol.jac
        if not sol.success:
            status = f"stopped: {sol.message}"
    except (ValueError, np.linalg.LinAlgError) as exc:    # a residual that is not finite, a singular step
        u, G, status = u_start, None, f"failed: {exc}"
    e = residual(u)
    if float(e @ e) > D_start:                               # never worse than where it started
        u, e, G, status = u_start, e0, None, "reverted to the start: the fit did not lower D"
    y = cache[tuple(np.round(u, 12))][1]
    half = _half_widths(G, disc, problem.noise_model, labels) if G is not None else {}
    w = w_of(u)
    fitted_effects = [(n, {**p, **{q_: w[f"{n}/{q_}"] for nn, q_, _ in free if nn == n}}) for n, p in effects]
    log(f"joint fit of {', '.join(labels)}: D {D_start:.1f} → {float(e @ e):.1f} ({count[0]} simulations)")
    w_first = w_of(u_start)
    return JointFit({k: w[k] for k in problem.names}, fitted_effects, y, float(e @ e), D_start, count[0], half,
                    {lab: float(w_first[lab]) for lab in labels}, status, labels, G, simulator=sim)


def _with_effects(config: Config, problem, effects: list[tuple[str, dict[str, Any]]]):
    """The config's simulator (the problem's class) with ``effects`` ``[(name, parameters)]`` added."""
    options = dict(config.simulator.options)
    options["effects"] = list(options.get("effects") or []) + [{"name": n, **p} for n, p in effects]
    sim_cls = type(problem.simulator)
    return sim_cls(**validate_options(sim_cls, options, file=str(config.source_file), key="simulator.options"))


def _half_widths(G: np.ndarray, disc: Discrepancy, noise_model, labels: list[str]) -> dict[str, float]:
    """Two sandwich standard errors of each normalised parameter, in % of its range.

    The whitened residual of a speed group, e = m / σ, has under the noise model the correlation
    R = Φ̃ᵀ Λ Φ̃ + diag(d / s²), Φ̃ the Karhunen-Loève modes over the bins' sd s (the group's factor
    1/v_g + 1/v0_g cancels); groups are independent. Cov(δ) = (GᵀG)⁻¹ (Σ_g G_gᵀ R G_g) (GᵀG)⁻¹.
    """
    n_groups = disc.target.shape[0]
    n_bins = disc.target[0].size
    sd = np.sqrt(np.maximum(noise_model.variance_.ravel(), 1e-30))
    phi = noise_model.components_ / sd[None, :]                      # (r, K·F)
    lam = (1.0 - noise_model.shrinkage_) * noise_model.eigenvalues_
    dd = noise_model.residual_variance_.ravel() / sd ** 2
    meat = np.zeros((G.shape[1], G.shape[1]))
    for g in range(n_groups):
        Gg = G[g * n_bins:(g + 1) * n_bins]
        P = phi @ Gg                                                  # (r, p)
        meat += P.T @ (lam[:, None] * P) + Gg.T @ (dd[:, None] * Gg)
    bread = np.linalg.pinv(G.T @ G)
    cov = bread @ meat @ bread
    se = np.sqrt(np.maximum(np.diag(cov), 0.0))
    dead = ~np.any(G != 0.0, axis=0)            # a parameter that acts on nothing here (a one-wheelset phase step)
    return {lab: round(float(200.0 * s), 4) if math.isfinite(s) and not d else None
            for lab, s, d in zip(labels, se, dead)}


def check_groups(config: Config, problem, disc: Discrepancy, fit: JointFit, *, max_evaluations: int = 60,
                 log: Callable[[str], None] = lambda s: None) -> dict[str, Any]:
    """Does each part of the data give the same suspension? The model-form check of a fit (sets
    ``fit.model_error`` and returns it).

    The sampling half-widths of the fit assume the model right; a model whose sensitivity to a parameter
    differs from the vehicle's (or an effect implemented otherwise than the vehicle has it) makes the parts of
    the data disagree, and the fit is a compromise set by where the model is wrong. As the identification's own
    check (:mod:`suspid.workflows.adequacy`, ``identifiability.model_error.adequacy``): the data groups of
    :func:`~suspid.workflows.adequacy.data_groups` (channel directions, the two frequency halves); in each, the
    suspension parameters holding at least ``min_group_share`` of their information there (Σ G² over the
    group's bins, G the fit's Jacobian) are fitted again by least squares on D restricted to the group, the
    effects and the other parameters fixed. The bias bound B of a parameter is half the spread of its group
    estimates; its bias-aware half-width (:func:`~suspid.method.identifiability.bias_aware_half_width`, at
    ``n_sigmas``) with the sampling sd; it is *identifiable* when that half-width is within ``max_half_width``
    and, as in the identification's check, its group estimates are not further apart than ``max_spread`` and
    2√2 sampling sd at once (the parts of the data disagree: the model's sensitivity to it differs from the
    vehicle's).
    """
    from suspid.method.identifiability import bias_aware_half_width
    from suspid.workflows.adequacy import data_groups

    ident = config.identifiability
    adequacy = ident.model_error.adequacy
    names = [n for n in problem.names if n in fit.fitted]
    w_fit = fit.w
    G = fit.jacobian[:, [fit.fitted.index(n) for n in names]] if fit.jacobian is not None else None
    shape = disc.target.shape                                        # (G, K, F)
    estimates: dict[str, dict[str, float]] = {}
    shares: dict[str, dict[str, float]] = {}
    if G is not None:
        info = G ** 2
        total = info.sum(axis=0)
        for group in data_groups(problem.channels, problem.freqs):
            mask = np.broadcast_to(group.channels[None, :, None] & group.freqs[None, None, :], shape).ravel()
            share = np.where(total > 0, info[mask].sum(axis=0) / np.where(total > 0, total, 1.0), 0.0)
            shares[group.name] = {n: round(float(v), 4) for n, v in zip(names, share)}
            free = [n for n, v in zip(names, share) if v >= adequacy.min_group_share]
            if not free:
                continue
            sub = copy.copy(disc)
            sub.scale = np.where(mask.reshape(shape), disc.scale, np.inf)
            g_fit = fit_jointly(config, problem, sub, w_fit, fit.effects, {n for n, _ in fit.effects},
                                max_evaluations=max_evaluations, suspension=free, simulator=fit.simulator)
            estimates[group.name] = {n: _percent(problem, n, g_fit.w[n] - w_fit[n]) for n in free}
    spread = {n: (max(v) - min(v)) if len(v) > 1 else 0.0
              for n in names for v in [[e[n] for e in estimates.values() if n in e]]}
    known = {n: fit.half_width_percent.get(n) is not None and G is not None for n in names}
    sd = np.array([(fit.half_width_percent.get(n) or 0.0) / 200.0 for n in names])
    bound = np.array([spread[n] / 200.0 for n in names])
    half = bias_aware_half_width(sd, bound, ident.n_sigmas)
    disagree = {n: spread[n] / 100.0 > adequacy.max_spread and spread[n] / 100.0 > 2 * np.sqrt(2) * s
                for n, s in zip(names, sd)}
    # without a sampling sd (a failed fit, a parameter the data do not move) nothing is measured: not identifiable
    out = {"groups": estimates, "information_share": shares,
           "spread_percent": {n: round(spread[n], 3) for n in names},
           "max_spread_percent": 100 * adequacy.max_spread,
           "groups_disagree": disagree,
           "bias_bound_percent": {n: round(100 * b, 3) for n, b in zip(names, bound)},
           "half_width_percent": {n: round(100 * h, 3) if known[n] else None for n, h in zip(names, half)},
           "max_half_width_percent": 100 * ident.model_error.max_half_width,
           "identifiable": {n: bool(known[n] and h <= ident.model_error.max_half_width and not disagree[n])
                            for n, h in zip(names, half)}}
    log("data groups: " + ", ".join(f"{n} spread {spread[n]:.1f} %, half-width {100 * h:.1f} %"
                                    for n, h in zip(names, half) if known[n]))
    fit.model_error = out
    return out


def _percent(problem, name: str, delta: float) -> float:
    """``delta`` (SI) in % of the admissible interval of ``name``."""
    lo, hi = problem.bounds[list(problem.names).index(name)]
    return round(100.0 * float(delta) / (float(hi) - float(lo)), 3)
