"""What the identified w_opt is worth: errors, identifiability, intervals, sensitivity.

:func:`analyse` turns the EGO result into the typed :class:`~suspid.workflows.results.Analysis`, the first
keys of ``result.json``: w_opt in SI and normalised units, the errors against a known
w_ref (numerical experiment), the identifiability verdict and the intervals of
:mod:`suspid.method.identifiability`, whose sandwich covariance needs the noise
in the gradient of J at w_opt (:func:`gradient_noise`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any, Iterator, Sequence

import numpy as np

from suspid.config import Config
from suspid.errors import SimulatorError
from suspid.infra.ledger import Evaluation, Ledger, stable_hash
from suspid.infra.seeds import rng as named_rng
from suspid.interfaces import Executor, SpectraModel
from suspid.method.adequacy import band_residuals, frequency_bands, information_share
from suspid.method.identifiability import ModelErrorOptions, Verdict, assess, bias_aware_half_width
from suspid.method.jacobian import fisher_identifiability, fisher_information
from suspid.method.noise import bootstrap_refit, reference_paths
from suspid.method.objective import ObjectiveFunction
from suspid.optimize.loop import LoopOutcome
from suspid.optimize.normalize import Normalized
from suspid.workflows.evaluation import j_of_spectra, objective_on, y_sim_key
from suspid.workflows.problem import Problem, segment_speeds
from suspid.workflows.tasks import SpectraTask, run_tasks
from suspid.workflows.adequacy import group_estimates
from suspid.workflows.nuisance import model_parameter_check
from suspid.workflows.phases import Phases
from suspid.workflows.linearised import (calibrate_at_reference, calibration_result, linearised_model_error,
                                         model_parameters)
from suspid.workflows.no_change import NoChange, apply_no_change, no_change_test, reported_correction
from suspid.workflows.reference import self_check, self_check_missing
from suspid.workflows.trust import (CHECK_LABELS, BiasSources, checks_report, combine_sources, correction_report,
                                    transfer_term, trust_states)
from suspid.workflows.results import Analysis, FailedPoint, IntervalMethod, PaperLoop, Sensitivity
from suspid.elements import declared_parameters


def _y_sim_key(problem: Problem, u: np.ndarray) -> tuple[str, dict[str, float]]:
    w = problem.w_of(problem.from_unit(u))
    return y_sim_key(problem, w), w


def simulate_missing(problem: Problem, ledger: Ledger, us: Sequence[np.ndarray], executor: Executor | None = None,
                     retry_failed: bool = False) -> None:
    """Simulate together, on ``executor``, the spectra at the points ``us`` ([0, 1]^q) not yet in the ledger.

    Each result is stored in the ledger (:func:`cached_y_sim` reads it); a failed
    simulation (:class:`~suspid.errors.SimulatorError`) is recorded as failed, and
    not simulated again unless ``retry_failed``.
    """
    todo = {}
    for u in us:
        key, w = _y_sim_key(problem, u)
        known = ledger.get(key)
        if ledger.get_array(key + ":y") is None and (known is None or known.ok or retry_failed):
            todo[key] = w
    task = SpectraTask.of(problem.simulator, problem.segments, problem.config.spectra, with_freqs=True)
    for (key, w), outcome in zip(todo.items(), run_tasks(executor, [(task, w) for w in todo.values()])):
        if isinstance(outcome, SimulatorError):
            ledger.put(Evaluation(key, w, None, None, status="failed", error=str(outcome)))
        elif isinstance(outcome, BaseException):
            raise outcome
        else:
            ledger.put_array(key + ":y", outcome[0])
            ledger.put_array(key + ":freqs", outcome[1])


def cached_y_sim(problem: Problem, ledger: Ledger, u: np.ndarray, retry_failed: bool = False,
                 executor: Executor | None = None) -> np.ndarray:
    """Spectra ``(v, n_channels, n_freqs)`` dB at ``u`` ([0, 1]^q) on the measurement date's segments.

    Cached in the ledger (simulated on ``executor`` when missing); a failure is
    cached too, and raised again (unless ``retry_failed``).
    """
    simulate_missing(problem, ledger, [u], executor, retry_failed)
    key, _ = _y_sim_key(problem, u)
    y = ledger.get_array(key + ":y")
    if y is None:
        raise SimulatorError(ledger.get(key).error)
    return y


def bootstrap_objectives(problem: Problem, n_redraws: int, paired: bool = True, reference: bool = True
                         ) -> Iterator[tuple[ObjectiveFunction, np.ndarray]]:
    """The bootstrap replicates of J behind the sampling interval (:func:`gradient_noise`), one at a time.

    Each replicate fits B again on the reference segments drawn with replacement (with ``reference``, the
    reference date's data in the run and no ``noise.path``), draws v new noise paths from it and resamples
    the v measured segments (with ``paired`` the simulated ones with the same indices). Draws come from the
    run's seed, so every caller sees the same replicates.

    :returns: per replicate, its J (an :class:`~suspid.method.objective.ObjectiveFunction` on the
        resampled measured spectra) and the indices ``(v,)`` to apply to simulated spectra ``(v, ...)``.
    """
    config = problem.config
    rng = named_rng(config.seed, "noise-redraws")
    ref_rng = named_rng(config.seed, "noise-redraws-reference")  # a stream of its own: the others' draws unchanged
    ref = problem.reference if reference and config.noise.path is None else {}  # B fitted in this run on them
    ref_speeds = segment_speeds(problem.reference_segments)
    paths = reference_paths(problem.noise_model, ref["y_mes0"], ref["y_sim0"]) if ref else None
    v = len(problem.segments)
    for _ in range(n_redraws):
        model = problem.noise_model
        if ref:
            model = bootstrap_refit(model, paths, ref_speeds, ref_rng, problem.freqs, problem.channels)
        b = model.sample(v, rng)
        i_mes = rng.integers(0, v, v)
        i_mod = i_mes if paired else rng.integers(0, v, v)
        yield objective_on(problem, b, problem.y_mes[i_mes], model), i_mod   # this replicate's J, built once


def second_difference(f0: np.ndarray | float, f_plus: np.ndarray, f_minus: np.ndarray, h_plus: np.ndarray,
                      h_minus: np.ndarray) -> np.ndarray:
    """d²f/du_k² from f at u, u + h_plus_k e_k and u - h_minus_k e_k (unequal steps: a box clips them).

    :param f_plus, f_minus: ``(q, ...)``, f at the q points on either side; ``f0`` f at u, broadcast against them.
    :param h_plus, h_minus: ``(q,)`` the steps, > 0 (a zero step divides by zero: the caller masks it).
    :returns: ``(q, ...)``.
    """
    shape = (-1,) + (1,) * (np.ndim(f_plus) - 1)
    hp, hm = np.reshape(h_plus, shape), np.reshape(h_minus, shape)
    return 2 * (hm * f_plus + hp * f_minus - (hp + hm) * f0) / (hp * hm * (hp + hm))


def gradient_noise(problem: Problem, ledger: Ledger, u_opt: np.ndarray, h: float, n_redraws: int,
                   paired: bool = True, failed: list[dict[str, Any]] | None = None,
                   retry_failed: bool = False, executor: Executor | None = None, reference: bool = True
                   ) -> tuple[np.ndarray, np.ndarray, float]:
    """Covariance of the noise in the gradient of J at w_opt, in [0, 1]^q coordinates.

    J is estimated from v measured spectra and v modelled ones (y_sim_i + b_i).
    Each of ``n_redraws`` replicates resamples the segments with replacement
    (a bootstrap over segments: the finite measured data; with ``paired`` a
    segment's measured and simulated spectra, which share its track, are
    drawn together, otherwise the two sets are resampled independently) and
    draws new noise paths b_i (the finite Monte Carlo sample of Y_mod, §2.3),
    then takes the central-difference gradient of J at w_opt from the 2q points
    w_opt ± h e_k (clipped to the box). The spread of these gradients over the
    replicates, Σ_g, is how far the data of the same kind could tilt J at its
    maximum. The 2q spectra are simulated once, together on ``executor`` (cached in the ledger).

    With ``reference`` and the reference date's data in the run, each replicate
    also resamples the v0 reference segments (y_mes0 and y_sim0 as pairs) and
    fits the noise model B again on them (eq. 3, the run's ``noise:`` options),
    then draws its noise paths from that B: the finite reference date is data
    too. Its mean μ_B, estimated from v0 segments, enters every Y_mod alike, so
    its error moves w_opt like a bias that a bootstrap of the measurement date
    alone cannot see (on the numerical experiment with the measurement process
    of :mod:`suspid.data.experiment` it left the intervals too narrow,
    ``benchmarks/RESULTS.md``). With a noise model read from ``noise.path``
    B is taken as known. The
    sensor-noise floor (``noise.floor``) is kept as fitted: only B's Gaussian
    part (mean and covariance) is fitted again, on the resampled paths.

    The same 2q + 1 spectra with the run's own data give the curvature of J
    along each axis, d²J/du_k² (central second differences).

    A ±h point whose simulation fails is replaced by w_opt itself (a one-sided
    difference along that axis, no curvature there) and appended to ``failed``.

    :returns: ``(Σ_g (q, q), curvature (q,), σ_J)``, σ_J the scatter of J(w_opt) itself.
    """
    q = problem.q

    y_sim_at = lambda u: cached_y_sim(problem, ledger, u, retry_failed)  # noqa: E731

    points = [u_opt, *np.clip(u_opt + h * np.eye(q), 0.0, 1.0), *np.clip(u_opt - h * np.eye(q), 0.0, 1.0)]
    simulate_missing(problem, ledger, points, executor, retry_failed)
    y_opt = y_sim_at(u_opt)  # w_opt was simulated by EGO: it cannot fail here

    def y_or_centre(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        try:
            return u, y_sim_at(u)
        except SimulatorError as exc:
            if failed is not None:
                failed.append({"phase": "intervals", "w": problem.w_of(problem.from_unit(u)), "error": str(exc)})
            return u_opt, y_opt

    plus, y_plus = map(list, zip(*[y_or_centre(u) for u in np.clip(u_opt + h * np.eye(q), 0.0, 1.0)]))
    minus, y_minus = map(list, zip(*[y_or_centre(u) for u in np.clip(u_opt - h * np.eye(q), 0.0, 1.0)]))
    plus, minus = np.array(plus), np.array(minus)
    step = np.diag(plus - minus)
    grads, j_opt = np.empty((n_redraws, q)), np.empty(n_redraws)
    for k, (fn, i_mod) in enumerate(bootstrap_objectives(problem, n_redraws, paired, reference)):
        J = lambda y: fn.evaluate(y[i_mod])[0]  # noqa: E731
        grads[k] = [(J(yp) - J(ym)) / step[i] if step[i] > 0 else 0.0  # both sides failed: no gradient
                    for i, (yp, ym) in enumerate(zip(y_plus, y_minus))]
        j_opt[k] = J(y_opt)
    J0 = j_of_spectra(problem, y_opt)[0]
    Jp = np.array([j_of_spectra(problem, y)[0] for y in y_plus])
    Jm = np.array([j_of_spectra(problem, y)[0] for y in y_minus])
    h_plus, h_minus = np.diag(plus) - u_opt, u_opt - np.diag(minus)
    with np.errstate(divide="ignore", invalid="ignore"):  # one-sided at a bound: no curvature there
        curvature = np.where((h_plus > 0) & (h_minus > 0), second_difference(J0, Jp, Jm, h_plus, h_minus), np.nan)
    return np.atleast_2d(np.cov(grads, rowvar=False)), curvature, float(np.std(j_opt, ddof=1))


def analyse(problem: Problem, ledger: Ledger, loop: LoopOutcome, surrogate: Normalized | None, config: Config,
            failed: list[dict[str, Any]] | None = None, retry_failed: bool = False,
            executor: Executor | None = None, phases: Phases | None = None,
            spectra_model: SpectraModel | None = None) -> Analysis:
    """w_opt, errors against w_ref, identifiability, intervals, trust and sensitivity (the first keys of
    ``result.json``: :meth:`Analysis.to_json`).

    :param loop: the loop's state at its end (:class:`~suspid.optimize.loop.LoopOutcome`, any optimiser):
        its best point, and the paper's loop before a refinement.
    :param surrogate: the surrogate fitted on the loop's points
        (:meth:`~suspid.optimize.loop.LoopOutcome.fitted_surrogate`; the verdict reads its model on the
        unit cube), None without one.
    :param failed: the points whose simulation failed during the design and EGO (listed in the result).
    :param executor: runs the simulations (entered; in this process without one).
    :param phases: shows each phase while it runs (:mod:`suspid.workflows.phases`; default: nowhere).
    :param spectra_model: the spectra with their Jacobian (a gradient-based optimiser's): the identifiability
        verdict then comes from the Fisher information at w_opt (:func:`fisher_verdict`) instead of the
        metamodel's Sobol indices, which a few points near the optimum do not support.
    """
    phases = phases or Phases()
    failed = list(failed or [])
    opts = config.identifiability
    names, lo, hi = problem.names, problem.bounds[:, 0], problem.bounds[:, 1]
    x_opt = np.asarray(loop.x_opt, float)
    u_opt = problem.to_unit(x_opt)
    phases.start(f"intervals ({2 * problem.q} simulations)")
    sigma_g, curvature, sigma_J = gradient_noise(problem, ledger, u_opt, opts.step, opts.n_redraws,
                                                 paired=opts.bootstrap == "paired", failed=failed,
                                                 retry_failed=retry_failed, executor=executor,
                                                 reference=opts.bootstrap_reference)
    rng = named_rng(config.seed, "identifiability")
    phases.start("identifiability")
    verdict = assess(names, u_opt, sigma_g, surrogate.cube if surrogate is not None else None, opts, rng, curvature)
    fisher = None
    if spectra_model is not None:
        try:
            verdict, fisher = fisher_verdict(problem, spectra_model, x_opt, verdict, config)
        except SimulatorError as exc:   # no Jacobian at w_opt: the metamodel's verdict stays, and says so
            fisher = {"kind": "sobol", "fisher_not_assessed": f"no Jacobian at w_opt: {exc}"}
    sd = np.sqrt(np.clip(np.diag(verdict.covariance), 0, None))
    trust = model_error(problem, ledger, u_opt, opts.step, opts.model_error, retry_failed, sd, executor, phases)
    phases.done()
    interval_unit = verdict.interval_unit
    correction = trust.get("correction")
    widen = opts.model_error.widen and trust["bias_bound"] is not None
    no_change = trust["report"].get("no_change") or {}
    if widen and no_change.get("status") == "done":
        u0 = problem.to_unit(np.array([problem.w0[n] for n in names], float))   # w0 not rejected: unchanged
        correction = reported_correction(no_change, u_opt, correction, u0, opts.model_error.no_change_report)
    u_est = u_opt if correction is None else np.clip(u_opt + correction, 0, 1)   # bias-corrected (linearised)
    if widen:
        half = bias_aware_half_width(sd, trust["bias_bound"], opts.n_sigmas)
        interval_unit = np.stack([np.clip(u_est - half, 0, 1), np.clip(u_est + half, 0, 1)], axis=1)
        imprecise(trust, names, verdict.identifiable, half, opts.n_sigmas * sd, opts.model_error.max_half_width)
        trust["report"].update({"bias_bound_percent": {n: float(100 * v) for n, v in zip(names, trust["bias_bound"])},
                                "half_width_percent": {n: float(100 * v) for n, v in zip(names, half)},
                                "max_half_width_percent": 100 * opts.model_error.max_half_width,
                                "transfer_error": opts.model_error.transfer_error})
    interval_si = problem.from_unit(interval_unit.T).T  # (q, 2): lower and upper ends, SI
    sampling_si = problem.from_unit(verdict.interval_unit.T).T
    units = {p.name: p.unit for p in declared_parameters(problem.simulator)}
    result = Analysis(
        name=config.name,
        parameters=names,
        units={n: units.get(n, "") for n in names},
        bounds={n: (float(a), float(b)) for n, a, b in zip(names, lo, hi)},
        w_opt={n: float(v) for n, v in zip(names, x_opt)},
        w_opt_normalized={n: float(v) for n, v in zip(names, u_opt)},
        identifiable={n: bool(v) for n, v in zip(names, verdict.identifiable)},
        non_identifiable_reasons={n: r for n, r in zip(names, verdict.reasons) if r},
        correlated_with={n: c for n, c in zip(names, verdict.correlated_with) if c},
        interval={n: (float(a), float(b)) for n, (a, b) in zip(names, interval_si)},
        interval_normalized={n: (float(a), float(b)) for n, (a, b) in zip(names, interval_unit)},
        interval_sampling={n: (float(a), float(b)) for n, (a, b) in zip(names, sampling_si)},
        trustworthy=trust["trustworthy"],
        untrustworthy_reasons=trust["reasons"],
        not_assessed_reasons=trust["not_assessed"],
        model_error=trust["report"],
        calibration=calibration_result(trust["report"]),
        interval_method=IntervalMethod(
            sigma_J=sigma_J, n_redraws=opts.n_redraws, step=opts.step, bootstrap=opts.bootstrap,
            bootstrap_reference=bool(opts.bootstrap_reference and problem.reference and config.noise.path is None),
            widened_by_model_error=bool(widen),
            n_sigmas=opts.n_sigmas, covariance_normalized=verdict.covariance.tolist()),
        sensitivity=Sensitivity(
            total_sobol={n: float(v) for n, v in zip(names, verdict.total_index)},
            first_sobol={n: float(v) for n, v in zip(names, verdict.first_index)},
            lengthscales=None if verdict.lengthscales is None
            else {n: float(v) for n, v in zip(names, np.ravel(verdict.lengthscales))}),
        J_max=float(loop.y_opt),
        objective=config.objective.plugin,
        surrogate=config.surrogate.plugin,
        simulator=config.simulator.plugin,
        seed=config.seed,
        failed_points=[FailedPoint(**f) for f in failed],
        identifiability_method=fisher,
    )
    if problem.w_ref is not None:
        w_ref = np.array([problem.w_ref[n] for n in names])
        result.w_ref = {n: float(v) for n, v in zip(names, w_ref)}
        result.w_ref_normalized = {n: float(v) for n, v in zip(names, problem.to_unit(w_ref))}
        result.errors_percent = errors_percent(problem, x_opt)
    if correction is not None:
        x_est = problem.from_unit(u_est)
        result.w_corrected = {n: float(v) for n, v in zip(names, x_est)}
        result.w_corrected_normalized = {n: float(v) for n, v in zip(names, u_est)}
        if problem.w_ref is not None:
            result.errors_percent_corrected = errors_percent(problem, x_est)
    if loop.n_refine:
        result.paper_loop = paper_loop(problem, loop)
    return result


def fisher_verdict(problem: Problem, spectra_model: SpectraModel, x_opt: np.ndarray, verdict: Verdict,
                   config: Config) -> tuple[Verdict, dict[str, Any]]:
    """The identifiability verdict from the Jacobian of the spectra at w_opt, for a gradient-based run.

    No influence and flat directions come from the Fisher information of the modelled spectra under the
    noise model B (:func:`suspid.method.jacobian.fisher_information`, [0, 1]^q units); *stuck on a bound*
    from the gradient of J on the spectra linearised at w_opt (J of y ± ∂y/∂u_k δ, no simulation). The
    intervals, correlations and Sobol indices of ``verdict`` are kept (the sandwich's).

    :returns: the verdict with its ``identifiable`` and ``reasons`` replaced, and the figures for result.json.
    """
    opts = config.identifiability
    names = problem.names
    widths = problem.bounds[:, 1] - problem.bounds[:, 0]
    y, jac = spectra_model.jacobian(np.asarray(x_opt, dtype=float))
    jac_u = np.asarray(jac, dtype=float) * widths                      # dB per unit of u in [0, 1]^q
    info = fisher_information(y, jac_u, problem.noise_model)
    fv = fisher_identifiability(info, names, opts.n_sigmas, opts.max_width)
    u_opt = problem.to_unit(np.asarray(x_opt, dtype=float))
    delta = 0.01
    reasons = [list(r) for r in fv.reasons]
    for k in range(problem.q):
        near_low, near_high = u_opt[k] <= opts.bound_margin, u_opt[k] >= 1 - opts.bound_margin
        if not (near_low or near_high):
            continue
        slope = (spectra_model.objective(y + delta * jac_u[..., k])
                 - spectra_model.objective(y - delta * jac_u[..., k])) / (2 * delta)
        if near_low and slope < 0:
            reasons[k].append("stuck on the lower bound (J of the linearised spectra still rises beyond it)")
        if near_high and slope > 0:
            reasons[k].append("stuck on the upper bound (J of the linearised spectra still rises beyond it)")
    identifiable = np.array([not r for r in reasons])
    figures = {"kind": "fisher", "n_sigmas": opts.n_sigmas, "max_width_percent": 100 * opts.max_width,
               "note": "Cramér-Rao spreads under B (no model error, an efficient estimator): lower bounds, not the "
                       "intervals, which are the sandwich's",
               "sd_alone_percent": {n: float(100 * v) for n, v in zip(names, fv.sd_alone)},
               "sd_percent": {n: (float(100 * v) if np.isfinite(v) else None) for n, v in zip(names, fv.sd)}}
    return replace(verdict, identifiable=identifiable, reasons=reasons), figures


def paper_loop(problem: Problem, loop: LoopOutcome) -> PaperLoop:
    """Where the paper's loop stood when it stopped, before the local refinement (``loop.refine``)."""
    names = problem.names
    n_loop = loop.n_evaluations - loop.n_refine
    best = int(np.argmax(loop.y[:n_loop]))
    x = np.asarray(loop.X[best], float)
    return PaperLoop(n_iterations=n_loop - loop.n_initial, n_simulator_calls=n_loop, J_max=float(loop.y[best]),
                     w_opt={n: float(v) for n, v in zip(names, x)},
                     w_opt_normalized={n: float(v) for n, v in zip(names, problem.to_unit(x))},
                     errors_percent=None if problem.w_ref is None else errors_percent(problem, x))


def errors_percent(problem: Problem, x_si: np.ndarray) -> dict[str, float]:
    """|w - w_ref| per component in % of its admissible interval; ``x_si (q,)`` SI."""
    lo, hi = problem.bounds[:, 0], problem.bounds[:, 1]
    return {n: float(100 * abs(a - problem.w_ref[n]) / (h - l)) for n, a, l, h in zip(problem.names, x_si, lo, hi)}


def local_sensitivity(problem: Problem, ledger: Ledger, u_opt: np.ndarray, h: float,
                      retry_failed: bool = False, executor: Executor | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Spectra at w_opt and their sensitivity, from the simulations of :func:`gradient_noise` (ledger cache).

    :returns: ``(y_opt (v, n_channels, n_freqs) dB, S (q, n_channels, n_freqs))`` with
        S_k = ∂ mean_i y_sim_i / ∂u_k (dB per unit of the normalised parameter),
        by central differences at w_opt ± h e_k (one-sided where a side fails or is clipped).
    """
    simulate_missing(problem, ledger, [u_opt, *np.clip(u_opt + h * np.eye(problem.q), 0, 1),
                                       *np.clip(u_opt - h * np.eye(problem.q), 0, 1)], executor, retry_failed)
    y_opt = cached_y_sim(problem, ledger, u_opt, retry_failed)
    mean_opt = y_opt.mean(axis=0)
    S = np.zeros((problem.q,) + mean_opt.shape)
    for k, e in enumerate(np.eye(problem.q)):
        sides = []
        for u in (np.clip(u_opt + h * e, 0, 1), np.clip(u_opt - h * e, 0, 1)):
            try:
                sides.append((u[k], cached_y_sim(problem, ledger, u, retry_failed).mean(axis=0)))
            except SimulatorError:
                sides.append((u_opt[k], mean_opt))
        (up, yp), (um, ym) = sides
        if up > um:
            S[k] = (yp - ym) / (up - um)
    return y_opt, S


def imprecise(trust: dict[str, Any], names: list[str], identifiable: np.ndarray, half: np.ndarray,
              sampling_half: np.ndarray, max_half_width: float) -> None:
    """Flag, in ``trust`` (from :func:`model_error`), the identifiable components whose bias-aware half-width
    ``half`` ``(q,)`` exceeds ``max_half_width`` (fractions of the admissible interval).

    The checks' bound on the bias, added to the sampling spread, says how far the reported value may be
    from the vehicle's: beyond ``max_half_width`` the value is not a finding, even when no single check
    flags it (each source small, the sum large; or a sampling spread that model error widens further).
    """
    for k, n in enumerate(names):
        if identifiable[k] and half[k] > max_half_width:
            trust["trustworthy"][n] = False
            trust.get("not_assessed", {}).pop(n, None)
            trust["reasons"].setdefault(n, []).append(
                f"too uncertain under model error: its bias-aware interval is ± {100 * half[k]:.1f} % of the "
                f"admissible one (sampling ± {100 * sampling_half[k]:.1f} %, model-error bound on the bias "
                f"{100 * trust['bias_bound'][k]:.1f} %), wider than ± {100 * max_half_width:.0f} %")


def biased(bias: np.ndarray, se: np.ndarray, max_bias: float) -> np.ndarray:
    """``(q,)`` bool: the reference-date self-check's mean shift ``bias`` ``(q,)`` is a bias (more than 2 standard
    errors ``se`` of the splits' mean from 0) and larger than ``max_bias`` (all in fractions of the interval).

    The size is judged on the estimate itself: a shift of 4.7 ± 1.2 % is a bias of about 4.7 %, over a
    3 % tolerance, even though its lower 2-sigma bound (2.3 %) is not.
    """
    bias = np.abs(np.asarray(bias, dtype=float))
    return (bias > 2 * np.asarray(se, dtype=float)) & (bias > max_bias)


def no_change_check(problem: Problem, ledger: Ledger, u_opt: np.ndarray, options: ModelErrorOptions,
                    retry_failed: bool, executor: Executor | None, correction: np.ndarray | None = None
                    ) -> tuple[NoChange | None, dict[str, Any]]:
    """The test of "nothing changed" on the measurement date (:mod:`suspid.workflows.no_change`), against where
    w_opt lies when nothing changed: w0 less the checks' ``correction`` ``(q,)`` (normalised; w0 itself without
    one). The reported estimate is w_opt + correction, so with w = w0 the model's maximiser sits at
    w0 − correction, not at w0 (the likelihood's model-form bias made J(w_opt) exceed J(w0) at w_ref = w0). One
    simulation there, on the measurement date's segments (cached in the ledger). Where a correction moves the
    null and w0's spectra are in the ledger already, the test against w0 itself is reported too
    (``against_w0``, no simulation).

    :returns: the test (None where it did not run) and its report.
    """
    if not options.no_change:
        return None, {"status": "disabled (identifiability.model_error.no_change: false)"}
    u0 = problem.to_unit(np.array([problem.w0[n] for n in problem.names], float))
    shift = np.zeros(problem.q) if correction is None else np.asarray(correction, float)
    u_null = np.clip(u0 - shift, 0, 1)
    n_sims = 0 if ledger.get_array(_y_sim_key(problem, u_null)[0] + ":y") is not None else 1
    where = "w0 − the correction" if shift.any() else "w0"
    try:
        y_null = cached_y_sim(problem, ledger, u_null, retry_failed, executor)
        y_opt = cached_y_sim(problem, ledger, np.asarray(u_opt, float), retry_failed, executor)
    except SimulatorError as exc:
        return None, {"status": f"not run: the simulation at {where} failed ({exc})", "n_simulations": n_sims}
    ident = problem.config.identifiability

    def test_against(y: np.ndarray) -> NoChange:
        return no_change_test(problem, y_opt, y, ident.n_redraws, ident.n_sigmas, reference=ident.bootstrap_reference)

    test = test_against(y_null)
    test.null = where
    out = test.to_dict(n_sims)
    if shift.any():
        out |= {"null": "w0 moved by the bias the checks correct (w0 − correction)",
                "null_shift_percent": {n: float(-100 * c) for n, c in zip(problem.names, shift)}}
        y0 = ledger.get_array(_y_sim_key(problem, u0)[0] + ":y")
        if y0 is not None:
            plain = test_against(y0).to_dict(0)
            out["against_w0"] = {k: plain[k] for k in ("delta_J", "sd_delta_J", "z", "rejected")}
    return test, out


def model_error(problem: Problem, ledger: Ledger, u_opt: np.ndarray, h: float, options: ModelErrorOptions,
                retry_failed: bool = False, sd: np.ndarray | None = None,
                executor: Executor | None = None, phases: Phases | None = None, *,
                apply_no_change_test: bool = True, model_parameters_check: bool = True) -> dict[str, Any]:
    """Trust under model error: the reference-date self-check, the adequacy test at w_opt, the data groups and
    the model parameters calibrated at the reference date, each re-identifying w by simulation (``method: full``).

    The model parameters θ (:func:`suspid.workflows.linearised.model_parameters`) are calibrated at the
    reference date as the linearised checks do (:func:`suspid.workflows.linearised.calibrate_at_reference`);
    the self-check then checks the calibrated model. A component is **not trustworthy under model error** when

    - (``correct: false`` only) the self-check (:func:`suspid.workflows.reference.self_check`) moves it by more
      than ``max_bias`` of its admissible interval at the reference date, where the truth is w0, and
      by more than 2 standard errors of the splits' mean (:func:`biased`); or
    - more than ``adequacy.max_share`` of its information (S_k² / Var B, weighted by α) lies in
      channel bands where the model at w_opt does not reproduce the measurements after B's mean
      (:mod:`suspid.method.adequacy`); or
    - the data groups that inform it (channel directions, frequency halves) give estimates more
      than ``adequacy.max_spread`` apart, and further apart than 2√2 sampling standard deviations
      ``sd`` (:mod:`suspid.workflows.adequacy`); or
    - (unless corrected after a calibration) a model parameter moves it by more than ``nuisance.max_shift`` at
      an end of its range (:mod:`suspid.workflows.nuisance`).

    Each check gives its source's shift of w_opt, and :func:`suspid.workflows.trust.combine_sources`, the rule
    the linearised checks use, combines them into the bias bound (and the correction by the calibrated model's
    shift): the two methods differ only in how each shift is obtained.

    The no-change test (:mod:`suspid.workflows.no_change`, ``no_change``) then asks whether the measurement
    date rejects w = w0; where it does not, the bound grows until every interval holds w0, and a component
    w0 lies further from than ``max_half_width`` is not trustworthy (the data do not tell it from w0).

    A component no check flags is trustworthy only when the checks of :data:`REQUIRED_CHECKS` all ran,
    otherwise *not assessed* (:func:`suspid.workflows.trust.trust_states`); ``report["checks"]`` says which ran and why not.

    :param sd: ``(q,)`` sampling standard deviations of w_opt in [0, 1] (the sandwich's).
    :param phases: shows each check while it runs (default: nowhere).
    :param model_parameters_check: calibrate and check the model parameters (off where the linearised checks
        call this for the adequacy bands alone).
    :returns: ``{"trustworthy": name -> True | False | None (not assessed), "reasons": name -> [str],
        "not_assessed": name -> [str] (the checks that did not run), "bias_bound": (q,) or None,
        that bound in [0, 1] (:func:`suspid.method.identifiability.bias_aware_half_width` widens the
        intervals by it), "correction": (q,) or None, the shift added to u_opt, "report": the JSON-able
        details for result.json}``.
    """
    names = problem.names
    q = problem.q
    phases = phases or Phases()
    reasons: list[list[str]] = [[] for _ in range(q)]
    if options.run == "never" or (options.run == "measured" and problem.config.data.source != "measured"):
        why = (f"not run (identifiability.model_error.run: {options.run}, data.source: "
               f"{problem.config.data.source}; 'always' runs them)")
        checks = {c: why for c in CHECK_LABELS}
        return {**trust_states(names, reasons, checks), "bias_bound": None,
                "report": {"status": why, "checks": checks_report(checks)}}
    if options.method == "linearised":  # the checks by linearisation, within budget (suspid.workflows.linearised)
        phases.start("model error (linearised)")
        return linearised_model_error(problem, ledger, u_opt, h, options, retry_failed, sd, executor, model_error)
    report: dict[str, Any] = {"max_bias_percent": 100 * options.max_bias, "method": "full"}
    phases.start("no-change test (1 simulation)")
    test, report["no_change"] = no_change_check(problem, ledger, u_opt, options, retry_failed, executor)
    budget: dict[str, Any] = {"no_change": int(report["no_change"].get("n_simulations", 0))}
    checks: dict[str, str] = {}
    sources, ran = BiasSources.none(q), False
    correct = options.correct
    theta = model_parameters(problem, options) if model_parameters_check else None
    cal = None
    if theta is not None:
        phases.start(f"calibration of {len(theta.names)} model parameters at the reference date")
        cal = calibrate_at_reference(problem, ledger, theta, options, executor)
        report["calibration"] = dict(cal.report)
        budget["calibration"] = cal.n_simulations
    extra = theta.w(cal.t_hat) if cal is not None and cal.done and np.any(cal.t_hat != 0) else None
    sc_opt = options.self_check
    if not sc_opt.enabled:
        report["self_check"] = {"status": "disabled (identifiability.model_error.self_check.enabled: false)"}
    else:
        phases.start(f"self-check ({sc_opt.n_splits} splits)")
        check = self_check(problem, ledger, sc_opt, log=phases.status, executor=executor, extra=extra)
        if check is None:
            report["self_check"] = {"status": f"not run: {self_check_missing(problem)}"}
        else:
            bias = np.abs(check.bias)
            sources.self_check, ran = np.asarray(check.bias, float), True
            budget["self_check"] = check.n_evaluations
            n_splits = check.shifts.shape[0]
            se = check.scatter / np.sqrt(n_splits)
            sources.self_check_se = se
            excess = np.maximum(bias - 2 * se, 0.0)  # what the scatter of the splits does not explain
            report["self_check"] = {"status": "done", **check.to_dict(names), "calibrated_model": extra is not None,
                                    "standard_error_percent": {n: float(100 * v) for n, v in zip(names, se)},
                                    "excess_bias_percent": {n: float(100 * v) for n, v in zip(names, excess)}}
            # corrected: the self-check's bias widens the interval (combine_sources) instead of flagging
            flagged = np.zeros(q, bool) if correct else biased(bias, se, options.max_bias)
            for k in range(q):
                if flagged[k]:
                    reasons[k].append(
                        f"reference-date self-check: w_opt moves by {100 * check.bias[k]:+.1f} ± "
                        f"{100 * se[k]:.1f} % of the interval where the truth is w0 (B fitted on half the "
                        f"segments, w identified on the other half, {n_splits} splits; threshold "
                        f"{100 * options.max_bias:.0f} %, the bias beyond 2 standard errors)")
    checks["self_check"] = report["self_check"]["status"]
    ad_opt = options.adequacy
    if not ad_opt.enabled:
        report["adequacy"] = {"status": "disabled (identifiability.model_error.adequacy.enabled: false)"}
        checks["groups"] = "not run: the adequacy test is disabled"
    else:
        phases.start(f"adequacy ({problem.q} simulations)")
        y_opt, S = local_sensitivity(problem, ledger, u_opt, h, retry_failed, executor)
        bands = frequency_bands(problem.freqs, ad_opt.bands_per_octave)
        res = band_residuals(problem.y_mes, y_opt, problem.noise_model, bands, ad_opt.z_threshold, ad_opt.min_db,
                             speeds=problem.speeds)
        share, info = information_share(S, problem.noise_model.variance_, problem.weights, res)
        f = problem.freqs
        labels = [f"{f[idx[0]]:.3g}-{f[idx[-1]]:.3g} Hz" for idx in bands]
        flagged = [{"channel": problem.channels[c], "band": labels[j], "residual_db": float(res.mean_db[c, j]),
                    "z": float(res.z[c, j])} for c, j in zip(*np.nonzero(res.inadequate))]
        report["adequacy"] = {
            "status": "done", "bands_per_octave": ad_opt.bands_per_octave, "z_threshold": ad_opt.z_threshold,
            "min_db": ad_opt.min_db, "max_share": ad_opt.max_share,
            "n_bands": int(res.inadequate.size), "n_inadequate": int(res.inadequate.sum()),
            "inadequate_bands": flagged,
            "inadequate_share": {n: float(v) for n, v in zip(names, share)},
            "residual_rms_db": {c: float(np.sqrt(np.mean(res.mean_db[i] ** 2)))
                                for i, c in enumerate(problem.channels)}}
        for k in range(q):
            if share[k] > ad_opt.max_share:
                cells = sorted(zip(*np.nonzero(res.inadequate)), key=lambda cj: -info[k][cj])[:3]
                where = ", ".join(f"{problem.channels[c]} {labels[j]} ({res.mean_db[c, j]:+.1f} dB)"
                                  for c, j in cells)
                reasons[k].append(f"model inadequate where it is read: {100 * share[k]:.0f} % of its information "
                                  f"lies in bands the model does not reproduce at w_opt ({where})")
        if not ad_opt.groups:
            checks["groups"] = "disabled (identifiability.model_error.adequacy.groups: false)"
        else:
            checks["groups"] = "done"
            phases.start("data groups")
            ge = group_estimates(problem, u_opt, S, ad_opt.min_group_share, ad_opt.group_evaluations,
                                 options.self_check.initial_step, ledger, executor)
            informed = np.isfinite(ge.u)
            spread = np.array([np.ptp(ge.u[informed[:, k], k]) if informed[:, k].sum() >= 2 else 0.0
                               for k in range(q)])
            sd_ = np.zeros(q) if sd is None else np.asarray(sd, float)
            report["adequacy"]["groups"] = {
                "min_group_share": ad_opt.min_group_share, "max_spread_percent": 100 * ad_opt.max_spread,
                "n_simulations": ge.n_simulations,
                "estimates_percent": {g.name: {n: (None if not np.isfinite(ge.u[i, k]) else float(100 * ge.u[i, k]))
                                               for k, n in enumerate(names)} for i, g in enumerate(ge.groups)},
                "information_share": {g.name: {n: float(ge.share[i, k]) for k, n in enumerate(names)}
                                      for i, g in enumerate(ge.groups)},
                "spread_percent": {n: float(100 * v) for n, v in zip(names, spread)}}
            sources.groups_half, ran = spread / 2, True
            budget["data_groups"] = ge.n_simulations
            for k in range(q):
                if spread[k] > ad_opt.max_spread and spread[k] > 2 * np.sqrt(2) * sd_[k]:
                    parts = ", ".join(f"{g.name} {100 * ge.u[i, k]:.0f} %" for i, g in enumerate(ge.groups)
                                      if informed[i, k])
                    reasons[k].append(f"the parts of the data disagree: re-identified on each data group it is "
                                      f"read from, it lies at {parts} of its interval (spread "
                                      f"{100 * spread[k]:.0f} %, threshold {100 * ad_opt.max_spread:.0f} %): "
                                      f"the model's sensitivity to it differs from the vehicle's")
    checks["adequacy"] = report["adequacy"]["status"]
    checks["nuisance"] = _model_parameters(problem, ledger, u_opt, options, theta, cal, sources, report, budget,
                                           reasons, phases, executor)
    ran = ran or checks["nuisance"] == "done"
    bound, correction = combine_sources(np.zeros(q) if sd is None else sd, sources, correct,
                                        problem.config.identifiability.n_sigmas, sc_opt.correct,
                                        options.transfer_error) if ran else (None, None)
    if correction is not None:
        report["correction"] = correction_report(problem, u_opt, correction, sources, sc_opt.correct,
                                                 " (re-identified)")
    if ran:
        transfer = transfer_term(sources, options.transfer_error, correct)
        report["bias_sources_percent"] = {
            n: {"self_check": float(100 * a), "groups_half_spread": float(100 * g),
                "model_parameters_shift": float(100 * m), "model_parameters_spread": float(100 * v),
                "model_parameters_transfer": float(100 * t)}
            for n, a, g, m, v, t in zip(names, sources.self_check, sources.groups_half, sources.model_shift,
                                        sources.model_spread, transfer)}
    budget["total"] = int(sum(v for v in budget.values()))
    report["budget"] = budget
    if apply_no_change_test:   # (the linearised checks apply it to their own estimate and bound)
        u0 = problem.to_unit(np.array([problem.w0[n] for n in names], float))
        u_est = np.asarray(u_opt, float) if correction is None else np.clip(np.asarray(u_opt, float) + correction, 0, 1)
        by_name = {n: r for n, r in zip(names, reasons)}
        bound = apply_no_change(test, names, sd, bound, u_est - u0,
                                problem.config.identifiability.n_sigmas, options.max_half_width, by_name)
    checks["no_change"] = report["no_change"]["status"]
    report["checks"] = checks_report(checks)
    return {**trust_states(names, reasons, checks), "bias_bound": bound, "report": report, "no_change": test,
            "correction": correction}


def _model_parameters(problem: Problem, ledger: Ledger, u_opt: np.ndarray, options: ModelErrorOptions, theta: Any,
                      cal: Any, sources: BiasSources, report: dict[str, Any], budget: dict[str, Any],
                      reasons: list[list[str]], phases: Phases, executor: Executor | None) -> str:
    """The full checks' model-parameter check (:func:`suspid.workflows.nuisance.model_parameter_check`): its
    report, its sources (the shift at the calibrated θ̂, the spread of what remains uncertain) and its flags, on
    the linearised checks' rule (a component whose shift at an end of a θ's range exceeds ``nuisance.max_shift``
    is flagged, unless the calibrated shift is corrected). :returns: the check's status."""
    names, q = problem.names, problem.q
    if theta is None:
        return "not run: the linearised checks propagate the model parameters"
    if not theta.names:
        report["nuisance"] = {"status": "not run: no model parameter"}
        return report["nuisance"]["status"]
    if not problem.reference or not problem.reference_segments:
        report["nuisance"] = {"status": "not run: the reference date's data are not part of this run "
                                        "(give noise.reference)"}
        return report["nuisance"]["status"]
    p = len(theta.names)
    phases.start(f"model parameters ({p}: {2 * p + 1} re-identifications)")
    mp = model_parameter_check(problem, ledger, u_opt, theta, cal, options, log=phases.status, executor=executor)
    budget["nuisance"] = mp.n_simulations
    sources.model_shift, sources.model_spread = mp.shift, mp.spread
    largest, rows = mp.largest()
    pinned = cal.pinned if cal.done else np.zeros(p, bool)
    report["nuisance"] = {
        "status": "done", "linearised": False, "n_simulations": mp.n_simulations,
        "max_shift_percent": 100 * options.nuisance.max_shift,
        "parameters": {n: {"range": [mp.values[2 * j][1], mp.values[2 * j + 1][1]], "calibrated": bool(pinned[j])}
                       for j, n in enumerate(theta.names)},
        "shifts_percent": [{"parameter": pn, "value": v, **{n: float(100 * s) for n, s in zip(names, row)}}
                           for (pn, v), row in zip(mp.values, mp.shifts)],
        "largest_shift_percent": {n: float(100 * v) for n, v in zip(names, largest)},
        "sensitivity_percent_per_range": {n: {tn: float(100 * mp.sensitivity[k, j]) for j, tn in enumerate(theta.names)}
                                          for k, n in enumerate(names)},
        "shift_percent": {n: float(100 * v) for n, v in zip(names, mp.shift)},
        "spread_percent": {n: float(100 * v) for n, v in zip(names, mp.spread)},
        "search_noise_percent": {n: float(100 * v) for n, v in zip(names, mp.search_noise)},
        "w_opt_calibrated": {n: float(v) for n, v in zip(names, problem.from_unit(np.clip(u_opt + mp.shift, 0, 1)))}}
    if options.correct and cal.done:   # corrected: the posterior's spread widens the interval instead
        return "done"
    for k in range(q):
        if largest[k] > options.nuisance.max_shift:
            name, value = mp.values[rows[k]]
            j = theta.names.index(name)
            what = "its calibrated interval" if pinned[j] else "its assumed range"
            reasons[k].append(
                f"rests on a model parameter: with {name} = {value:g} (end of {what}) it is identified "
                f"{100 * mp.shifts[rows[k], k]:+.1f} % of its interval away (threshold "
                f"{100 * options.nuisance.max_shift:.0f} %)")
    return "done"
