"""What the identified w_opt is worth: errors, identifiability, intervals, sensitivity.

:func:`analyse` turns the EGO result into the JSON-able dict of
``result.json``: w_opt in SI and normalised units, the errors against a known
w_ref (numerical experiment), the identifiability verdict and the intervals of
:mod:`suspid.method.identifiability`, whose sandwich covariance needs the noise
in the gradient of J at w_opt (:func:`gradient_noise`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from suspid.config import Config
from suspid.errors import SimulatorError
from suspid.infra.ledger import Evaluation, Ledger, stable_hash
from suspid.infra.seeds import rng as named_rng
from suspid.method.identifiability import assess
from suspid.optimize.ego import EGOResult
from suspid.workflows.evaluation import j_of_spectra
from suspid.workflows.problem import Problem, _cached_spectra, simulate_spectra


def gradient_noise(problem: Problem, ledger: Ledger, u_opt: np.ndarray, h: float, n_redraws: int,
                   paired: bool = True, failed: list[dict[str, Any]] | None = None,
                   retry_failed: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
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
    maximum. The 2q spectra are simulated once (cached in the ledger).

    The same 2q + 1 spectra with the run's own data give the curvature of J
    along each axis, d²J/du_k² (central second differences).

    A ±h point whose simulation fails is replaced by w_opt itself (a one-sided
    difference along that axis, no curvature there) and appended to ``failed``.

    :returns: ``(Σ_g (q, q), curvature (q,), σ_J)``, σ_J the scatter of J(w_opt) itself.
    """
    config = problem.config
    q = problem.q

    def y_sim_at(u: np.ndarray) -> np.ndarray:
        """Spectra at ``u``, cached in the ledger; a failure is cached too, and raised again."""
        w = problem.w_of(problem.from_unit(u))
        key = stable_hash("y_sim", problem.simulator_identity, w, problem.segments_digest)
        known = ledger.get(key)
        if known is not None and not known.ok and not retry_failed:
            raise SimulatorError(known.error)
        try:
            return _cached_spectra(ledger, key, lambda: simulate_spectra(problem.simulator, w, problem.segments,
                                                                          config.spectra))[0]
        except SimulatorError as exc:
            ledger.put(Evaluation(key, w, None, None, status="failed", error=str(exc)))
            raise

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
    rng = named_rng(config.seed, "noise-redraws")
    v = len(problem.segments)
    grads, j_opt = np.empty((n_redraws, q)), np.empty(n_redraws)
    for k in range(n_redraws):
        b = problem.noise_model.sample(v, rng)
        i_mes = rng.integers(0, v, v)
        i_mod = i_mes if paired else rng.integers(0, v, v)
        y_mes = problem.y_mes[i_mes]
        J = lambda y: j_of_spectra(problem, y[i_mod], b, y_mes)[0]  # noqa: E731
        grads[k] = [(J(yp) - J(ym)) / step[i] if step[i] > 0 else 0.0  # both sides failed: no gradient
                    for i, (yp, ym) in enumerate(zip(y_plus, y_minus))]
        j_opt[k] = J(y_opt)
    J0 = j_of_spectra(problem, y_opt)[0]
    Jp = np.array([j_of_spectra(problem, y)[0] for y in y_plus])
    Jm = np.array([j_of_spectra(problem, y)[0] for y in y_minus])
    h_plus, h_minus = np.diag(plus) - u_opt, u_opt - np.diag(minus)
    with np.errstate(divide="ignore", invalid="ignore"):  # one-sided at a bound: no curvature there
        curvature = np.where((h_plus > 0) & (h_minus > 0),
                             2 * (h_minus * Jp + h_plus * Jm - (h_plus + h_minus) * J0)
                             / (h_plus * h_minus * (h_plus + h_minus)), np.nan)
    return np.atleast_2d(np.cov(grads, rowvar=False)), curvature, float(np.std(j_opt, ddof=1))


def analyse(problem: Problem, ledger: Ledger, ego: EGOResult, config: Config,
            failed: list[dict[str, Any]] | None = None, retry_failed: bool = False) -> dict[str, Any]:
    """w_opt, errors against w_ref, identifiability, intervals and sensitivity, as a JSON-able dict.

    :param failed: the points whose simulation failed during the design and EGO (listed in the result).
    """
    failed = list(failed or [])
    opts = config.identifiability
    names, lo, hi = problem.names, problem.bounds[:, 0], problem.bounds[:, 1]
    x_opt = np.asarray(ego.x_opt, float)
    u_opt = problem.to_unit(x_opt)
    sigma_g, curvature, sigma_J = gradient_noise(problem, ledger, u_opt, opts.step, opts.n_redraws,
                                                 paired=opts.bootstrap == "paired", failed=failed,
                                                 retry_failed=retry_failed)
    rng = named_rng(config.seed, "identifiability")
    verdict = assess(names, u_opt, sigma_g, ego.surrogate, opts, rng, curvature)
    interval_si = problem.from_unit(verdict.interval_unit.T).T  # (q, 2): lower and upper ends, SI
    units = {p.name: p.unit for p in problem.simulator.parameters()}
    result: dict[str, Any] = {
        "name": config.name,
        "parameters": names,
        "units": {n: units.get(n, "") for n in names},
        "bounds": {n: [float(a), float(b)] for n, a, b in zip(names, lo, hi)},
        "w_opt": {n: float(v) for n, v in zip(names, x_opt)},
        "w_opt_normalized": {n: float(v) for n, v in zip(names, u_opt)},
        "identifiable": {n: bool(v) for n, v in zip(names, verdict.identifiable)},
        "non_identifiable_reasons": {n: r for n, r in zip(names, verdict.reasons) if r},
        "correlated_with": {n: c for n, c in zip(names, verdict.correlated_with) if c},
        "interval": {n: [float(a), float(b)] for n, (a, b) in zip(names, interval_si)},
        "interval_normalized": {n: [float(a), float(b)] for n, (a, b) in zip(names, verdict.interval_unit)},
        "interval_method": {"sigma_J": sigma_J, "n_redraws": opts.n_redraws, "step": opts.step,
                            "bootstrap": opts.bootstrap,
                            "n_sigmas": opts.n_sigmas,
                            "covariance_normalized": verdict.covariance.tolist()},
        "sensitivity": {
            "total_sobol": {n: float(v) for n, v in zip(names, verdict.total_index)},
            "first_sobol": {n: float(v) for n, v in zip(names, verdict.first_index)},
            "lengthscales": None if verdict.lengthscales is None
            else {n: float(v) for n, v in zip(names, np.ravel(verdict.lengthscales))},
        },
        "J_max": float(ego.y_opt),
        "objective": config.objective.plugin,
        "surrogate": config.surrogate.plugin,
        "simulator": config.simulator.plugin,
        "seed": config.seed,
        "failed_points": failed,
    }
    if problem.w_ref is not None:
        w_ref = np.array([problem.w_ref[n] for n in names])
        result["w_ref"] = {n: float(v) for n, v in zip(names, w_ref)}
        result["w_ref_normalized"] = {n: float(v) for n, v in zip(names, problem.to_unit(w_ref))}
        result["errors_percent"] = errors_percent(problem, x_opt)
    if ego.n_refine:
        result["paper_loop"] = paper_loop(problem, ego)
    return result


def paper_loop(problem: Problem, ego: EGOResult) -> dict[str, Any]:
    """Where the paper's loop stood when it stopped, before the local refinement (``ego.refine``)."""
    names = problem.names
    n_loop = ego.n_evaluations - ego.n_refine
    best = int(np.argmax(ego.y[:n_loop]))
    x = np.asarray(ego.X[best], float)
    out: dict[str, Any] = {
        "n_iterations": n_loop - ego.n_initial, "n_simulator_calls": n_loop, "J_max": float(ego.y[best]),
        "w_opt": {n: float(v) for n, v in zip(names, x)},
        "w_opt_normalized": {n: float(v) for n, v in zip(names, problem.to_unit(x))}}
    if problem.w_ref is not None:
        out["errors_percent"] = errors_percent(problem, x)
    return out


def errors_percent(problem: Problem, x_si: np.ndarray) -> dict[str, float]:
    """|w - w_ref| per component in % of its admissible interval; ``x_si (q,)`` SI."""
    lo, hi = problem.bounds[:, 0], problem.bounds[:, 1]
    return {n: float(100 * abs(a - problem.w_ref[n]) / (h - l)) for n, a, l, h in zip(problem.names, x_si, lo, hi)}
