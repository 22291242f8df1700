"""Identifiability and intervals of the identified parameters (paper §3.3, the second component).

A component of w_opt is reported as known only when the data pin it down.
Three symptoms flag a component as **not identifiable**:

- *no influence*: its total Sobol index S_T on the metamodel J~ (over the
  whole box) is below ``min_total_index``;
- *flat direction*: its interval (below) spans more than ``max_width`` of the
  admissible interval (J~ is flat along it, or a combination of it and
  another component, at the scale of the data's noise);
- *stuck on a bound*: w_opt lies within ``bound_margin`` of a bound and J~
  still rises towards it, so the optimum may lie beyond the admissible
  interval (the paper's second component under the overlap objective).

A strong correlation (|r| > ``max_correlation``) between two components is
reported beside them: it is how a flat direction shared by two parameters
shows (the paper's first and second components).

Interval (a sandwich estimate, as for M-estimators). Near its maximum,
J(w) ≈ J_max + g·Δ + ½ Δᵀ H Δ, with Δ = w - w_opt in [0, 1]^q
coordinates, H the Hessian of the metamodel's mean at w_opt, and g the
random tilt that other data of the same kind would give (zero on average).
The maximum then moves by Δ = -H⁻¹ g, so Cov(w_opt) ≈ H⁻¹ Σ_g H⁻¹, where
The diagonal of H comes from simulations at w_opt ± h e_k, its correlation
structure from the metamodel. Σ_g, the covariance of the gradient of J at w_opt, comes from a bootstrap
over segments with redrawn noise paths, and over the reference date's
segments with B fitted again on each resample (``bootstrap_reference``: the
finite reference date moves w_opt too)
(:func:`suspid.workflows.analysis.gradient_noise`). Segments are resampled as pairs:
segment i's measured spectra and its simulated spectra come from the same
track, so they vary together. Resampling the two sets independently
(``bootstrap: independent``) miscalibrates the intervals (coverage over seeds of
the quickstart experiment: ``benchmarks/RESULTS.md``, "Interval coverage over seeds"). The interval of component k is
w_opt,k ± ``n_sigmas`` σ_k, clipped to the box. Directions where H is not
negative definite (flat or rising) get an unbounded spread, hence the whole
interval.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field
from scipy.optimize import brentq
from scipy.stats import norm

from suspid.method.calibration import CalibrationOptions
from suspid.method.sensitivity import surrogate_sensitivity
from suspid.options import Section


class SelfCheckOptions(Section):
    """``identifiability.model_error.self_check``: the reference-date self-check (:mod:`suspid.workflows.reference`)."""

    enabled: bool = Field(default=True, description="run it when the reference date's data are part of the run")
    n_splits: int = Field(default=8, ge=1, le=64, description="random halves: B fitted on one, w identified on the other")
    max_evaluations: int = Field(default=0, ge=0, description="simulations per split (Nelder-Mead); 0: 30 q")
    initial_step: float = Field(default=0.1, gt=0, le=0.5, description="initial simplex size in [0, 1]^q")
    correct: bool = Field(
        default=True, description="linearised method with model_error.correct: a mean shift beyond 2 standard errors "
        "is a bias of known sign, measured on the calibrated model where the truth is w0: w_opt is corrected by it "
        "and its standard error widens the interval; false: its size bounds the bias (sign unknown)")


class AdequacyOptions(Section):
    """``identifiability.model_error.adequacy``: residuals at w_opt against B (:mod:`suspid.method.adequacy`)."""

    enabled: bool = True
    bands_per_octave: float = Field(default=1.0, gt=0, le=12, description="band width: 1/bands_per_octave octave")
    z_threshold: float = Field(default=3.0, gt=0, description="|mean residual| / its standard error above which "
                               "a band is inadequate")
    min_db: float = Field(default=0.5, ge=0, description="... and |mean residual| above this many dB")
    max_share: float = Field(default=0.5, gt=0, le=1, description="a parameter with more of its information in "
                             "inadequate bands is not trustworthy")
    groups: bool = Field(default=True, description="re-identify on data groups (directions, frequency halves)")
    min_group_share: float = Field(default=0.2, gt=0, le=1, description="a parameter is free in a group holding "
                                   "at least this share of its information")
    max_spread: float = Field(default=0.06, ge=0, le=1, description="largest spread of a parameter's group "
                              "estimates, fraction of the admissible interval, of a trustworthy component")
    group_evaluations: int = Field(default=20, ge=2, description="simulations per free parameter and group")


class NuisanceOptions(Section):
    """``identifiability.model_error.nuisance``: w_opt's dependence on assumed model parameters
    (:mod:`suspid.workflows.nuisance`)."""

    parameters: dict[str, tuple[float, float]] = Field(
        default_factory=dict, description="not-identified model parameters whose value is uncertain, each with "
        "its plausible range [low, high] in SI units; empty: the check is not run")
    max_shift: float = Field(default=0.05, gt=0, le=1, description="largest move of w_opt, fraction of the "
                             "admissible interval, when one of them takes an end of its range, of a trustworthy "
                             "component")
    max_evaluations: int = Field(default=0, ge=0, description="simulations per re-identification; 0: 20 q")


class ModelErrorOptions(Section):
    """``identifiability.model_error``: when a component is *not trustworthy under model error*."""

    run: Literal["measured", "always", "never"] = Field(
        default="measured", description="when to run the checks: on measured data only (the numerical "
        "experiment's model is the truth's, so it has no model-form error to find), always, or never")
    max_bias: float = Field(default=0.03, ge=0, le=1, description="largest self-check bias of a trustworthy "
                            "component, fraction of the admissible interval (a shift counts as a bias when it lies "
                            "beyond 2 standard errors of the splits' mean)")
    max_half_width: float = Field(
        default=0.08, gt=0, le=1, description="largest half-width of a trustworthy component's bias-aware "
        "interval, fraction of the admissible interval: a component that the sampling spread and the bound on the "
        "model-error bias together leave less precise is not reported as a finding")
    widen: bool = Field(default=True, description="make the intervals bias-aware: widen them by the model-error "
                        "checks' bound on the bias (self-check bias, half the groups' spread, nuisance shifts)")
    method: Literal["full", "linearised"] = Field(
        default="linearised", description="linearised: the model parameters calibrated at the reference date and "
        "every check on the spectra linearised at w0 and w_opt (one Jacobian per date, suspid.workflows.linearised; "
        "a few simulator calls, fewer than the identification's); full: the same calibration, and every shift "
        "re-identified by simulation (self-check splits, data groups, the model parameters' ends and calibrated "
        "values: about 40 times the identification's simulations), combined on the same rule")
    correct: bool = Field(
        default=True, description="both methods: correct w_opt by the shift the model parameters calibrated "
        "at the reference date give, centre the interval there with their posterior spread, and bound the rest "
        "(the self-check's bias, half the groups' spread) in quadrature; false: keep w_opt and add every source as "
        "a worst case (the self-check and the ends of each model parameter's range then flag on their own)")
    transfer_error: float = Field(
        default=0.25, ge=0, le=2, description="with correct: the relative error of the calibrated model's shift "
        "away from the reference date. The noise model absorbs the model's discrepancy at w0, so where nothing "
        "changed the shift vanishes up to sampling; at w_opt it is an extrapolation of how the discrepancy changes "
        "with w by model parameters that may only stand in for what the model lacks (a reservoir, a blow-off): "
        "transfer_error x |shift| is a bias of unknown sign in quadrature with the self-check's and the groups' "
        "(0: the shift is taken as exact)")
    correction_draws: int = Field(
        default=8, ge=1, le=64, description="linearised method: draws of the noise paths the calibrated shift is "
        "averaged over (each draw's calibrated and nominal searches share its paths); one draw moves J's maximiser "
        "by about 1 % of the interval on the likelihood, and their Monte Carlo standard error widens the interval. "
        "No simulation")
    no_change: bool = Field(
        default=True, description="test w = w0 on the measurement date (J(w_opt) - J(w0) against its bootstrap "
        "spread, one simulation at w0); where the data do not reject w0, every interval is widened to hold it "
        "(suspid.workflows.no_change)")
    no_change_report: Literal["reference", "estimate"] = Field(
        default="reference", description="where the no-change test does not reject w0: 'reference' reports the "
        "reference date's values (no change the data show; each interval holds the estimate too, which stays in "
        "w_opt and the correction's report), 'estimate' reports the (bias-corrected) estimate")
    calibration: CalibrationOptions = Field(default_factory=CalibrationOptions)
    self_check: SelfCheckOptions = Field(default_factory=SelfCheckOptions)
    adequacy: AdequacyOptions = Field(default_factory=AdequacyOptions)
    nuisance: NuisanceOptions = Field(default_factory=NuisanceOptions)


class IdentifiabilityOptions(Section):
    """Thresholds of the identifiability verdict (config section ``identifiability:``)."""

    min_total_index: float = Field(default=0.005, ge=0, le=1)
    max_width: float = Field(default=0.5, gt=0, le=1)
    bound_margin: float = Field(default=0.02, ge=0, lt=0.5)
    max_correlation: float = Field(default=0.9, gt=0, le=1)
    n_redraws: int = Field(default=32, ge=4, description="bootstrap replicates of the gradient noise")
    step: float = Field(default=0.05, gt=0, le=0.25, description="finite-difference step in [0, 1]^q")
    n_sigmas: float = Field(default=2.0, gt=0, description="half-width of the intervals, in standard deviations")
    bootstrap: Literal["paired", "independent"] = Field(
        default="paired", description="resample the segments as (measured, simulated) pairs, which share the "
        "segment's track, or the two sets independently")
    bootstrap_reference: bool = Field(
        default=True, description="each bootstrap replicate also resamples the reference date's segments and fits "
        "the noise model again on them (its finite sample is data too); needs the reference date's data in the run")
    model_error: ModelErrorOptions = Field(default_factory=ModelErrorOptions)


@dataclass
class Verdict:
    """Per-component verdicts; arrays are ``(q,)``, intervals ``(q, 2)`` and covariance ``(q, q)`` normalised."""

    identifiable: np.ndarray
    reasons: list[list[str]]
    interval_unit: np.ndarray
    covariance: np.ndarray
    total_index: np.ndarray
    first_index: np.ndarray
    lengthscales: np.ndarray | None
    correlated_with: list[list[str]]


def bias_aware_half_width(sd: np.ndarray, bias_bound: np.ndarray, n_sigmas: float) -> np.ndarray:
    """Half-widths ``(q,)`` of intervals that keep their level when w_opt may be biased by up to ``bias_bound``.

    The sandwich interval w_opt ± n σ assumes an unbiased estimate. Under
    model-form error the estimate is w + b + σ Z with a bias |b| ≤ B that the
    model-error checks bound but whose sign they do not know. The shortest
    interval w_opt ± χ that holds w with the same probability as the unbiased
    one, 1 - α = P(|Z| ≤ n), for every such b is the fixed-length bias-aware
    interval of Armstrong and Kolesár ("Simple and honest confidence intervals
    in nonparametric regression", Quantitative Economics, 2020): χ = c σ with
    c the 1 - α quantile of |N(B/σ, 1)|, i.e. P(|Z + B/σ| ≤ c) = 1 - α. It is n σ
    without bias and tends to B + z_{1-α} σ (z the one-sided quantile) when the
    bias dominates: adding B to n σ would be longer, adding them in quadrature
    would not hold the level.

    :param sd: ``(q,)`` sampling standard deviations σ (fractions of the admissible interval).
    :param bias_bound: ``(q,)`` bounds B ≥ 0 on the bias, same units.
    :param n_sigmas: n, the unbiased interval's half-width in σ.
    :returns: ``(q,)`` χ, same units (B where σ = 0).
    """
    sd, bound = np.asarray(sd, dtype=float), np.abs(np.asarray(bias_bound, dtype=float))
    level = 2 * norm.cdf(n_sigmas) - 1
    chi = np.empty_like(sd)
    for k, (s, b) in enumerate(zip(sd, bound)):
        if s <= 0:
            chi[k] = b
            continue
        t = b / s
        chi[k] = s * brentq(lambda c: norm.cdf(c - t) - norm.cdf(-c - t) - level, 0.0, t + n_sigmas + 1.0)
    return chi


def bias_bound_for_half_width(sd: float, half_width: float, n_sigmas: float, lower: float = 0.0,
                              upper: float | None = None) -> float:
    """The inverse of :func:`bias_aware_half_width` in the bias bound: the B ≥ ``lower`` whose half-width χ(σ, B)
    is ``half_width`` (χ increases with B), for one component (fractions of the admissible interval).

    ``lower`` where χ(σ, ``lower``) reaches ``half_width`` already; ``half_width`` itself where σ = 0 (χ = B). The
    root is bracketed in [``lower``, ``upper``], by default up to ``half_width`` + n σ + 1 (χ ≥ B exceeds it there).
    """
    if sd <= 0:
        return float(half_width)
    f = lambda b: bias_aware_half_width(np.array([sd]), np.array([b]), n_sigmas)[0] - half_width  # noqa: E731
    if f(lower) >= 0:
        return float(lower)
    return float(brentq(f, lower, half_width + n_sigmas * sd + 1.0 if upper is None else upper))


def mean_hessian(mean_fn, u: np.ndarray, h: float = 0.02) -> np.ndarray:
    """Hessian ``(q, q)`` of a scalar function at ``u`` by central differences (one batched call)."""
    q = u.size
    E = h * np.eye(q)
    pts = [u]
    for i in range(q):
        for j in range(q):
            pts += [u + E[i] + E[j], u + E[i] - E[j], u - E[i] + E[j], u - E[i] - E[j]]
    f = np.asarray(mean_fn(np.array(pts)))
    H = np.empty((q, q))
    for i in range(q):
        for j in range(q):
            a = 1 + 4 * (i * q + j)
            H[i, j] = (f[a] - f[a + 1] - f[a + 2] + f[a + 3]) / (4 * h * h)
    return 0.5 * (H + H.T)


def sandwich_covariance(H: np.ndarray, sigma_g: np.ndarray, big: float = 1e6) -> np.ndarray:
    """H⁻¹ Σ_g H⁻¹ on the negative-definite part of H; other directions get variance ``big``."""
    lam, V = np.linalg.eigh(H)
    scale = np.abs(lam).max() if lam.size else 1.0
    inv = np.where(lam < -1e-9 * scale, 1.0 / np.minimum(lam, -1e-300), 0.0)
    Hinv = (V * inv) @ V.T
    cov = Hinv @ sigma_g @ Hinv
    flat = V[:, lam >= -1e-9 * scale]
    return cov + big * flat @ flat.T


def combine_hessian(H_model: np.ndarray, curvature: np.ndarray | None) -> np.ndarray:
    """The Hessian with the simulated curvatures on its diagonal and the metamodel's correlations.

    ``H_ij = r_ij sqrt(c_i c_j)`` with c the simulated curvatures (where
    finite) and r the metamodel Hessian's correlation structure; a component
    whose curvature is not negative keeps no coupling (flat).
    """
    if curvature is None:
        return H_model
    c = np.where(np.isfinite(curvature), curvature, np.diag(H_model))
    d = np.diag(H_model)
    H = np.diag(c).astype(float)
    q = c.size
    for i in range(q):
        for j in range(q):
            if i != j and c[i] < 0 and c[j] < 0 and d[i] < 0 and d[j] < 0:
                r = np.clip(H_model[i, j] / np.sqrt(d[i] * d[j]), -0.999, 0.999)  # H = -D R D, R_ij = -r
                H[i, j] = r * np.sqrt(c[i] * c[j])
    return H


def assess(names: list[str], u_opt: np.ndarray, sigma_g: np.ndarray, surrogate,
           options: IdentifiabilityOptions, rng: np.random.Generator,
           curvature: np.ndarray | None = None) -> Verdict:
    """The identifiability verdict of every component (see the module docstring).

    :param u_opt: ``(q,)`` w_opt in [0, 1]^q.
    :param sigma_g: ``(q, q)`` covariance of the gradient of J at w_opt, [0, 1]^q coordinates.
    :param surrogate: a fitted surrogate whose inputs are normalised points.
    :param curvature: ``(q,)`` d²J/du_k² at w_opt from simulations (NaN where unknown);
        without it the metamodel's Hessian is used alone.
    """
    q = len(names)
    mean_fn = lambda U: surrogate.predict(np.atleast_2d(U))[0]  # noqa: E731
    sens = surrogate_sensitivity(surrogate, q, seed=int(rng.integers(2**31)), names=names)
    first, total = np.clip(sens.first_order, 0, 1), np.clip(sens.total, 0, 1)
    H = combine_hessian(mean_hessian(mean_fn, u_opt), curvature)
    cov = sandwich_covariance(H, sigma_g)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    interval = np.stack([np.clip(u_opt - options.n_sigmas * sd, 0, 1),
                         np.clip(u_opt + options.n_sigmas * sd, 0, 1)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(sd, sd)
    grad = np.array([(mean_fn(np.clip(u_opt + 0.01 * e, 0, 1)[None])[0]
                      - mean_fn(np.clip(u_opt - 0.01 * e, 0, 1)[None])[0]) for e in np.eye(q)])
    identifiable = np.ones(q, dtype=bool)
    reasons: list[list[str]] = [[] for _ in range(q)]
    correlated: list[list[str]] = [[] for _ in range(q)]
    for k in range(q):
        width = interval[k, 1] - interval[k, 0]
        if total[k] < options.min_total_index:
            reasons[k].append(f"no influence on J (total Sobol index {total[k]:.3g})")
        if width > options.max_width:
            reasons[k].append(f"flat direction: the interval spans {100 * width:.0f} % of the admissible one")
        if u_opt[k] <= options.bound_margin and grad[k] < 0:
            reasons[k].append("stuck on the lower bound (J still rises beyond it)")
        if u_opt[k] >= 1 - options.bound_margin and grad[k] > 0:
            reasons[k].append("stuck on the upper bound (J still rises beyond it)")
        for j in range(q):
            if j != k and np.isfinite(corr[k, j]) and abs(corr[k, j]) > options.max_correlation:
                correlated[k].append(f"{names[j]} (r = {corr[k, j]:+.2f})")
        identifiable[k] = not reasons[k]
    return Verdict(identifiable, reasons, interval, cov, total, first, sens.lengthscales, correlated)
