"""Observability of element groups and localisation of a change to the element group(s) that explain it.

Both read the model through the Jacobian of its mean spectra with respect to
the *logarithm* of each finest element group's value (one element each):
``J (n_channels, n_freqs, n_g)`` in dB per unit of ln(value), and the variance
``var (n_channels, n_freqs)`` dB² of the observed change of the mean spectra
between two dates (the measurement date against the reference date, where
w = w0: :func:`change_statistics`).

**Fisher information and separability.** With independent cells,
F = Jᵀ diag(1/var) J ``(n_g, n_g)``. A change of relative size ``change`` of
element i (θ_i = ln(1 - change)) is told apart from the best-fitting change of
element j when the χ² the fit of j leaves, θ_i² (F_ii - F_ij² / F_jj), exceeds
``separation_chi2``; i and j are *separable* when that holds both ways.
Elements of one kind that are pairwise not separable form a cluster (complete
linkage): the cluster is the finest level the sensors resolve, identifiable
only through the sum of its members' changes (a left and a right yaw damper of
one bogie act on the carbody and bogie through their sum in a linear model).
A cluster is *detectable* when a change of its members together gives
θ² uᵀ F u >= ``separation_chi2`` (u the cluster's indicator).

A flat gain per channel (a calibration drift between the dates, the segments'
own gains) is fitted with every hypothesis and with the null when
``channel_gains`` is on (:func:`without_channel_gains`: Δ and J less their
weighted mean over each channel's frequencies).

The Jacobian is taken where the model reproduces the reference date: with
its uncertain model parameters (creep scale, conicity, series stiffnesses)
calibrated there (``calibrate``, by the caller). At their nominal values a
model whose resonances sit elsewhere than the vehicle's gives a sensitivity
of the wrong shape, and the least-squares change, a projection on it, comes
out smaller than the true one (and another element's sensitivity may fit the
change better).

**Localisation.** Each cluster c is a hypothesis "the elements of c deviate
together by θ": fitted by weighted least squares to the observed change Δ,
θ_c = (u_cᵀ Jᵀ W Δ) / (u_cᵀ F u_c), χ²_c = Σ W (Δ - J u_c θ_c)², then refined by
Gauss-Newton on simulations by the caller. Its evidence against "nothing
changed" is the Bayesian information criterion's difference
(χ²_0 - χ²_c) / s² - ln(n_cells), with s² = max(1, χ²_c / (n_cells - 1)) the
reduced χ² of the fit (model error and correlated cells widen the noise, never
narrow it): above ``min_evidence`` the best cluster is named, with every
hypothesis within ``near`` of it as an alternative that fits nearly as well.
Evidences of about 10 and more are "very strong" on Kass and Raftery's scale
(Bayes factors, JASA 90 (1995) 773-795), the default.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal, Sequence

import numpy as np
from pydantic import Field
from scipy.interpolate import BSpline
from scipy.stats import chi2 as chi2_dist

from suspid.options import Section

__all__ = ["LocalisationOptions", "Hypothesis", "HypothesisFit", "fisher_information", "separability",
           "clusters", "fit_hypotheses", "change_statistics", "fisher_information_unbiased",
           "without_channel_gains", "sandwich_sd", "smooth_gain_basis", "without_smooth_gains",
           "cluster_sd", "consistent_channels"]


class LocalisationOptions(Section):
    """The ``localisation:`` section: observability of element groups and localisation of a change."""

    enabled: bool | Literal["auto"] = Field(
        default=False, description="localise after an identification: true, 'auto' (when an identified kind with "
        "declared elements moved: its interval excludes the nominal value) or false (the default: a kind-level run "
        "stays as it was, in results and run time)")
    kinds: list[str] | None = Field(default=None, description="kinds whose elements are hypotheses (default: the "
                                    "identified parameters' kinds that have declared elements)")
    change: float = Field(default=0.3, gt=0.0, lt=1.0, description="relative change at which separability is "
                          "judged (0.3: an element at 70 % of its nominal value)")
    separation_chi2: float = Field(default=10.8, gt=0.0, description="χ² by which a change of one element must fit "
                                   "worse as another element's to be told apart (10.8: 1 dof, 0.1 %)")
    min_evidence: float = Field(default=10.0, ge=0.0, description="evidence (BIC difference against no change) to "
                                "name a group")
    near: float = Field(default=6.0, ge=0.0, description="alternatives: hypotheses within this evidence of the best")
    n_segments: int = Field(default=8, ge=2, description="segments the Jacobians are computed on: half of them "
                            "measurement-date segments, half their mirror images")
    refine_top: int = Field(default=3, ge=1, description="hypotheses refined by Gauss-Newton on simulations")
    gauss_newton_steps: int = Field(default=3, ge=0, le=10, description="Gauss-Newton steps of each refinement")
    floor_db: float = Field(default=0.05, gt=0.0, description="least standard deviation of a cell's change, dB")
    direction: Literal["any", "decrease"] = Field(
        default="any", description="'decrease': only a loss (value below nominal) is named, as wear, a leaking "
        "damper or a deflated air spring gives; 'any': a rise too")
    channel_gains: bool = Field(default=True, description="fit a flat gain per channel with every hypothesis (and "
                                "the null): a calibration drift or segment gains are not taken for a change")
    sensor_floor: bool = Field(default=True, description="when the noise model has no sensor floor (noise.floor: "
                               "none), estimate one on the reference date as noise.floor: auto does: where sensor "
                               "noise masks the response the measured spectra do not follow an element's change")
    calibrate: bool = Field(default=True, description="linearise the model at its model parameters estimated on "
                            "the reference date (identifiability.model_error.calibration's parameters and steps: by "
                            "default the simulator's calibratable ones), where its resonances match the vehicle's: "
                            "false linearises at their nominal values")
    model_form_octaves: float | None = Field(
        default=1.0, gt=0.0, description="the interval also holds the refined fit's structured misfit: a "
        "cluster-robust standard deviation with the cells of one channel within bands of this many octaves taken "
        "as correlated (the larger of it and the segments' one is used); null: the segments' spread only")
    consistent_channels: bool = Field(
        default=True, description="the named group's value and interval from the channels whose own estimates "
        "agree (the most discordant dropped one at a time while their heterogeneity exceeds its 0.1 % χ² level); "
        "the evidence stays that of every channel")
    calibration_gain_octaves: float | None = Field(
        default=1.0, gt=0.0, description="a smooth gain per channel (cubic B-splines in log2(f), knots this many "
        "octaves apart: sensor transfer functions, unmodelled flexibility) estimated jointly with the model "
        "parameters on the reference date, so that the calibration does not take it for a model parameter; null: "
        "a flat gain per channel only")


def change_statistics(residual_mes: np.ndarray, residual_ref: np.ndarray, floor_db: float = 0.05
                      ) -> tuple[np.ndarray, np.ndarray]:
    """The observed change Δ and its variance from per-segment residuals (measured minus model at w0).

    :param residual_mes: ``(v, n_channels, n_freqs)`` dB, measurement date.
    :param residual_ref: ``(v0, n_channels, n_freqs)`` dB, reference date (w = w0).
    :returns: ``Δ (n_channels, n_freqs)`` dB: the mean residual's change; ``var`` dB², the variance of that
        mean (segment spread over v on each date), at least ``floor_db``².
    """
    v, v0 = residual_mes.shape[0], residual_ref.shape[0]
    delta = residual_mes.mean(axis=0) - residual_ref.mean(axis=0)
    s_mes = residual_mes.var(axis=0, ddof=1) if v > 1 else np.zeros_like(delta)
    s_ref = residual_ref.var(axis=0, ddof=1) if v0 > 1 else np.zeros_like(delta)
    var = np.maximum(s_mes / v + s_ref / v0, floor_db ** 2)
    return delta, var


def without_channel_gains(x: np.ndarray, var: np.ndarray) -> np.ndarray:
    """``x (n_channels, n_freqs, ...)`` less its 1/var-weighted mean over the frequencies of each channel: the
    part a flat gain per channel (a nuisance parameter fitted with every hypothesis) cannot explain."""
    w = (1.0 / var).reshape(var.shape + (1,) * (x.ndim - 2))
    return x - np.sum(w * x, axis=1, keepdims=True) / np.sum(w, axis=1, keepdims=True)


def smooth_gain_basis(freqs: np.ndarray, octaves: float) -> np.ndarray:
    """``(n_freqs, m)``: cubic B-splines in log2(f) with knots every ``octaves`` octaves over the grid ``freqs``
    (Hz), a basis of the smooth gains per channel (sensor transfer functions, unmodelled flexibility) that a
    calibration on one date must not take for a model parameter; their sum is 1 (a flat gain is in it)."""
    x = np.log2(np.asarray(freqs, dtype=float))
    lo, hi = float(x.min()), float(x.max())
    n_int = max(1, int(math.ceil((hi - lo) / octaves - 1e-9)))
    inner = np.linspace(lo, hi, n_int + 1)
    knots = np.concatenate([[lo] * 3, inner, [hi] * 3])
    return BSpline.design_matrix(np.clip(x, lo, hi), knots, 3).toarray()


def without_smooth_gains(x: np.ndarray, weights: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """``x (n_channels, n_freqs, ...)`` less its weighted least-squares fit by ``basis (n_freqs, m)`` on each
    channel (weights ``(n_channels, n_freqs)``, 1/dB²): the part a smooth gain per channel cannot explain. By
    the Frisch-Waugh-Lovell theorem a least squares on what is left gives the estimate a joint fit with the
    gains would give."""
    out = np.array(x, dtype=float, copy=True)
    for k in range(x.shape[0]):
        sw = np.sqrt(np.asarray(weights[k], dtype=float))
        B = basis * sw[:, None]
        y = x[k].reshape(x.shape[1], -1) * sw[:, None]
        coef, *_ = np.linalg.lstsq(B, y, rcond=None)
        out[k] = x[k] - (basis @ coef).reshape(x[k].shape)
    return out


def fisher_information(J: np.ndarray, var: np.ndarray) -> np.ndarray:
    """F = Jᵀ diag(1/var) J ``(n_g, n_g)`` from ``J (n_channels, n_freqs, n_g)`` and ``var (n_channels, n_freqs)``."""
    A = J.reshape(-1, J.shape[-1]) / np.sqrt(var.reshape(-1))[:, None]
    return A.T @ A


def fisher_information_unbiased(J_segments: np.ndarray, var: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fisher information of the *expected* spectra from per-segment Jacobians, and their mean.

    The mean Jacobian over v segments carries each segment's own realisation of the track: a left and a right
    element of a mirror-symmetric car change the expected spectra of centreline sensors identically (a mirror
    image of the track is as likely), yet a single segment's spectra differently. E ||J̄ d||² = ||E[J] d||² +
    dᵀ Cov(J) d / v, so F = J̄ᵀ W J̄ - Σ_cells W Cov_s(J_cell) / v, negative eigenvalues set to 0.

    :param J_segments: ``(v, n_channels, n_freqs, n_g)``; :param var: ``(n_channels, n_freqs)``.
    :returns: ``F (n_g, n_g)`` and ``J̄ (n_channels, n_freqs, n_g)``.
    """
    v = J_segments.shape[0]
    J = J_segments.mean(axis=0)
    F = fisher_information(J, var)
    if v > 1:
        A = ((J_segments - J) / np.sqrt(var)[None, ..., None]).reshape(v, -1, J.shape[-1])
        C = np.einsum("sci,scj->ij", A, A) / (v - 1)
        lam, V = np.linalg.eigh(F - C / v)
        F = (V * np.maximum(lam, 0.0)) @ V.T
    return F, J


def separability(F: np.ndarray, change: float) -> np.ndarray:
    """``(n_g, n_g)``: S[i, j] = θ² (F_ii - F_ij² / F_jj), the χ² a change of element i by ``change`` leaves when
    fitted as a change of j (θ = ln(1 - change)); the diagonal is 0."""
    theta2 = math.log(1.0 - change) ** 2
    d = np.diag(F)
    with np.errstate(divide="ignore", invalid="ignore"):
        S = theta2 * (d[:, None] - F ** 2 / np.where(d[None, :] > 0, d[None, :], np.inf))
    np.fill_diagonal(S, 0.0)
    return np.maximum(S, 0.0)


def clusters(S: np.ndarray, kinds: Sequence[str], threshold: float) -> list[list[int]]:
    """Groups, within each kind, of elements that are pairwise not separable (min(S_ij, S_ji) < ``threshold``).

    Complete linkage: two groups merge, closest pair first, only when every element of one is inseparable from
    every element of the other, so that a weakly seen element does not chain separable ones together.
    """
    n = len(kinds)
    groups: list[list[int]] = [[i] for i in range(n)]
    close = lambda i, j: kinds[i] == kinds[j] and min(S[i, j], S[j, i]) < threshold  # noqa: E731
    order = sorted(((min(S[i, j], S[j, i]), i, j) for i in range(n) for j in range(i + 1, n) if close(i, j)))
    where = list(range(n))
    for _, i, j in order:
        a, b = where[i], where[j]
        if a == b or not all(close(x, y) for x in groups[a] for y in groups[b]):
            continue
        groups[a] += groups[b]
        for x in groups[b]:
            where[x] = a
        groups[b] = []
    return [sorted(g) for g in groups if g]


@dataclass
class Hypothesis:
    """"The elements ``members`` (indices of the finest groups) deviate together": one cluster."""

    name: str
    kind: str
    members: list[int]
    nominal: float
    note: str = ""


@dataclass
class HypothesisFit:
    """A hypothesis fitted to the observed change.

    :ivar theta: ln(value / nominal) of its elements; :ivar sd: its standard deviation (reduced-χ² scaled).
    :ivar chi2: χ² of the fit; :ivar evidence: BIC difference against no change (larger: better).
    """

    hypothesis: Hypothesis
    theta: float
    sd: float
    chi2: float
    evidence: float
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def value(self) -> float:
        """SI value of every element of the hypothesis."""
        return self.hypothesis.nominal * math.exp(self.theta)

    def interval(self, n_sigmas: float = 2.0, sd: float | None = None) -> tuple[float, float]:
        """SI interval exp(θ ± n sd) times the nominal value (``sd``: another standard deviation of θ)."""
        n, sd = self.hypothesis.nominal, self.sd if sd is None else sd
        return n * math.exp(self.theta - n_sigmas * sd), n * math.exp(self.theta + n_sigmas * sd)


def fit_column(column: np.ndarray, delta: np.ndarray, var: np.ndarray) -> tuple[float, float, float]:
    """Weighted least squares of ``delta ≈ column θ`` over the cells: ``(θ, sd of θ, χ²)`` (sd unscaled)."""
    w = 1.0 / var
    a = float(np.sum(w * column * column))
    if not a > 0:
        return 0.0, math.inf, float(np.sum(w * delta * delta))
    theta = float(np.sum(w * column * delta)) / a
    chi2 = float(np.sum(w * (delta - column * theta) ** 2))
    return theta, 1.0 / math.sqrt(a), chi2


def sandwich_sd(column: np.ndarray, var: np.ndarray, residuals: Sequence[np.ndarray]) -> float:
    """Standard deviation of the weighted least-squares θ from the segments themselves: θ = a · Δ with
    a = W c / (cᵀ W c), Δ the difference of the dates' mean residuals, so var θ = Σ_dates Var_s(a · r_s) / v.
    It holds whatever the correlation of the cells (smooth gains per segment, overlapping lines).

    :param residuals: per date ``(v, n_channels, n_freqs)`` dB (at least 2 segments each).
    """
    w = column / var
    a = w / float(np.sum(w * column))
    total = 0.0
    for r in residuals:
        t = np.tensordot(r, a, axes=([1, 2], [0, 1]))
        total += float(np.var(t, ddof=1)) / len(t) if len(t) > 1 else 0.0
    return math.sqrt(total)


def cluster_sd(column: np.ndarray, var: np.ndarray, residual: np.ndarray, clusters: np.ndarray) -> float:
    """Standard deviation of the weighted least-squares θ of ``delta ≈ column θ`` that the fit's own residual
    ``e (n_channels, n_freqs)`` dB implies when the cells of one cluster (a channel's octave band,
    :func:`suspid.method.calibration.octave_clusters`) may be correlated in any way and clusters are
    independent: the cluster-robust sandwich var θ = Σ_c (Σ_{cells of c} a e)², a = W c / (cᵀ W c).

    The segments' spread (:func:`sandwich_sd`) sees the noise of the dates only; where the model responds to
    the element differently from the vehicle (model-form error: a resonance it has and the vehicle lacks,
    a damper's nonlinearity), the residual is a structured misfit, smooth over frequency, and the channels'
    own estimates disagree beyond their noise: this sandwich carries that into the interval."""
    w = column / var
    a = w / float(np.sum(w * column))
    score = (a * residual).reshape(-1)
    labels = np.asarray(clusters).reshape(-1)
    sums = np.zeros(int(labels.max()) + 1)
    np.add.at(sums, labels, score)
    return float(math.sqrt(np.sum(sums ** 2)))


def consistent_channels(theta: np.ndarray, sd: np.ndarray, level: float = 0.999) -> np.ndarray:
    """``(n_channels,)`` bool: the channels whose own estimates θ_k ± sd_k agree, the most discordant (farthest
    from the mean of the others, in their joint standard deviations) dropped one at a time while the heterogeneity Q = Σ ((θ_k − θ̄) / sd_k)² (θ̄ their inverse-variance mean) exceeds the
    χ² quantile ``level`` of its m − 1 degrees of freedom, and at least three channels are left. Channels that do
    not see the change (sd infinite) are kept: they weigh nothing.

    Where one channel's model responds to an element otherwise than the vehicle does (a resonance the vehicle
    lacks), its θ_k disagrees with the others' beyond their noise, and pooling it pulls the value toward its own."""
    theta, sd = np.asarray(theta, float), np.asarray(sd, float)
    keep = np.ones(theta.size, bool)
    seen = np.isfinite(sd) & (sd > 0) & np.isfinite(theta)
    while True:
        idx = np.flatnonzero(keep & seen)
        if idx.size <= 3:
            return keep
        w = 1.0 / sd[idx] ** 2
        mean = float(np.sum(w * theta[idx]) / np.sum(w))
        if float(np.sum(w * (theta[idx] - mean) ** 2)) <= chi2_dist.ppf(level, idx.size - 1):
            return keep
        # the channel farthest from the others' mean (leave-one-out: a dominant channel does not hide itself)
        w_rest = np.sum(w) - w
        mean_rest = (np.sum(w * theta[idx]) - w * theta[idx]) / w_rest
        z = (theta[idx] - mean_rest) / np.sqrt(sd[idx] ** 2 + 1.0 / w_rest)
        keep[idx[int(np.argmax(np.abs(z)))]] = False


def evidence(chi2_null: float, chi2: float, n_cells: int, inflation: float = 1.0) -> tuple[float, float]:
    """``(evidence, s²)``: BIC difference of a one-parameter fit against no change, the χ² divided by
    s² = max(1, reduced χ² of the fit, ``inflation``) (``inflation``: (sandwich sd / model sd)² of θ, the
    correlation of the cells)."""
    s2 = max(1.0, chi2 / max(1, n_cells - 1), inflation)
    return (chi2_null - chi2) / s2 - math.log(n_cells), s2


def fit_hypotheses(hypotheses: Sequence[Hypothesis], J: np.ndarray, delta: np.ndarray,
                   var: np.ndarray, residuals: Sequence[np.ndarray] = ()) -> list[HypothesisFit]:
    """Every hypothesis fitted on the linearised model (``J`` per ln value, ``(n_channels, n_freqs, n_g)``),
    best evidence first; ``residuals`` (per date, :func:`sandwich_sd`) widen sd and evidence for correlated
    cells."""
    n_cells = delta.size
    chi2_null = float(np.sum(delta ** 2 / var))
    out = []
    for h in hypotheses:
        column = J[..., h.members].sum(axis=-1)
        theta, sd, chi2 = fit_column(column, delta, var)
        sw = sandwich_sd(column, var, residuals) if len(residuals) and math.isfinite(sd) else 0.0
        ev, s2 = evidence(chi2_null, chi2, n_cells, (sw / sd) ** 2 if sd > 0 and math.isfinite(sd) else 1.0)
        out.append(HypothesisFit(h, theta, sd * math.sqrt(s2), chi2, ev, {"chi2_null": chi2_null, "s2": s2,
                                                                          "method": "linearised"}))
    return sorted(out, key=lambda f: -f.evidence)
