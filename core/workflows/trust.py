"""Trust per component under model error: yes, no or not assessed, which checks ran, and the bias bound.

Shared by the full checks (:func:`suspid.workflows.analysis.model_error`) and the linearised ones
(:func:`suspid.workflows.linearised.linearised_model_error`), so that both call a component
trustworthy on the same rule and combine the sources of bias on the same rule
(:func:`combine_sources`): the two methods differ only in how each source's shift of w_opt is
obtained (re-identification by simulation, or on spectra linearised once per date).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from suspid.method.identifiability import bias_aware_half_width, bias_bound_for_half_width

__all__ = ["REQUIRED_CHECKS", "CHECK_LABELS", "LINEARISED_LABELS", "BiasSources", "check_labels", "checks_report",
           "combine_sources", "correction_report", "equivalent_bias_bound", "model_spread", "transfer_term",
           "trust_states", "trust_word"]

REQUIRED_CHECKS = ("self_check", "adequacy", "groups")
"""The checks that must all have run for a component to be called trustworthy: the reference-date self-check
(model-form error at w0), the adequacy test at w_opt and the data groups (a sensitivity that differs from the
vehicle's). The nuisance sweep is opt-in: it runs where the user declares uncertain model parameters."""

CHECK_LABELS = {"self_check": "reference-date self-check", "adequacy": "adequacy at w_opt",
                "groups": "data groups", "nuisance": "nuisance parameters", "no_change": "no-change test at w0"}

LINEARISED_LABELS = CHECK_LABELS | {
    "self_check": "reference-date self-check on the spectra linearised at w0",
    "groups": "data groups on the spectra linearised at w_opt",
    "nuisance": "model parameters calibrated at the reference date and propagated by linearisation"}
"""The checks' names when ``identifiability.model_error.method`` is ``linearised`` (the default): no
re-identification by simulation, the same checks on the spectra linearised once per date."""


def check_labels(method: str | None) -> dict[str, str]:
    """The checks' names for report.md and the terminal, by the model-error method of a result."""
    return LINEARISED_LABELS if method == "linearised" else CHECK_LABELS


def trust_word(trustworthy: bool | None) -> str:
    """A component's trust under model error in words: True "yes", False "no", None (or absent) "not assessed"."""
    return "yes" if trustworthy is True else "no" if trustworthy is False else "not assessed"


def checks_report(checks: dict[str, str]) -> dict[str, dict[str, Any]]:
    """``{check: {"ran": bool, "status": str, "required": bool}}`` for result.json (every check, in order)."""
    out = {}
    for c in CHECK_LABELS:
        status = checks.get(c, "not run")
        out[c] = {"ran": status == "done", "status": status, "required": c in REQUIRED_CHECKS}
    return out


def trust_states(names: list[str], flags: list[list[str]], checks: dict[str, str]) -> dict[str, Any]:
    """Trust per component: yes (True), no (False) or not assessed (None), with the reasons.

    A component is **not trustworthy** when a check that ran flags it (``flags[k]`` not empty): one check
    is enough to say no. It is **trustworthy** only when no check flags it and every check of
    :data:`REQUIRED_CHECKS` ran (``checks[c] == "done"``); otherwise it is **not assessed**: no check that
    ran found a fault, but the checks that would judge it did not all run (their statuses are the reasons).

    :param flags: ``(q,)`` lists of the checks' reasons against each component.
    :param checks: check name -> ``"done"`` or why it did not run.
    :returns: ``{"trustworthy": name -> bool | None, "reasons": name -> [str] (the no's),
        "not_assessed": name -> [str]}``.
    """
    missing = [f"{CHECK_LABELS[c]} {checks.get(c, 'not run')}" for c in REQUIRED_CHECKS if checks.get(c) != "done"]
    trustworthy: dict[str, bool | None] = {}
    for n, f in zip(names, flags):
        trustworthy[n] = False if f else (None if missing else True)
    return {"trustworthy": trustworthy, "reasons": {n: f for n, f in zip(names, flags) if f},
            "not_assessed": {n: list(missing) for n in names if trustworthy[n] is None}}


def equivalent_bias_bound(sd: np.ndarray, shift: np.ndarray, sd_model: np.ndarray, n_sigmas: float) -> np.ndarray:
    """The bias bound B that gives :func:`~suspid.method.identifiability.bias_aware_half_width` the interval of
    an estimate with sampling spread ``sd``, a bias of at most ``|shift|`` and a further *random* spread
    ``sd_model`` from the model parameters (all ``(q,)``, fractions of the admissible interval).

    The uncertain θ move w_opt by G Δt, a random quantity independent of the sampling: its spread adds in
    quadrature, σ_eff² = σ² + σ_model², and the interval of level P(|Z| ≤ n) is the bias-aware one of σ_eff
    and |shift|. The analysis widens intervals by a bound B on top of σ, so B solves χ(σ, B) = χ(σ_eff, |shift|)
    (χ increases with B).
    """
    sd = np.asarray(sd, float)
    shift = np.abs(np.asarray(shift, float))
    sd_model = np.nan_to_num(np.asarray(sd_model, float), nan=0.0)
    target = bias_aware_half_width(np.sqrt(sd ** 2 + sd_model ** 2), shift, n_sigmas)
    return np.array([bias_bound_for_half_width(s, chi, n_sigmas) for s, chi in zip(sd, target)])


def model_spread(sensitivity: np.ndarray, covariance_t: np.ndarray) -> np.ndarray:
    """``(q,)`` the standard deviation of w_opt's shift G Δt when Δt has covariance Σ_t: √diag(G Σ_t Gᵀ), with the
    correlations of the model parameters (two that the reference date can only tell apart in a combination move
    w_opt together, or against each other).

    :param sensitivity: ``(q, p)`` G = du_opt/dt (NaN, where a component is flat, counts 0).
    :param covariance_t: ``(p, p)`` Σ_t.
    """
    G = np.nan_to_num(np.asarray(sensitivity, float))
    return np.sqrt(np.clip(np.diag(G @ np.asarray(covariance_t, float) @ G.T), 0, None))


@dataclass
class BiasSources:
    """What moves w_opt besides the sampling, per source: each ``(q,)`` in fractions of the admissible interval,
    however it was obtained (a check that did not run gives zeros).

    :ivar self_check: the reference-date self-check's mean shift u_opt − u0 over its splits (signed).
    :ivar groups_half: half the spread of the data groups' estimates.
    :ivar model_shift: the shift of w_opt the model parameters give at their calibrated values (at the middle of
        their assumed ranges without a calibration), signed: a known bias.
    :ivar model_spread: the standard deviation of w_opt's shift from what remains uncertain of the model
        parameters, √diag(G Σ_t Gᵀ), G = du_opt/dt, Σ_t the calibration's posterior (with its correlations) or the
        uniform spread of the assumed ranges.
    :ivar residual: what the way ``model_shift`` was obtained may still miss (the linearised search's last step;
        0 for a re-identification by simulation).
    :ivar self_check_se: the standard error of ``self_check`` over its splits (``None``: not measured, the shift
        is then never corrected).
    """

    self_check: np.ndarray
    groups_half: np.ndarray
    model_shift: np.ndarray
    model_spread: np.ndarray
    residual: np.ndarray
    self_check_se: np.ndarray | None = None

    def significant_self_check(self) -> np.ndarray:
        """``(q,)`` the self-check's mean shift where it is a bias (beyond 2 standard errors), 0 elsewhere: measured
        on the (calibrated) model where the truth is w0, it can be corrected with its sign."""
        sc = np.asarray(self.self_check, float)
        if self.self_check_se is None:
            return np.zeros_like(sc)
        return np.where(np.abs(sc) > 2 * np.asarray(self.self_check_se, float), sc, 0.0)

    @classmethod
    def none(cls, q: int) -> "BiasSources":
        """No source measured yet: every term 0."""
        return cls(*(np.zeros(q) for _ in range(5)))


def combine_sources(sd: np.ndarray, sources: BiasSources, correct: bool, n_sigmas: float,
                    correct_self_check: bool = False, transfer_error: float = 0.0
                    ) -> tuple[np.ndarray, np.ndarray | None]:
    """The bias bound of w_opt's interval from its sources (:class:`BiasSources`), and the correction.

    - ``correct`` (the default): the model parameters' shift is a known bias and is corrected (the estimate
      becomes w_opt + ``model_shift``); the self-check's mean shift and half the groups' spread, two sources of
      unknown sign, are combined in quadrature, plus ``residual``; the model parameters' remaining spread adds to
      the sampling one in quadrature (:func:`equivalent_bias_bound`). With ``correct_self_check``, the
      self-check's significant bias (:meth:`BiasSources.significant_self_check`) is corrected too, and its
      standard error, a random error of that correction, adds to the model parameters' spread in quadrature.
      ``transfer_error`` ρ: where nothing changed the corrected shift vanishes up to sampling (the noise model
      absorbs the discrepancy at w0); at w_opt it is an extrapolation by model parameters that may stand in for
      physics the model lacks, whose effect changes with w otherwise (a w-dependent discrepancy, Brynjarsdóttir
      and O'Hagan, "Learning about physical parameters: the importance of model discrepancy", Inverse Problems
      2014): ρ |model_shift| (:func:`transfer_term`) is one more bias of unknown sign in the quadrature.
    - otherwise: w_opt is kept and every source is added as a worst case, |self_check| + groups_half +
      |model_shift|, with the same spread.

    :param sd: ``(q,)`` the sampling standard deviations of w_opt (fractions of the interval).
    :returns: ``(bound (q,), correction (q,) or None)``: the bound B for
        :func:`~suspid.method.identifiability.bias_aware_half_width`, and the shift to add to u_opt.
    """
    sd = np.asarray(sd, float)
    sc, gh = np.asarray(sources.self_check, float), np.asarray(sources.groups_half, float)
    if correct:
        fix = sources.significant_self_check() if correct_self_check else np.zeros_like(sc)
        se = np.zeros_like(sc) if sources.self_check_se is None else np.asarray(sources.self_check_se, float)
        known = np.sqrt((sc - fix) ** 2 + gh ** 2 + transfer_term(sources, transfer_error) ** 2) \
            + np.abs(sources.residual)
        spread = np.hypot(np.nan_to_num(np.asarray(sources.model_spread, float)), np.where(fix != 0, se, 0.0))
        return (equivalent_bias_bound(sd, known, spread, n_sigmas),
                np.asarray(sources.model_shift, float) - fix)
    known = np.abs(sc) + gh + np.abs(sources.model_shift)
    return equivalent_bias_bound(sd, known, sources.model_spread, n_sigmas), None


def transfer_term(sources: BiasSources, transfer_error: float, correct: bool = True) -> np.ndarray:
    """``(q,)`` the bound on the calibrated shift's own error away from the reference date, ρ |model_shift|
    (fractions of the admissible interval; :func:`combine_sources`); zeros uncorrected (``correct`` false),
    where the whole shift is already a worst case."""
    rho = float(transfer_error) if correct else 0.0
    return rho * np.abs(np.nan_to_num(np.asarray(sources.model_shift, float)))


def correction_report(problem: Any, u_opt: np.ndarray, correction: np.ndarray, sources: BiasSources,
                      correct_self_check: bool, how: str = "", **terms: np.ndarray) -> dict[str, Any]:
    """result.json's ``model_error.correction``, for both methods: what was corrected, the correction and the
    self-check's part of it (% of the interval), ``terms`` (name -> ``(q,)``, e.g. the linearised search's last
    step) and the corrected values (SI).

    :param problem: the run's :class:`~suspid.workflows.problem.Problem` (names, unit cube).
    :param correction: ``(q,)`` the shift added to u_opt (:func:`combine_sources`).
    :param how: how the model parameters' shift was obtained, appended to the description.
    """
    names = problem.names
    fix = sources.significant_self_check() if correct_self_check else np.zeros(len(names))
    return {
        "method": "w_opt + the shift the model parameters calibrated at the reference date give" + how
                  + (" − the self-check's significant bias" if correct_self_check else ""),
        "correction_percent": {n: float(100 * c) for n, c in zip(names, correction)},
        "self_check_percent": {n: float(-100 * c) for n, c in zip(names, fix)},
        **{key: {n: float(100 * c) for n, c in zip(names, v)} for key, v in terms.items()},
        "w_corrected": {n: float(v) for n, v in
                        zip(names, problem.from_unit(np.clip(np.asarray(u_opt, float) + correction, 0, 1)))}}
