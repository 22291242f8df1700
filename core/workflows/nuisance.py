"""How much of w_opt rests on the model's other parameters, by re-identification (the full checks; beyond the paper).

The reference-date self-check (:mod:`suspid.workflows.reference`) and the data
groups (:mod:`suspid.workflows.adequacy`) see model-form error where it shows
in the data. A model whose sensitivity to an identified parameter is wrong in
the same way in every part of the data shows nothing: a damper modelled
without the series stiffness of its bushes feels a change of its rate more
than the vehicle does, on every channel and in every band; every group then
agrees on the same wrong value, and the residuals at w_opt are small.

What is known is which of the model's *other* parameters θ are uncertain (the
yaw damper's series stiffness, the creep coefficients' fraction of Kalker's
theory, the equivalent conicity, ...; :func:`suspid.workflows.linearised.model_parameters`)
and that at the reference date w = w0 is known, so that θ can be calibrated there
(:mod:`suspid.method.calibration`, the same Gauss-Newton as the linearised
checks'). This module measures, by simulation, what θ does to w_opt:

1. for a value of θ the reference date is simulated at w0 with it and the noise
   model B fitted again (eq. 3): that model explains the reference date as well
   as the nominal one, since B absorbs the difference there;
2. w is identified again on the measurement date with that model and its B, by
   a bounded Nelder-Mead search started at w_opt;
3. the **shift** is that estimate minus the same search with the nominal model
   (same noise draws, so that the Monte Carlo of Y_mod cancels).

Shifts are measured at each end of each θ's range (its calibrated interval where
the reference date pins it down, its assumed range otherwise) and at the
calibrated θ̂ (the middle of the ranges without a calibration). The ends give
the sensitivity G = du_opt/dt (:func:`sensitivity_of_ends`), hence the spread √diag(G Σ_t Gᵀ) that
what remains uncertain of θ gives w_opt (Σ_t the calibration's posterior, with
its correlations), and the searches' own scatter, which adds to it; the shift at θ̂ is a known bias, corrected. Both go to the
combination rule the linearised checks use (:func:`suspid.workflows.trust.combine_sources`).
The searches cost about ``(2 p + 2) · 20 q`` simulations of the measurement date and one of the reference
date per value of θ.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from suspid.infra.ledger import Ledger, stable_hash
from suspid.infra.seeds import rng as named_rng
from suspid.interfaces import Executor
from suspid.method.calibration import UNIFORM_SD
from suspid.method.identifiability import ModelErrorOptions
from suspid.method.noise import fit_noise_model
from suspid.method.objective import ObjectiveFunction
from suspid.workflows.linearised import Calibration, ModelParameters
from suspid.workflows.problem import Problem, segment_speeds, segments_digest
from suspid.workflows.reference import SearchObjective, local_search
from suspid.workflows.tasks import SpectraTask, run_one
from suspid.workflows.trust import model_spread
from suspid.elements import declared_parameters

__all__ = ["ModelParameterCheck", "model_parameter_check", "reidentify", "sensitivity_of_ends"]


def reidentify(problem: Problem, ledger: Ledger, u_opt: np.ndarray, points: list[dict[str, float]],
               initial_step: float, max_evaluations: int, log: Callable[[str], None] = lambda s: None,
               executor: Executor | None = None) -> tuple[np.ndarray, int]:
    """Steps 1-3 of the module docstring for each of ``points`` (SI values of model parameters):
    ``(shifts (len(points), q), simulations)``; a point at the nominal model has shift 0 without a search.

    Cached in the run ledger (keyed by the data, w_opt, the points and the options), so that a resumed run does
    not simulate it again. Simulations run on ``executor``.
    """
    ref, ref_segments, config, q = problem.reference, problem.reference_segments, problem.config, problem.q
    ref_digest, u_list = segments_digest(ref_segments), np.asarray(u_opt).tolist()
    key = stable_hash("model-parameter-shifts", problem.simulator_identity, problem.data_identity, ref_digest, u_list,
                      points, initial_step, max_evaluations)   # the data identity covers B's inputs, α, J, the seed
    legacy = stable_hash("model-parameter-shifts", problem.simulator_identity, problem.legacy_identity, ref_digest,
                         u_list, points, config.noise.model_dump(mode="json"), config.objective.plugin,
                         config.objective.options, problem.weights.tolist(), config.spectra.model_dump(), config.seed,
                         initial_step, max_evaluations)   # ledgers written before the input identities
    cached = ledger.get_array_migrating(key, [legacy])
    if cached is not None:
        return cached[:, :q], int(cached[0, q]) if len(cached) else 0
    noise_options = config.noise.model_dump(exclude={"path", "reference"})
    ref_task = SpectraTask.of(problem.simulator, ref_segments, config.spectra)
    task = SpectraTask.of(problem.simulator, problem.segments, config.spectra)
    n_sims = 0

    def identify(extra: dict[str, float], y_sim0: np.ndarray) -> np.ndarray:
        """w re-identified from u_opt with the model at ``extra`` and its own B."""
        nonlocal n_sims
        model = fit_noise_model(ref["y_mes0"], y_sim0, noise_options, freqs=problem.freqs, channels=problem.channels,
                                speeds=segment_speeds(ref_segments))
        fn = ObjectiveFunction.from_noise_model(problem.objective, problem.y_mes, problem.freqs, model,
                                                named_rng(config.seed, "nuisance"),  # the same draws each time
                                                weights=problem.weights, channels=problem.channels,
                                                speeds=problem.speeds)
        neg_j = SearchObjective(problem, task, fn, executor, extra)
        found = local_search(neg_j, np.asarray(u_opt, float), initial_step, max_evaluations)
        n_sims += neg_j.n_simulations
        return found

    nominal = {p.name: p.nominal for p in declared_parameters(problem.simulator)}
    base = identify({}, ref["y_sim0"])
    shifts = np.zeros((len(points), q))
    for i, extra in enumerate(points):
        if all(v == nominal.get(n) for n, v in extra.items()):  # the nominal model again: the same search
            continue
        y_sim0 = run_one(executor, ref_task, problem.w0 | extra)
        n_sims += 1
        shifts[i] = identify(extra, y_sim0) - base
        log(", ".join(f"{n} = {v:g}" for n, v in extra.items()) + ": w_opt moves by "
            + ", ".join(f"{n} {100 * d:+.1f} %" for n, d in zip(problem.names, shifts[i])))
    ledger.put_array(key, np.column_stack([shifts, np.full(len(points), n_sims)]))
    return shifts, n_sims


@dataclass
class ModelParameterCheck:
    """The model parameters' effect on w_opt, each shift by a re-identification (fractions of the interval).

    :ivar values: ``(name, SI value)`` of each end row of ``shifts``.
    :ivar shifts: ``(2 p, q)`` the shift with one parameter at an end of its range, the others nominal.
    :ivar sensitivity: ``(q, p)`` G, the secant of each parameter's two ends per unit of t.
    :ivar shift: ``(q,)`` the shift at the calibrated θ̂ (the middle of the ranges without a calibration).
    :ivar spread: ``(q,)`` √diag(G Σ_t Gᵀ).
    :ivar lo_t, hi_t: ``(p,)`` the ends, in t.
    :ivar search_noise: ``(q,)`` the re-identifications' scatter about G (:func:`sensitivity_of_ends`), in ``spread``.
    """

    values: list[tuple[str, float]]
    shifts: np.ndarray
    sensitivity: np.ndarray
    shift: np.ndarray
    spread: np.ndarray
    lo_t: np.ndarray
    hi_t: np.ndarray
    n_simulations: int
    search_noise: np.ndarray

    def largest(self) -> tuple[np.ndarray, np.ndarray]:
        """``(q,)`` largest |shift| over the ends, and the row that gives it."""
        rows = np.argmax(np.abs(self.shifts), axis=0)
        return np.abs(self.shifts[rows, np.arange(self.shifts.shape[1])]), rows


def model_parameter_check(problem: Problem, ledger: Ledger, u_opt: np.ndarray, theta: ModelParameters,
                          cal: Calibration, options: ModelErrorOptions, log: Callable[[str], None] = lambda s: None,
                          executor: Executor | None = None) -> ModelParameterCheck:
    """The shifts of the module docstring: the ends of each θ's range (its calibrated interval ± ``n_sigmas``
    standard deviations where pinned down, its assumed range otherwise) and θ̂, each re-identified."""
    p = len(theta.names)
    n_c = options.calibration.n_sigmas
    sd_t = np.sqrt(np.clip(np.diag(cal.covariance_t), 0, None))
    pinned = cal.pinned if cal.done else np.zeros(p, bool)
    lo_t = np.where(pinned, cal.t_hat - n_c * sd_t, theta.t_of(theta.lower))
    hi_t = np.where(pinned, cal.t_hat + n_c * sd_t, theta.t_of(theta.upper))
    values, points = [], []
    for j, name in enumerate(theta.names):
        for t_end, si_end in ((lo_t[j], theta.lower[j]), (hi_t[j], theta.upper[j])):
            v = float(theta.theta_of(np.eye(p)[j] * t_end)[j]) if pinned[j] else float(si_end)
            values.append((name, v))
            points.append({name: v})
    # what remains uncertain: the calibration's posterior, or each θ uniform over its assumed range
    if cal.done:
        mean_t, cov = cal.t_hat, cal.covariance_t
    else:
        mean_t, cov = 0.5 * (theta.t_of(theta.lower) + theta.t_of(theta.upper)), np.eye(p) * UNIFORM_SD ** 2
    points.append(theta.w(mean_t))
    step, n_eval = options.self_check.initial_step, options.nuisance.max_evaluations or 20 * problem.q
    shifts, n_sims = reidentify(problem, ledger, u_opt, points, step, n_eval, log, executor)
    ends = shifts[:-1]
    G, noise = sensitivity_of_ends(lo_t, hi_t, ends[0::2], ends[1::2])
    # the searches' own scatter is a random error of the calibrated shift too: it adds to the spread
    spread = np.hypot(model_spread(G, cov), noise)
    return ModelParameterCheck(values, ends, G, shifts[-1], spread, lo_t, hi_t, n_sims, noise)


def sensitivity_of_ends(lo_t: np.ndarray, hi_t: np.ndarray, s_lo: np.ndarray, s_hi: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """G = du_opt/dt ``(q, p)`` from the shifts at the ends of each parameter's range, and the re-identifications'
    scatter about it ``(q,)``.

    The shift is 0 at t = 0 (the nominal model) by definition, so each parameter's G is the least-squares slope
    through the origin of its two ends (``lo_t``, ``hi_t`` ``(p,)``; shifts ``s_lo``, ``s_hi`` ``(p, q)``). A
    linear response puts both ends on that line; what they miss it by (both ends moving the same way, or an end
    at the nominal value moving) is the searches' scatter (a Nelder-Mead re-identification stops within its
    tolerance and evaluation budget, with B fitted again) or a curvature: pooled over the parameters (one degree
    of freedom each where both ends differ from the nominal), it is the standard deviation of one shift.
    """
    lo_t, hi_t = np.asarray(lo_t, float), np.asarray(hi_t, float)
    s_lo, s_hi = np.asarray(s_lo, float), np.asarray(s_hi, float)
    ss = lo_t ** 2 + hi_t ** 2                                            # (p,)
    with np.errstate(divide="ignore", invalid="ignore"):
        G = np.where(ss[:, None] > 0, (lo_t[:, None] * s_lo + hi_t[:, None] * s_hi) / ss[:, None], 0.0)  # (p, q)
    resid = (s_lo - lo_t[:, None] * G) ** 2 + (s_hi - hi_t[:, None] * G) ** 2
    dof = int(np.sum((lo_t != 0) & (hi_t != 0)))
    noise = np.sqrt(resid.sum(axis=0) / dof) if dof else np.zeros(s_lo.shape[1])
    return G.T, noise
