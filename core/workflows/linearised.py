"""The model-error checks by linearisation, with the model parameters calibrated at the reference date (beyond the paper).

``identifiability.model_error.method: linearised``. The full checks
(:func:`suspid.workflows.analysis.model_error`) re-identify w by simulation:
the self-check once per split of the reference date, the data groups once per
group, the nuisance check once per end of each assumed model parameter's range,
about 35 times the identification's simulations on the built-in model. Here
the spectra are linearised instead, once per date, and every check reads them:

- **two Jacobians**: the reference date's spectra at w0 and the measurement
  date's at w_opt, each with respect to the identified parameters w and the
  model parameters θ (:func:`suspid.workflows.jacobian.spectra_jacobian`:
  analytic where the simulator differentiates, forward differences through the
  run's executor otherwise, q + p + 1 simulations), kept in the run ledger;
- **calibration** of θ at the reference date, where w = w0 is known
  (:mod:`suspid.method.calibration`: Gauss-Newton on the mean spectra, a
  cluster-robust covariance; each further step one Jacobian in θ);
- **self-check**: the splits of :mod:`suspid.workflows.reference` (the same
  random halves, noise fits and noise paths), w identified on each by the same
  local search, on y_sim0 + ∂y_sim0/∂u Δu instead of simulations, y_sim0 and its
  Jacobian those of the calibrated model, simulated at w0 (one Jacobian more);
- **data groups**: :func:`suspid.workflows.adequacy.group_estimates` on the
  spectra linearised at w_opt;
- **model parameters**: the implicit-function theorem, du_opt/dt = −H_uu⁻¹ H_ut,
  H the Hessian of J(u, t) evaluated exactly on the linearised spectra, the
  noise model B fitted again at the reference date for every t (as the full
  nuisance check does); its shift at the ends of each parameter's range
  (the calibrated interval where the reference date pins it down, the assumed
  range otherwise) flags a component as the full check does; the spread
  G Σ_t Gᵀ of what remains uncertain, with the correlations of Σ_t, widens the
  intervals with the sampling spread in quadrature (a random bias, not a worst
  case); the calibrated model's shift is a known bias, found by the local search
  on the spectra of the calibrated model itself (one Jacobian per date at θ̂: a
  mount's stiffness changes the spectra far from linearly over a factor 2).

The no-change test (:mod:`suspid.workflows.no_change`, one simulation on the measurement date at w0 less the
correction: where w_opt lies when nothing changed) runs
with the adequacy bands; where the data do not reject w0, the bound grows until every interval around the
(corrected) estimate holds w0.

The adequacy bands at w_opt read the 2q + 1 simulations of the intervals
(:func:`suspid.workflows.analysis.gradient_noise`): no new simulation. A
linearisation is valid where the spectra are nearly linear in w and θ over
the shifts it predicts (a few % of the interval); ``benchmarks/bench_trust_budget.py``
compares its flags with the full checks'.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from suspid.errors import ClusterError, SuspidError
from suspid.infra.ledger import Ledger, stable_hash
from suspid.infra.seeds import rng as named_rng
from suspid.interfaces import Executor, TrackSegment
from suspid.method.calibration import UNIFORM_SD, calibrate_step, implicit_shifts, octave_clusters
from suspid.method.identifiability import ModelErrorOptions
from suspid.workflows.jacobian import spectra_jacobian
from suspid.workflows.no_change import apply_no_change
from suspid.method.noise import fit_noise_model
from suspid.method.objective import ObjectiveFunction
from suspid.workflows.adequacy import group_estimates
from suspid.workflows.problem import Problem, segment_speeds, segments_digest
from suspid.workflows.reference import SELF_CHECK_MIN_SEGMENTS, local_search, self_check_missing
from suspid.workflows.trust import (BiasSources, checks_report, combine_sources, correction_report,  # noqa: F401
                                    equivalent_bias_bound, model_spread, transfer_term, trust_states)
from suspid.elements import declared_parameters

__all__ = ["linearised_model_error", "model_parameters", "calibrate_at_reference", "Calibration", "calibration_result",
           "calibration_of", "calibration_markdown", "equivalent_bias_bound", "DateJacobian"]

ModelErrorFn = Callable[..., dict[str, Any]]

REFINE_SHIFT = 0.03
"""A calibrated model's shift of w_opt beyond this (fraction of an interval, any component) is searched again on
the spectra linearised where it lands: on test_nuisance's car a factor-2 mount stiffness moved c_yaw by 15 % and
the one-step linearised shift missed the truth by 1 % of its interval."""


@dataclass
class DateJacobian:
    """The spectra of one date and their Jacobian, per unit of the normalised parameters.

    :ivar y: ``(v, n_channels, n_freqs)`` dB.
    :ivar du: ``(v, n_channels, n_freqs, q)`` dB per unit of u ∈ [0, 1]^q (the identified parameters).
    :ivar dt: ``(v, n_channels, n_freqs, p)`` dB per unit of t (each model parameter per width of its range).
    :ivar n_simulations: plain simulations its finite differences took, plus its analytic calls.
    :ivar methods: parameter -> analytic / forward / central.
    """

    y: np.ndarray
    du: np.ndarray
    dt: np.ndarray
    n_simulations: int
    methods: dict[str, str]
    cached: bool


@dataclass
class ModelParameters:
    """The model parameters θ the checks calibrate and propagate: names, nominal values, assumed ranges (SI)."""

    names: list[str]
    nominal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    source: str

    @property
    def width(self) -> np.ndarray:
        return self.upper - self.lower

    def t_of(self, theta: np.ndarray) -> np.ndarray:
        """θ ``(..., p)`` SI to t = (θ − θ_nominal) / width."""
        return (np.asarray(theta, float) - self.nominal) / self.width

    def theta_of(self, t: np.ndarray) -> np.ndarray:
        return self.nominal + np.asarray(t, float) * self.width

    def w(self, t: np.ndarray) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, self.theta_of(t))}


def model_parameters(problem: Problem, options: ModelErrorOptions) -> ModelParameters:
    """θ: ``calibration.parameters`` if given, else ``nuisance.parameters``, else the simulator's
    :meth:`~suspid.interfaces.Simulator.calibratable` ones over their declared bounds; identified names left out.

    :raises ConfigError: a name the simulator does not declare.
    """
    declared = {p.name: p for p in declared_parameters(problem.simulator)}
    if options.calibration.parameters:
        given, source, key = dict(options.calibration.parameters), "calibration.parameters", "calibration.parameters"
    elif options.nuisance.parameters:
        given, source, key = dict(options.nuisance.parameters), "nuisance.parameters", "nuisance.parameters"
    else:
        given = {n: None for n in problem.simulator.calibratable()}
        source, key = f"declared calibratable by simulator '{problem.simulator.name}'", ""
    names, nominal, lower, upper = [], [], [], []
    for n, rng in given.items():
        if n in problem.names:
            continue
        if n not in declared:
            raise problem.config.error(f"model parameter '{n}' is not declared by simulator "
                                       f"'{problem.simulator.name}'",
                                       f"identifiability.model_error.{key or 'calibration.parameters'}")
        p = declared[n]
        lo, hi = (p.lower, p.upper) if rng is None else (float(min(rng)), float(max(rng)))
        lo, hi = min(lo, p.nominal), max(hi, p.nominal)
        if not hi > lo:
            raise problem.config.error(f"the range of model parameter '{n}' is empty ([{lo:g}, {hi:g}])",
                                       f"identifiability.model_error.{key}")
        names.append(n)
        nominal.append(float(p.nominal))
        lower.append(lo)
        upper.append(hi)
    return ModelParameters(names, np.array(nominal), np.array(lower), np.array(upper), source)


def date_jacobian(problem: Problem, ledger: Ledger, segments: list[TrackSegment], w: dict[str, float],
                  u_names: list[str], theta: ModelParameters, executor: Executor | None) -> DateJacobian:
    """Spectra on ``segments`` at ``w`` (SI, identified and model parameters) and their Jacobian with respect to
    ``u_names`` (identified) and θ, in normalised units; cached in the ledger."""
    names = list(u_names) + list(theta.names)
    key = stable_hash("linearised-jacobian", problem.simulator_identity, w, segments_digest(segments), names,
                      problem.config.spectra.model_dump())
    y, jac, meta = (ledger.get_array(key + s) for s in (":y", ":jacobian", ":meta"))
    cached = y is not None and jac is not None and meta is not None
    if not cached:
        res = spectra_jacobian(problem.simulator, w, names, segments, problem.config.spectra, executor=executor,
                               fallback="forward")
        y, jac = res.y, res.jacobian
        meta = np.array([res.n_simulations + res.n_analytic_calls]
                        + [{"analytic": 0, "forward": 1, "central": 2}[res.methods[n]] for n in names], float)
        ledger.put_array(key + ":y", y)
        ledger.put_array(key + ":jacobian", jac)
        ledger.put_array(key + ":meta", meta)
    q = len(u_names)
    scale_u = np.array([hi - lo for lo, hi in problem.bounds[[problem.names.index(n) for n in u_names]]]) \
        if q else np.zeros(0)
    methods = {n: ("analytic", "forward", "central")[int(m)] for n, m in zip(names, meta[1:])}
    return DateJacobian(np.asarray(y), jac[..., :q] * scale_u, jac[..., q:] * theta.width, int(meta[0]), methods,
                        cached)


# ----------------------------------------------------------------------------------------------- calibration
def calibrate(problem: Problem, ledger: Ledger, theta: ModelParameters, jac0: DateJacobian, u_names: list[str],
              options: ModelErrorOptions, executor: Executor | None,
              without_gains: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None) -> dict[str, Any]:
    """θ estimated at the reference date (:mod:`suspid.method.calibration`), Gauss-Newton from the nominal θ.

    ``without_gains(x, weights)``: the part of ``x (n_channels, n_freqs, ...)`` that a gain per channel more than
    the flat one cannot explain (applied to the residual and the Jacobian: that gain estimated jointly with θ);
    none: the flat offsets only.

    :returns: JSON-able details, with ``"t_hat"`` ``(p,)``, ``"covariance_t"`` ``(p, p)`` and ``"pinned"`` ``(p,)``
        (lists) for the checks, and ``"n_simulations"`` the further Jacobians' simulations.
    """
    opt = options.calibration
    ref = problem.reference
    y_mes0 = ref["y_mes0"]
    v0 = y_mes0.shape[0]
    K, F = y_mes0.shape[1:]
    weights = v0 / np.maximum(problem.noise_model.variance_, 1e-12)
    clusters = octave_clusters(problem.freqs, K, opt.cluster_octaves)
    p = len(theta.names)
    t_lo, t_hi = theta.t_of(theta.lower), theta.t_of(theta.upper)
    prior = np.full(p, 1.0 / UNIFORM_SD ** 2)        # uniform over the assumed range, as a Gaussian of its spread
    t = np.zeros(p)
    y_sim, dt = jac0.y, jac0.dt
    strip = without_gains or (lambda x, w: x)
    residual = strip(y_mes0.mean(axis=0) - y_sim.mean(axis=0), weights)
    dt_mean = strip(dt.mean(axis=0), weights)
    # the overdispersion κ: how much the discrepancy inflates the data-only covariance over the white one
    first = calibrate_step(residual, dt_mean, weights, clusters, t, np.zeros(p))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.diag(first.covariance) / first.naive_sd ** 2
    kappa = float(max(1.0, np.nanmean(ratio[np.isfinite(ratio)]) if np.isfinite(ratio).any() else 1.0))
    n_sims, history = 0, []
    for it in range(opt.max_iterations):
        step = calibrate_step(residual, dt_mean, weights, clusters, t, prior, kappa)
        new_t = np.clip(t + step.step, t_lo, t_hi)
        history.append({"t": t.tolist(), "step": step.step.tolist(),
                        "sd": np.sqrt(np.clip(np.diag(step.covariance), 0, None)).tolist(),
                        "residual_rms_db": step.residual_rms_db})
        moved = float(np.abs(new_t - t).max()) if p else 0.0
        t = new_t
        if moved < 2e-3 or it == opt.max_iterations - 1:
            break
        jac = date_jacobian(problem, ledger, problem.reference_segments, dict(problem.w0) | theta.w(t), [], theta,
                            executor)
        n_sims += 0 if jac.cached else jac.n_simulations
        y_sim, dt = jac.y, jac.dt
        residual = strip(y_mes0.mean(axis=0) - y_sim.mean(axis=0), weights)
        dt_mean = strip(dt.mean(axis=0), weights)
    final = step
    cov = final.covariance
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    at_bound = np.isclose(t, t_lo) | np.isclose(t, t_hi)
    pinned = (sd <= opt.max_sd_fraction) & ~at_bound
    theta_hat = theta.theta_of(t)
    n = opt.n_sigmas
    params = {}
    for j, name in enumerate(theta.names):
        entry: dict[str, Any] = {"nominal": float(theta.nominal[j]),
                                 "assumed_range": [float(theta.lower[j]), float(theta.upper[j])],
                                 "standard_deviation": float(sd[j] * theta.width[j]),
                                 "estimate": float(theta_hat[j])}
        if pinned[j]:
            lo = max(theta_hat[j] - n * sd[j] * theta.width[j], 0.0 if theta.lower[j] >= 0 else -np.inf)
            entry.update({"status": "calibrated", "value": float(theta_hat[j]),
                          "interval": [float(lo), float(theta_hat[j] + n * sd[j] * theta.width[j])]})
        else:
            why = ("its estimate reaches a bound of the assumed range" if at_bound[j] and sd[j] <= opt.max_sd_fraction
                   else f"weak information: its standard deviation exceeds {100 * opt.max_sd_fraction:.0f} % of the "
                   "assumed range")
            entry.update({"status": "not pinned down: keeps its assumed range", "reason": why,
                          "value": float(theta.nominal[j]), "interval": [float(theta.lower[j]), float(theta.upper[j])]})
        params[name] = entry
    return {"status": "done", "method": "Gauss-Newton least squares on the reference date's mean spectra, per-channel "
            "offsets profiled out, cluster-robust (channel x octave) covariance", "source": theta.source,
            "n_sigmas": n, "max_sd_fraction": opt.max_sd_fraction, "parameters": params,
            "n_iterations": len(history), "n_clusters": final.n_clusters, "overdispersion": kappa,
            "residual_rms_db": final.residual_rms_db, "n_simulations": n_sims, "history": history,
            "t_hat": t.tolist(), "covariance_t": cov.tolist(), "pinned": pinned.tolist()}


# ----------------------------------------------------------------------------------------------- the checks
def _objective_at_reference(problem: Problem, y_sim0: np.ndarray, rng_name: str) -> ObjectiveFunction:
    """J on the measurement date with B fitted again on the reference date's ``y_sim0`` (as the nuisance check)."""
    ref, config = problem.reference, problem.config
    model = fit_noise_model(ref["y_mes0"], y_sim0, config.noise.model_dump(exclude={"path", "reference"}),
                            freqs=problem.freqs, channels=problem.channels,
                            speeds=segment_speeds(problem.reference_segments))
    return ObjectiveFunction.from_noise_model(problem.objective, problem.y_mes, problem.freqs, model,
                                              named_rng(config.seed, rng_name), weights=problem.weights,
                                              channels=problem.channels, speeds=problem.speeds)


def _curvature(J: Callable[[np.ndarray], float], q: int, h_u: float) -> tuple[np.ndarray, np.ndarray]:
    """Hessian ``(q, q)`` and gradient ``(q,)`` of ``J`` at 0 by central differences of step ``h_u``."""
    Eu = h_u * np.eye(q)
    J0 = J(np.zeros(q))
    H = np.empty((q, q))
    g = np.empty(q)
    for i in range(q):
        Jp, Jm = J(Eu[i]), J(-Eu[i])
        H[i, i] = (Jp - 2 * J0 + Jm) / h_u ** 2
        g[i] = (Jp - Jm) / (2 * h_u)
        for j in range(i):
            H[i, j] = H[j, i] = (J(Eu[i] + Eu[j]) - J(Eu[i] - Eu[j]) - J(-Eu[i] + Eu[j]) + J(-Eu[i] - Eu[j])) \
                / (4 * h_u ** 2)
    return H, g


def correction_draws(n: int) -> list[str]:
    """The names of the ``n`` noise-path draws (RNG streams of the config seed) the calibrated shift averages over;
    the first is the one the other linearised checks use."""
    return ["nuisance"] + [f"nuisance-{i}" for i in range(1, int(n))]


def search_point(problem: Problem, jac: DateJacobian, y_sim0: np.ndarray, u_opt: np.ndarray, initial_step: float,
                 max_evaluations: int, rng_name: str = "nuisance") -> np.ndarray:
    """The maximiser of J on the spectra ``jac.y + jac.du (u - u_opt)`` (linearised at u_opt), B fitted on the
    reference date's ``y_sim0`` with the noise paths of the stream ``rng_name``, by the self-check's local search
    from u_opt: ``(q,)`` its u − u_opt. No simulation. A search, not a Newton step: J (the overlap's kernel
    densities) has a sharp maximum whose curvature at u_opt says little about where it lies."""
    fn = _objective_at_reference(problem, y_sim0, rng_name)
    u_opt = np.asarray(u_opt, float)

    def neg_j(u: np.ndarray) -> float:
        return -float(fn.evaluate(jac.y + jac.du @ (np.clip(u, 0, 1) - u_opt))[0])

    return local_search(neg_j, u_opt, initial_step, max_evaluations) - u_opt


def parameter_shifts(problem: Problem, jac_opt: DateJacobian, jac0: DateJacobian, y_sim0: np.ndarray,
                     h_u: float = 0.02, h_t: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """G = du_opt/dt ``(q, p)`` by the implicit-function theorem on J(u, t) evaluated on the linearised spectra
    y_opt + ∂y/∂u Δu + ∂y/∂t Δt, B fitted again at the reference date on y_sim0 + ∂y_sim0/∂t Δt for each t.

    Second differences with steps ``h_u`` (u) and ``h_t`` (t) of the evaluations of J; no simulation.
    :returns: ``(G, flat (q,) bool)`` (:func:`suspid.method.calibration.implicit_shifts`).
    """
    q, p = jac_opt.du.shape[-1], jac_opt.dt.shape[-1]
    fns: dict[tuple, ObjectiveFunction] = {}

    def J(du: np.ndarray, dt: np.ndarray) -> float:
        k = tuple(np.round(dt, 9))
        if k not in fns:
            fns[k] = _objective_at_reference(problem, y_sim0 + jac0.dt @ dt, "nuisance")
        return float(fns[k].evaluate(jac_opt.y + jac_opt.du @ du + jac_opt.dt @ dt)[0])

    zero_t = np.zeros(p)
    Eu, Et = h_u * np.eye(q), h_t * np.eye(p)
    H_uu, _ = _curvature(lambda du: J(du, zero_t), q, h_u)
    H_ut = np.empty((q, p))
    for i in range(q):
        for j in range(p):
            H_ut[i, j] = (J(Eu[i], Et[j]) - J(Eu[i], -Et[j]) - J(-Eu[i], Et[j]) + J(-Eu[i], -Et[j])) / (4 * h_u * h_t)
    return implicit_shifts(H_uu, H_ut)


def linear_self_check(problem: Problem, jac0: DateJacobian, options: ModelErrorOptions) -> np.ndarray | None:
    """The self-check's splits (:func:`suspid.workflows.reference.self_check`: the same halves, noise fits and
    noise paths) with w identified on the reference spectra ``jac0.y`` linearised in w, y + ∂y/∂u Δu (``jac0``
    at w0 and the model parameters the run identifies with, the calibrated ones where calibrated):
    ``(n_splits, q)`` shifts u_opt − u0, or None without enough reference segments."""
    ref, segments = problem.reference, problem.reference_segments
    if not ref or not segments or len(segments) < SELF_CHECK_MIN_SEGMENTS:
        return None
    sc, config, q = options.self_check, problem.config, problem.q
    y_mes0, y_sim0 = ref["y_mes0"], jac0.y
    v0 = y_mes0.shape[0]
    u0 = problem.to_unit(np.array([problem.w0[n] for n in problem.names]))
    max_eval = sc.max_evaluations or 30 * q
    rng = named_rng(config.seed, "self-check")
    noise_options = config.noise.model_dump(exclude={"path", "reference"})
    n_fit = v0 // 2
    shifts = np.empty((sc.n_splits, q))
    for s in range(sc.n_splits):
        perm = rng.permutation(v0)
        a, b = np.sort(perm[:n_fit]), np.sort(perm[n_fit:])
        model = fit_noise_model(y_mes0[a], y_sim0[a], noise_options, freqs=problem.freqs,
                                channels=problem.channels, speeds=[segments[i].mean_speed for i in a])
        fn = ObjectiveFunction.from_noise_model(problem.objective, y_mes0[b], problem.freqs, model, rng,
                                                weights=problem.weights, channels=problem.channels,
                                                speeds=[segments[i].mean_speed for i in b])
        y_b, du_b = y_sim0[b], jac0.du[b]

        def neg_j(u: np.ndarray) -> float:
            return -float(fn.evaluate(y_b + du_b @ (np.clip(u, 0, 1) - u0))[0])  # noqa: B023

        shifts[s] = local_search(neg_j, u0, sc.initial_step, max_eval) - u0
    return shifts


def linearised_model_error(problem: Problem, ledger: Ledger, u_opt: np.ndarray, h: float, options: ModelErrorOptions,
                           retry_failed: bool, sd: np.ndarray | None, executor: Executor | None,
                           full: ModelErrorFn) -> dict[str, Any]:
    """The model-error checks of :func:`suspid.workflows.analysis.model_error` by linearisation (module docstring).

    :param full: :func:`suspid.workflows.analysis.model_error`, run here for the adequacy bands alone (its
        searches off), whose flags and report this extends.
    :returns: the same contract as ``full``; the report adds ``"method": "linearised"``, ``"calibration"`` and
        ``"budget"`` (the simulations each check took).
    """
    from suspid.workflows.analysis import no_change_check   # (analysis imports this module)

    t_start = time.perf_counter()
    base_opts = options.model_copy(update={
        "method": "full", "self_check": options.self_check.model_copy(update={"enabled": False}),
        "adequacy": options.adequacy.model_copy(update={"groups": False}),
        "nuisance": options.nuisance.model_copy(update={"parameters": {}}), "no_change": False})
    trust = full(problem, ledger, u_opt, h, base_opts, retry_failed, sd, executor, apply_no_change_test=False,
                 model_parameters_check=False)
    report = trust["report"]
    report["method"] = "linearised"
    names, q = problem.names, problem.q
    reasons: dict[str, list[str]] = {n: list(r) for n, r in trust["reasons"].items()}
    sd_ = np.zeros(q) if sd is None else np.asarray(sd, float)
    theta = model_parameters(problem, options)
    budget: dict[str, Any] = {"adequacy": 0}
    n_sigmas = problem.config.identifiability.n_sigmas
    u0 = problem.to_unit(np.array([problem.w0[n] for n in names], float))
    have_ref = bool(problem.reference) and bool(problem.reference_segments)
    x_opt = problem.from_unit(np.asarray(u_opt, float))
    w_opt = problem.w_of(x_opt)

    # the two Jacobians, shared by every check
    jac0 = jac_opt = None
    try:
        if have_ref:
            jac0 = date_jacobian(problem, ledger, problem.reference_segments, dict(problem.w0), names, theta, executor)
            budget["jacobian_reference_w0"] = jac0.n_simulations
        jac_opt = date_jacobian(problem, ledger, problem.segments, w_opt, names, theta, executor)
    except ClusterError:
        raise
    except SuspidError as exc:   # e.g. an unstable vehicle at a finite-difference step: no linearised check
        why = f"not run: the spectra's Jacobian failed ({exc})"
        no_change, report["no_change"] = no_change_check(problem, ledger, u_opt, options, retry_failed, executor)
        budget["no_change"] = int(report["no_change"].get("n_simulations", 0))
        report.update({"self_check": {"status": why}, "nuisance": {"status": why}, "calibration": {"status": why},
                       "budget": budget})
        checks = {"adequacy": _base_status(report, "adequacy"), "self_check": why, "groups": why, "nuisance": why,
                  "no_change": report.get("no_change", {}).get("status", "not run")}
        bound = apply_no_change(no_change, names, sd_, trust["bias_bound"], np.asarray(u_opt, float) - u0, n_sigmas,
                                options.max_half_width, reasons)
        return _trust(names, reasons, checks, bound, report)
    budget["jacobian_measurement_w_opt"] = jac_opt.n_simulations
    budget["methods"] = jac_opt.methods

    # calibration of θ at the reference date (jac0's simulations are counted above)
    p = len(theta.names)
    cal = calibrate_at_reference(problem, ledger, theta, options, executor, jac0)
    t_hat, cov_t, pinned = cal.t_hat, cal.covariance_t, cal.pinned
    if cal.done:
        budget["calibration"] = cal.n_simulations
    report["calibration"] = cal.report
    # the calibrated model's reference spectra and their Jacobian, simulated at θ̂ (one Jacobian more): extrapolated
    # linearly from the nominal θ (y_sim0 + ∂y/∂t Δt) they inflated the self-check's bias, the spectra being far from
    # linear in a mount's stiffness (independent2, seed 7: k_prim_z -10.4 % extrapolated, -8.0 % simulated)
    jac0_cal = jac0
    if have_ref and report["calibration"].get("status") == "done" and np.any(t_hat != 0):
        jac0_cal = date_jacobian(problem, ledger, problem.reference_segments, dict(problem.w0) | theta.w(t_hat), names,
                                 theta, executor)
        budget["jacobian_reference_calibrated"] = 0 if jac0_cal.cached else jac0_cal.n_simulations

    bound_known = np.zeros(q)     # bias bounds from the self-check and the groups (signs unknown)
    sc_bias, sc_se, groups_half = np.zeros(q), np.zeros(q), np.zeros(q)
    correct = options.correct
    sc_opt = options.self_check
    if not sc_opt.enabled:
        report["self_check"] = {"status": "disabled"}
    else:
        shifts = linear_self_check(problem, jac0_cal, options) if have_ref else None
        if shifts is None:
            report["self_check"] = {"status": f"not run: {self_check_missing(problem)}"}
        else:
            n_splits = shifts.shape[0]
            bias = shifts.mean(axis=0)
            scatter = shifts.std(axis=0, ddof=1) if n_splits > 1 else np.zeros(q)
            se = scatter / np.sqrt(n_splits)
            v0 = problem.reference["y_mes0"].shape[0]
            report["self_check"] = {
                "status": "done", "linearised": True, "calibrated_model": bool(pinned.any()),
                "bias_percent": {n: float(100 * b) for n, b in zip(names, bias)},
                "scatter_percent": {n: float(100 * s) for n, s in zip(names, scatter)},
                "shifts_percent": [{n: float(100 * s) for n, s in zip(names, row)} for row in shifts],
                "n_splits": n_splits, "segments_fit": v0 // 2, "segments_identify": v0 - v0 // 2,
                "n_simulations": 0, "standard_error_percent": {n: float(100 * v) for n, v in zip(names, se)},
                "excess_bias_percent": {n: float(100 * v) for n, v in zip(names, np.maximum(np.abs(bias) - 2 * se, 0))}}
            budget["self_check"] = 0
            bound_known += np.abs(bias)
            sc_bias, sc_se = bias, se
            for k in ([] if correct else np.flatnonzero((np.abs(bias) > 2 * se) & (np.abs(bias) > options.max_bias))):
                reasons.setdefault(names[k], []).append(
                    f"reference-date self-check (linearised): w_opt moves by {100 * bias[k]:+.1f} ± {100 * se[k]:.1f} % "
                    f"of the interval where the truth is w0 ({n_splits} splits; threshold "
                    f"{100 * options.max_bias:.0f} %, the bias beyond 2 standard errors)")

    ad = options.adequacy
    if ad.enabled and ad.groups and "groups" not in report.get("adequacy", {}):
        S = jac_opt.du.mean(axis=0)
        S = np.moveaxis(S, -1, 0)
        y_lin = lambda u: jac_opt.y + jac_opt.du @ (np.asarray(u, float) - u_opt)  # noqa: E731
        ge = group_estimates(problem, np.asarray(u_opt, float), S, ad.min_group_share, ad.group_evaluations,
                             sc_opt.initial_step, None, executor, spectra_at=y_lin)
        informed = np.isfinite(ge.u)
        spread = np.array([np.ptp(ge.u[informed[:, k], k]) if informed[:, k].sum() >= 2 else 0.0 for k in range(q)])
        report.setdefault("adequacy", {})["groups"] = {
            "linearised": True, "min_group_share": ad.min_group_share, "max_spread_percent": 100 * ad.max_spread,
            "n_simulations": 0,
            "estimates_percent": {g.name: {n: (None if not np.isfinite(ge.u[i, k]) else float(100 * ge.u[i, k]))
                                           for k, n in enumerate(names)} for i, g in enumerate(ge.groups)},
            "information_share": {g.name: {n: float(ge.share[i, k]) for k, n in enumerate(names)}
                                  for i, g in enumerate(ge.groups)},
            "spread_percent": {n: float(100 * v) for n, v in zip(names, spread)}}
        budget["data_groups"] = 0
        bound_known += spread / 2
        groups_half = spread / 2
        for k in range(q):
            if spread[k] > ad.max_spread and spread[k] > 2 * np.sqrt(2) * sd_[k]:
                parts = ", ".join(f"{g.name} {100 * ge.u[i, k]:.0f} %" for i, g in enumerate(ge.groups)
                                  if informed[i, k])
                reasons.setdefault(names[k], []).append(
                    f"the parts of the data disagree (linearised): re-identified on each data group it is read from, "
                    f"it lies at {parts} of its interval (spread {100 * spread[k]:.0f} %, threshold "
                    f"{100 * ad.max_spread:.0f} %)")

    shift_known = np.zeros(q)
    shift_se = np.zeros(q)       # the Monte Carlo standard error of the calibrated shift over the path draws
    n_draws = 0                  # the path draws it was searched on (0: no calibrated model, G times t instead)
    last_step = np.zeros(q)      # the correction's last linearised step (its remaining error)
    sd_model = np.zeros(q)
    if not theta.names:
        report["nuisance"] = {"status": "not run: no model parameter"}
    elif not have_ref:
        report["nuisance"] = {"status": "not run: the reference date's data are not part of this run "
                                        "(give noise.reference)"}
    else:
        G, flat = parameter_shifts(problem, jac_opt, jac0, jac0.y)
        Gz = np.nan_to_num(G)
        # each θ's range for the check: its calibrated interval where pinned, its assumed range otherwise
        n_c = options.calibration.n_sigmas
        sd_t = np.sqrt(np.clip(np.diag(cov_t), 0, None))
        lo_t = np.where(pinned, t_hat - n_c * sd_t, theta.t_of(theta.lower))
        hi_t = np.where(pinned, t_hat + n_c * sd_t, theta.t_of(theta.upper))
        values, rows = [], []
        for j, name in enumerate(theta.names):
            for t_end in (lo_t[j], hi_t[j]):
                values.append((name, float(theta.theta_of(np.eye(p)[j] * t_end)[j])))
                rows.append(Gz[:, j] * t_end)
        shifts = np.array(rows)
        largest_row = np.argmax(np.abs(shifts), axis=0)
        largest = np.abs(shifts[largest_row, np.arange(q)])
        # what remains uncertain: the calibration's posterior, or each θ uniform over its assumed range
        if report["calibration"].get("status") == "done":   # the posterior, with the correlations of the θ
            mean_t, cov = t_hat, cov_t
        else:
            mean_t, cov = 0.5 * (theta.t_of(theta.lower) + theta.t_of(theta.upper)), np.eye(p) * UNIFORM_SD ** 2
        shift_known = Gz @ mean_t
        if report["calibration"].get("status") == "done" and np.any(t_hat != 0):
            # the calibrated model's own spectra (the spectra are far from linear in a mount's stiffness over a
            # factor 2): the maximiser moves by the search's point there minus its point with the nominal model
            w_hat = theta.w(t_hat)
            at_hat = date_jacobian(problem, ledger, problem.segments, w_opt | w_hat, names, theta, executor)
            ref_hat = jac0_cal
            budget["jacobians_at_calibrated"] = 0 if at_hat.cached else at_hat.n_simulations
            step, n_eval = options.self_check.initial_step, options.nuisance.max_evaluations or 20 * q
            # each draw of the noise paths moves J's maximiser (the likelihood's by about 1 % of the interval): the
            # calibrated and the nominal searches share each draw's paths, and their differences are averaged
            draws = correction_draws(options.correction_draws)
            n_draws = len(draws)
            base = np.array([search_point(problem, jac_opt, jac0.y, u_opt, step, n_eval, r) for r in draws])
            cal_r = np.array([search_point(problem, at_hat, ref_hat.y, u_opt, step, n_eval, r) for r in draws])
            diffs = cal_r - base      # (draws, q): each draw's calibrated minus nominal maximiser
            if correct and np.abs(diffs.mean(axis=0)).max() > REFINE_SHIFT:
                # a large shift leaves the linearisation at w_opt: linearise again where the calibrated searches
                # land and search again (one Jacobian more); what that moved bounds what the linearisation misses
                u1 = np.clip(np.asarray(u_opt, float) + cal_r.mean(axis=0), 0, 1)
                at_1 = date_jacobian(problem, ledger, problem.segments, problem.w_of(problem.from_unit(u1)) | w_hat,
                                     names, theta, executor)
                budget["jacobians_at_calibrated"] += 0 if at_1.cached else at_1.n_simulations
                cal_1 = np.array([u1 - np.asarray(u_opt, float) + search_point(problem, at_1, ref_hat.y, u1, step,
                                                                               n_eval, r) for r in draws])
                last_step = (cal_1 - cal_r).mean(axis=0)
                diffs = cal_1 - base
            shift_known = diffs.mean(axis=0)
            shift_se = diffs.std(axis=0, ddof=1) / np.sqrt(n_draws) if n_draws > 1 else np.zeros(q)
        sd_model = np.hypot(model_spread(Gz, cov), shift_se)   # the draws' Monte Carlo error is random too
        report["nuisance"] = {
            "status": "done", "linearised": True, "n_simulations": 0, "max_shift_percent": 100 * options.nuisance.max_shift,
            "parameters": {n: {"range": [float(theta.theta_of(np.eye(p)[j] * lo_t[j])[j]),
                                         float(theta.theta_of(np.eye(p)[j] * hi_t[j])[j])],
                               "calibrated": bool(pinned[j])} for j, n in enumerate(theta.names)},
            "shifts_percent": [{"parameter": pn, "value": v, **{n: float(100 * s) for n, s in zip(names, row)}}
                               for (pn, v), row in zip(values, shifts)],
            "largest_shift_percent": {n: float(100 * v) for n, v in zip(names, largest)},
            "sensitivity_percent_per_range": {n: {tn: (None if not np.isfinite(G[k, j]) else float(100 * G[k, j]))
                                                  for j, tn in enumerate(theta.names)} for k, n in enumerate(names)},
            "shift_percent": {n: float(100 * v) for n, v in zip(names, shift_known)},
            "shift_draws": n_draws,
            "shift_standard_error_percent": {n: float(100 * v) for n, v in zip(names, shift_se)},
            "spread_percent": {n: float(100 * v) for n, v in zip(names, sd_model)},
            "w_opt_calibrated": {n: float(v) for n, v in
                                 zip(names, problem.from_unit(np.clip(u_opt + shift_known, 0, 1)))}}
        budget["nuisance"] = 0
        calibrated = report["calibration"].get("status") == "done"
        for k in range(q):
            if flat[k] or (correct and calibrated):   # corrected: the posterior's spread widens the interval
                continue
            if largest[k] > options.nuisance.max_shift:
                name, value = values[largest_row[k]]
                j = theta.names.index(name)
                what = "its calibrated interval" if pinned[j] else "its assumed range"
                reasons.setdefault(names[k], []).append(
                    f"rests on a model parameter (linearised): with {name} = {value:g} (end of {what}) it is "
                    f"identified {100 * shifts[largest_row[k], k]:+.1f} % of its interval away (threshold "
                    f"{100 * options.nuisance.max_shift:.0f} %)")
    sources = BiasSources(sc_bias, groups_half, shift_known, sd_model, last_step, sc_se)  # (suspid.workflows.trust)
    # with correct (the default): the calibrated model's shift corrected (a bias with its sign), and the self-check's
    # mean shift where it is beyond 2 standard errors (self_check.correct: measured on the calibrated model's own
    # spectra where the truth is w0), its standard error added to the spread; what is left of the self-check's
    # shift and half the groups' spread bound the rest, two independent sources of unknown sign in quadrature; the
    # model parameters' posterior spread adds to the sampling one; the shift's own error away from w0
    # (transfer_error x |shift|) is a third source of unknown sign
    bound, correction = combine_sources(sd_, sources, correct, n_sigmas, sc_opt.correct, options.transfer_error)
    if correction is not None:
        report["correction"] = correction_report(problem, u_opt, correction, sources, sc_opt.correct,
                                                 last_step_percent=last_step)
    u_est = np.asarray(u_opt, float) if correction is None else np.clip(np.asarray(u_opt, float) + correction, 0, 1)
    no_change, report["no_change"] = no_change_check(problem, ledger, u_opt, options, retry_failed, executor,
                                                      correction)
    budget["no_change"] = int(report["no_change"].get("n_simulations", 0))
    bound = apply_no_change(no_change, names, sd_, bound, u_est - u0, n_sigmas, options.max_half_width, reasons)
    transfer = transfer_term(sources, options.transfer_error, correct)
    report["bias_sources_percent"] = {n: {"self_check_and_groups": float(100 * a), "model_parameters_shift": float(100 * s),
                                          "model_parameters_spread": float(100 * m),
                                          "model_parameters_transfer": float(100 * t)}
                                      for n, a, s, m, t in zip(names, bound_known, shift_known, sd_model, transfer)}
    budget["total"] = int(sum(v for k, v in budget.items() if isinstance(v, int) and k != "total"))
    budget["wall_time_s"] = round(time.perf_counter() - t_start, 2)
    report["budget"] = budget
    groups = report.get("adequacy", {}).get("groups")
    checks = {"adequacy": _base_status(report, "adequacy"),
              "self_check": report["self_check"]["status"],
              "groups": ("done" if groups is not None else
                         "not run: the adequacy test is disabled" if not ad.enabled else
                         "disabled (identifiability.model_error.adequacy.groups: false)"),
              "nuisance": report.get("nuisance", {}).get("status", "done"),
              "no_change": report.get("no_change", {}).get("status", "not run")}
    return {**_trust(names, reasons, checks, bound, report), "correction": correction}


def _base_status(report: dict[str, Any], check: str) -> str:
    """The status the full checks' own run gave ``check`` (the adequacy test runs there)."""
    return report.get("checks", {}).get(check, {}).get("status", report.get(check, {}).get("status", "not run"))


def _trust(names: list[str], reasons: dict[str, list[str]], checks: dict[str, str], bound: Any,
           report: dict[str, Any]) -> dict[str, Any]:
    """The contract of :func:`suspid.workflows.analysis.model_error`: trust in three states on the same rule."""
    report["checks"] = checks_report(checks)
    return {**trust_states(names, [reasons.get(n, []) for n in names], checks), "bias_bound": bound,
            "report": report}


@dataclass
class Calibration:
    """θ at the reference date in the units t = (θ − θ_nominal) / width of its range.

    :ivar report: JSON-able details (result.json's ``calibration``), with ``"status"``.
    :ivar t_hat: ``(p,)`` the estimate (zeros where the calibration did not run).
    :ivar covariance_t: ``(p, p)`` its posterior covariance.
    :ivar pinned: ``(p,)`` bool, the parameters the reference date pins down.
    :ivar n_simulations: simulations it took (its Jacobians', an analytic Jacobian counting one).
    """

    report: dict[str, Any]
    t_hat: np.ndarray
    covariance_t: np.ndarray
    pinned: np.ndarray
    n_simulations: int

    @property
    def done(self) -> bool:
        return self.report.get("status") == "done"


def calibrate_at_reference(problem: Problem, ledger: Ledger, theta: ModelParameters, options: ModelErrorOptions,
                           executor: Executor | None, jac0: DateJacobian | None = None) -> Calibration:
    """θ calibrated at the reference date (:func:`calibrate`), or why not, for both methods' checks.

    :param jac0: the reference date's spectra and Jacobian at w0 and the nominal θ, where the caller holds them
        (otherwise from :func:`date_jacobian`, kept in the ledger; its simulations count in ``n_simulations``).
    """
    p = len(theta.names)
    none = lambda why: Calibration({"status": why}, np.zeros(p), np.zeros((p, p)), np.zeros(p, bool), 0)  # noqa: E731
    if not theta.names:
        return none("not run: no model parameter to calibrate (the simulator declares none calibratable; give "
                    "identifiability.model_error.calibration.parameters)")
    if not problem.reference or not problem.reference_segments:
        return none("not run: the reference date's data are not part of this run (give noise.reference)")
    if not options.calibration.enabled:
        return none("disabled")
    n_jac0 = 0
    if jac0 is None:
        jac0 = date_jacobian(problem, ledger, problem.reference_segments, dict(problem.w0), problem.names, theta,
                             executor)
        n_jac0 = 0 if jac0.cached else jac0.n_simulations
    cal = calibrate(problem, ledger, theta, jac0, problem.names, options, executor)
    t_hat, cov, pinned = np.array(cal.pop("t_hat")), np.array(cal.pop("covariance_t")), np.array(cal.pop("pinned"))
    return Calibration(cal, t_hat, cov, pinned, n_jac0 + cal["n_simulations"])


# ----------------------------------------------------------------------------------------------- reporting
def calibration_result(report: dict[str, Any]) -> dict[str, Any] | None:
    """``result.json``'s ``"calibration"``: each model parameter with its value and interval (None when the
    linearised checks did not run). ``report`` is the model-error report (``result["model_error"]``); the
    calibration is *moved* out of it, so that result.json carries it once, at its top level (results written
    before keep a copy under ``model_error``: :func:`calibration_of` reads both)."""
    cal = (report or {}).pop("calibration", None)
    return None if cal is None else dict(cal)


def calibration_of(result: dict[str, Any]) -> dict[str, Any] | None:
    """The calibration of a result.json: its top-level ``"calibration"``, or (results written before it moved
    there alone) ``model_error.calibration``."""
    return result.get("calibration") or (result.get("model_error") or {}).get("calibration")


def calibration_markdown(result: dict[str, Any]) -> str:
    """report.md's section on the calibrated model parameters (empty without a calibration)."""
    cal = calibration_of(result)
    if not cal:
        return ""
    out = ["", "## Model parameters calibrated at the reference date", ""]
    if cal.get("status") != "done":
        return "\n".join(out + [f"Calibration: {cal.get('status')}.", ""])
    out.append(f"{cal['method']} ({cal['n_iterations']} step(s), {cal['n_clusters']} clusters, residual "
               f"{cal['residual_rms_db']:.2f} dB rms; parameters: {cal['source']}). A parameter is calibrated when "
               f"its standard deviation is below {100 * cal['max_sd_fraction']:.0f} % of its assumed range; the "
               f"others keep that range. Intervals: ± {cal['n_sigmas']:g} standard deviations.\n")
    rows = []
    for n, e in cal["parameters"].items():
        rows.append([n, f"{e['nominal']:.4g}", "[{:.4g}, {:.4g}]".format(*e["assumed_range"]), f"{e['value']:.4g}",
                     "[{:.4g}, {:.4g}]".format(*e["interval"]),
                     e["status"] + (f" ({e['reason']})" if e.get("reason") else "")])
    header = ["model parameter", "nominal", "assumed range", "value", "interval", "status"]
    out.append("| " + " | ".join(header) + " |")
    out.append("|" + "---|" * len(header))
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(out) + "\n"
