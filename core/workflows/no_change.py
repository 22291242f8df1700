"""Does the measurement date tell w_opt from the reference state w0? A test of "nothing changed" (beyond the paper).

The intervals of :mod:`suspid.method.identifiability` are local: the sandwich
reads the curvature of J at its maximum w_opt. Where J has a second maximum of
nearly the same height, the data do not decide between the two, and an
interval around one of them says nothing of the other. The alternative that
matters most to a user is w0, the suspension of the reference date: "nothing
changed". On the second independent train with the likelihood objective and
w_ref = w0, J on the measurement date had a maximum at k_sec_z 13 % of its
interval below w0 and another near w0, 0.06 higher against a bootstrap
spread of 0.04 for the difference (``benchmarks/RESULTS.md``): the sandwich's
± 5 % around the first held neither w0 nor the truth.

The test: ΔJ = J(w_opt) − J(w0) on the measurement date (one simulation at
w0 on its segments), and its spread over the bootstrap replicates of
:func:`suspid.workflows.analysis.gradient_noise` (segments resampled as
pairs, noise paths drawn again, the noise model fitted again on the resampled
reference date). w0 is *rejected* when ΔJ exceeds n_sigmas of those
standard deviations (the intervals' own level). When it is not rejected, w0
belongs to what the data support: every component's interval is widened until
it holds w0's value (the test inverted at w0), and a component whose interval
then exceeds the precision a finding must have (``max_half_width``) is not
reported, with the reason. And what is reported is then the reference date's state
(``identifiability.model_error.no_change_report: reference``, the default): a change the data do not show is
not reported as one, while the estimate stays in ``w_opt`` and the interval, centred on w0, still holds it.
A maintenance engineer reads "nothing changed" instead of values that drift within their intervals from date
to date; ``estimate`` keeps the estimate as the reported value.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from suspid.infra.seeds import rng as named_rng
from suspid.method.identifiability import bias_aware_half_width, bias_bound_for_half_width
from suspid.method.noise import bootstrap_refit, reference_paths
from suspid.workflows.evaluation import j_of_spectra
from suspid.workflows.problem import Problem, segment_speeds

__all__ = ["NoChange", "no_change_test", "reach_bound", "apply_no_change", "reported_correction",
           "reports_reference"]


@dataclass
class NoChange:
    """The test of w = w0 on the measurement date.

    :ivar delta_j: J(w_opt) − J(w0) with the run's own noise paths (J's units).
    :ivar sd: the bootstrap standard deviation of that difference.
    :ivar rejected: ΔJ > n_sigmas · sd.
    :ivar n_redraws: bootstrap replicates.
    :ivar n_sigmas: the level, in standard deviations.
    :ivar null: the point J(w_opt) is compared with, in words (w0, or w0 less the bias the checks correct).
    """

    delta_j: float
    sd: float
    rejected: bool
    n_redraws: int
    n_sigmas: float
    null: str = "w0"

    @property
    def z(self) -> float:
        return float(self.delta_j / self.sd) if self.sd > 0 else (0.0 if self.delta_j <= 0 else float("inf"))

    def to_dict(self, n_simulations: int) -> dict[str, Any]:
        return {"status": "done", "delta_J": self.delta_j, "sd_delta_J": self.sd, "z": self.z,
                "n_sigmas": self.n_sigmas, "rejected": self.rejected, "n_redraws": self.n_redraws,
                "n_simulations": n_simulations}


def no_change_test(problem: Problem, y_opt: np.ndarray, y0: np.ndarray, n_redraws: int, n_sigmas: float,
                   reference: bool = True) -> NoChange:
    """ΔJ = J(w_opt) − J(w0) and its bootstrap spread (module docstring). No simulation.

    :param y_opt: ``(v, n_channels, n_freqs)`` dB, the spectra at w_opt on the measurement date's segments.
    :param y0: the same at w0.
    :param reference: resample the reference date too and fit B again (when its data are in the run and B
        was fitted in it), as the intervals' bootstrap does.
    """
    config = problem.config
    rng = named_rng(config.seed, "no-change")
    ref = problem.reference if reference and config.noise.path is None else {}
    ref_speeds = segment_speeds(problem.reference_segments)
    paths = reference_paths(problem.noise_model, ref["y_mes0"], ref["y_sim0"]) if ref else None
    v = len(problem.segments)
    diffs = np.empty(n_redraws)
    for k in range(n_redraws):
        model = problem.noise_model
        if ref:
            model = bootstrap_refit(model, paths, ref_speeds, rng, problem.freqs, problem.channels)
        b = model.sample(v, rng)
        i = rng.integers(0, v, v)    # paired: a segment's measured and simulated spectra share its track
        y_mes = problem.y_mes[i]
        diffs[k] = (j_of_spectra(problem, y_opt[i], b, y_mes, model)[0]
                    - j_of_spectra(problem, y0[i], b, y_mes, model)[0])
    delta = float(j_of_spectra(problem, y_opt)[0] - j_of_spectra(problem, y0)[0])
    sd = float(np.std(diffs, ddof=1))
    return NoChange(delta, sd, bool(delta > n_sigmas * sd), n_redraws, n_sigmas)


def reach_bound(sd: np.ndarray, bound: np.ndarray, distance: np.ndarray, n_sigmas: float) -> np.ndarray:
    """The smallest bias bound B' ≥ ``bound`` whose bias-aware half-width χ(σ, B') reaches ``|distance|`` (all
    ``(q,)``, fractions of the admissible interval): the interval around the estimate then holds the point
    ``distance`` away from it (χ increases with B)."""
    sd, bound = np.asarray(sd, float), np.abs(np.asarray(bound, float))
    dist = np.abs(np.asarray(distance, float))
    out = bound.copy()
    half = bias_aware_half_width(sd, bound, n_sigmas)
    for k in np.flatnonzero(half < dist):
        out[k] = bias_bound_for_half_width(sd[k], dist[k], n_sigmas, lower=bound[k], upper=dist[k] + 1.0)
    return out


def apply_no_change(test: NoChange | None, names: list[str], sd: np.ndarray, bound: np.ndarray | None,
                    distance: np.ndarray, n_sigmas: float, max_half_width: float,
                    reasons: dict[str, list[str]]) -> np.ndarray | None:
    """Where w0 is not rejected: the bias bound that makes every interval hold w0, and the reasons of the
    components that it leaves wider than ``max_half_width``.

    :param distance: ``(q,)`` the reported estimate minus w0, fractions of the admissible interval.
    :param reasons: name -> reasons against it, extended in place.
    :returns: the new bound ``(q,)`` (``bound`` itself when w0 is rejected or no test ran).
    """
    if test is None or test.rejected:
        return bound
    sd = np.zeros(len(names)) if sd is None else np.asarray(sd, float)
    base = np.zeros(len(names)) if bound is None else np.asarray(bound, float)
    new = reach_bound(sd, base, distance, n_sigmas)
    for k, n in enumerate(names):
        if abs(distance[k]) > max_half_width:
            reasons.setdefault(n, []).append(
                f"the data do not tell it from its value at the reference date: J({test.null}) is {abs(test.z):.1f} "
                f"bootstrap standard deviations {'below' if test.z >= 0 else 'above'} J(w_opt) on the measurement "
                f"date (w0 rejected beyond "
                f"{test.n_sigmas:g}), and w0 lies {100 * abs(distance[k]):.1f} % of the interval away")
    return new


REFERENCE_REPORTED = "the reference date's values"
"""How ``no_change.reported`` begins where the values reported are w0's (:func:`reported_correction`)."""


def reports_reference(result: dict[str, Any]) -> bool:
    """Whether a ``result.json`` reports the reference date's values because the no-change test kept w0."""
    nc = (result.get("model_error") or {}).get("no_change") or {}
    return str(nc.get("reported", "")).startswith(REFERENCE_REPORTED)


def reported_correction(report: dict[str, Any], u_opt: np.ndarray, correction: np.ndarray | None, u0: np.ndarray,
                        how: str) -> np.ndarray | None:
    """The shift from w_opt to the reported value ``(q,)`` (normalised), given the no-change test's ``report``
    (``result.json``'s ``model_error.no_change``): where it ran and did not reject w0 and ``how`` is
    ``"reference"``, the shift to w0 itself (``u0 - u_opt``), and the report says so (``reported``); otherwise
    ``correction`` unchanged (None: no correction).

    The interval stays valid: :func:`apply_no_change` widened it to reach from the estimate to w0, so centred on w0
    it holds the estimate."""
    if how != "reference" or report.get("status") != "done" or report.get("rejected", True):
        if report.get("status") == "done":
            report["reported"] = "the estimate" + (": w0 is rejected" if report.get("rejected") else
                                                   " (identifiability.model_error.no_change_report: estimate)")
        return correction
    u_opt, u0 = np.asarray(u_opt, float), np.asarray(u0, float)
    before = u_opt if correction is None else np.clip(u_opt + np.asarray(correction, float), 0, 1)
    report["reported"] = (REFERENCE_REPORTED + ": the data do not show a change (w0 not rejected); the "
                          "intervals, centred on w0, hold the estimate")
    report["estimate_minus_w0_percent"] = [float(100 * d) for d in before - u0]
    return u0 - u_opt
