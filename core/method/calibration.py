"""Calibration of the model's uncertain parameters at the reference date, and their effect on w_opt (beyond the paper).

The paper's protocol has one date where the truth is known: at the reference
date the train runs at w0. Its data therefore also inform the *other*
parameters of the model, the ones that are not identified but are uncertain
(a damper mount's series stiffness, the fraction of Kalker's creep
coefficients, the equivalent conicity, whatever the simulator declares in
:meth:`suspid.interfaces.Simulator.calibratable`). Here they are estimated
from the reference date instead of being swept over assumed ranges, the idea
of Kennedy and O'Hagan ("Bayesian calibration of computer models", J. R.
Stat. Soc. B 63, 2001) applied where the protocol already gives a known state.

**Estimate** (:func:`calibrate_step`). A weighted least squares on the mean
spectra of the v0 reference segments, linearised in θ (one Gauss-Newton step;
the caller iterates with the Jacobian at the new θ):

    ȳ_mes0,kj − ȳ_sim0,kj(θ) = g_k + Σ_p ∂ȳ_sim0,kj/∂t_p Δt_p + e_kj,

with t = (θ − θ_nominal) / (width of θ's assumed range), g_k a per-channel
offset in dB (a sensor gain, profiled out: the calibration reads the *shape*
of the spectra over frequency, which a gain does not change) and weights
v0 / Var B_kj (the noise model's variance of one path). Why the mean spectra
and not the objective J: the mean spectra make θ a linear least squares per
step, whose information and covariance are closed forms, while J at the
reference date is the noise model's own fit (B absorbs any mean difference
there, J does not see it).

**Uncertainty**: the residual e is not white. What the model lacks besides θ
(the Kennedy-O'Hagan discrepancy: gains smooth over frequency, effects it does
not have) is correlated over neighbouring frequencies, so the textbook
covariance (XᵀWX)⁻¹ would be far too narrow. The covariance is the
cluster-robust sandwich P⁻¹ (M / κ² + Λ) P⁻¹, M = Σ_c X_cᵀ W e_c e_cᵀ W X_c with
clusters c the (channel, octave band) blocks (inside a block the residuals may
be correlated in any way, between blocks they are taken as independent), and
P = XᵀWX / κ + Λ. Λ is a prior on t, a Gaussian of the spread of a uniform
law over the assumed range (precision 12 per unit of t), which keeps a
parameter the data do not see at its nominal value with its range's spread;
κ ≥ 1 is the discrepancy's variance inflation, measured once as the mean
ratio of the data-only sandwich's variances to the white ones: without it the
weights W would let the 8 × n_freqs cells outweigh the prior as if they were
independent, with it the estimate weighs data and prior as the sandwich does.
The discrepancy can still be confounded with θ: a gain curve correlated over
more than an octave that resembles ∂y/∂θ biases θ beyond its interval
(``benchmarks/RESULTS.md``).

**Pinned or not**: a parameter whose standard deviation exceeds
``max_sd_fraction`` of its assumed range, or whose estimate reaches a bound of
that range, is not pinned down by the reference date (weak Fisher information,
or a reference date that asks for a value the model's other errors explain):
it is reported with its nominal value and its assumed range, and says so. The
checks still use the whole posterior (its mean and its correlations) for
every parameter.

**Propagation** (:func:`implicit_shifts`): by the implicit-function theorem,
the maximiser of J(u, t) moves by du/dt = −H_uu⁻¹ H_ut, H the Hessian of J in
the normalised identified parameters u ∈ [0, 1]^q and t. The bias of w_opt
from the θ that remain uncertain is then G Δt with G = du/dt: its covariance
G Σ_t Gᵀ carries the correlation of the sources (through G, and through Σ_t
for the calibrated ones), instead of a sum of worst cases.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from pydantic import Field

from suspid.options import Section

__all__ = ["CalibrationOptions", "CalibrationStep", "calibrate_step", "octave_clusters", "implicit_shifts",
           "UNIFORM_SD"]

UNIFORM_SD = 1.0 / np.sqrt(12.0)
"""Standard deviation of a parameter uniform over its assumed range, in units of that range's width."""


class CalibrationOptions(Section):
    """``identifiability.model_error.calibration``: the model parameters estimated at the reference date
    (:mod:`suspid.method.calibration`; run by ``identifiability.model_error.method: linearised``)."""

    enabled: bool = Field(default=True, description="estimate the model parameters at the reference date")
    parameters: dict[str, tuple[float, float] | None] = Field(
        default_factory=dict, description="model parameter -> its assumed range [low, high] in SI units (null: "
        "the simulator's bounds); empty: nuisance.parameters if given, else the parameters the simulator declares "
        "calibratable")
    max_iterations: int = Field(default=5, ge=1, le=10, description="Gauss-Newton steps (each a Jacobian of the "
                                "reference date's spectra with respect to the model parameters)")
    max_sd_fraction: float = Field(default=0.1, gt=0, le=1, description="a parameter is pinned down by the "
                                   "reference date when its standard deviation is below this fraction of its "
                                   "assumed range")
    n_sigmas: float = Field(default=2.0, gt=0, description="half-width of a calibrated parameter's interval, in "
                            "standard deviations")
    cluster_octaves: float = Field(default=1.0, gt=0, le=8, description="width of the frequency bands (octaves) "
                                   "within which the residuals of a channel may be correlated (the sandwich's "
                                   "clusters)")


@dataclass
class CalibrationStep:
    """One Gauss-Newton step of the calibration, in units of the assumed ranges.

    :ivar step: ``(p,)`` Δt.
    :ivar covariance: ``(p, p)`` cluster-robust covariance of t after the step.
    :ivar naive_sd: ``(p,)`` the white-residual standard deviation √diag((XᵀWX)⁻¹), for comparison.
    :ivar offsets_db: ``(n_channels,)`` the profiled per-channel offsets g_k.
    :ivar residual_rms_db: rms of the weighted fit's residual e, dB.
    :ivar n_clusters: number of (channel, octave) clusters of the sandwich.
    """

    step: np.ndarray
    covariance: np.ndarray
    naive_sd: np.ndarray
    offsets_db: np.ndarray
    residual_rms_db: float
    n_clusters: int


def octave_clusters(freqs: np.ndarray, n_channels: int, octaves: float = 1.0) -> np.ndarray:
    """``(n_channels, n_freqs)`` int: the cluster of each cell, one per channel and band of ``octaves``
    octaves (bands counted from the grid's lowest frequency)."""
    f = np.asarray(freqs, dtype=float)
    band = np.floor(np.log2(f / f[0]) / octaves + 1e-9).astype(int)
    n_bands = int(band.max()) + 1
    return np.arange(n_channels)[:, None] * n_bands + band[None, :]


def calibrate_step(residual: np.ndarray, jacobian: np.ndarray, weights: np.ndarray, clusters: np.ndarray,
                   t: np.ndarray, prior_precision: np.ndarray, scale: float = 1.0,
                   ridge: float = 1e-9) -> CalibrationStep:
    """One Gauss-Newton step of the calibration at ``t`` (see the module docstring).

    Minimises Σ W e² / κ + tᵀ Λ t over the step and the channel offsets, the prior Λ = ``prior_precision`` on t
    (nominal at 0), the data's weights divided by the overdispersion κ = ``scale`` (the variance inflation of the
    sandwich over the white-residual covariance: the discrepancy makes the cells count less than they number).
    The covariance is the sandwich of that estimating equation,
    P⁻¹ (M / κ² + Λ) P⁻¹ with P = XᵀWX / κ + Λ and M the clusters' meat.

    :param residual: ``(n_channels, n_freqs)`` dB, ȳ_mes0 − ȳ_sim0(θ) at the current θ.
    :param jacobian: ``(n_channels, n_freqs, p)`` dB per unit of t, ∂ȳ_sim0/∂t at the current θ.
    :param weights: ``(n_channels, n_freqs)`` 1/dB², v0 / Var B (0 where a cell is left out).
    :param clusters: ``(n_channels, n_freqs)`` int, the sandwich's clusters (:func:`octave_clusters`).
    :param t: ``(p,)`` the current point; :param prior_precision: ``(p,)`` Λ's diagonal (0: no prior).
    :param ridge: relative Tikhonov term keeping P invertible along directions nothing informs.
    """
    r = np.asarray(residual, dtype=float)
    Jt = np.asarray(jacobian, dtype=float)
    K, F, p = Jt.shape
    t = np.asarray(t, dtype=float)
    X = np.concatenate([np.repeat(np.eye(K)[:, None, :], F, axis=1), Jt], axis=2).reshape(K * F, -1)
    W = np.asarray(weights, dtype=float).reshape(-1)
    y = r.reshape(-1)
    lam = np.concatenate([np.zeros(K), np.asarray(prior_precision, dtype=float)])
    A = X.T @ (X * W[:, None])
    P = A / scale + np.diag(lam)
    P += ridge * np.trace(P) / P.shape[0] * np.eye(P.shape[0])
    P_inv = np.linalg.inv(P)
    beta = P_inv @ (X.T @ (W * y) / scale - lam * np.concatenate([np.zeros(K), t]))
    e = y - X @ beta
    score = X * (W * e)[:, None]                       # each cell's contribution to the estimating equation
    labels = np.asarray(clusters).reshape(-1)
    sums = np.zeros((labels.max() + 1, X.shape[1]))
    np.add.at(sums, labels, score)
    meat = sums.T @ sums
    cov = P_inv @ (meat / scale ** 2 + np.diag(lam)) @ P_inv
    A_inv = np.linalg.pinv(A)
    w_sum = max(W.sum(), 1e-300)
    return CalibrationStep(beta[K:], cov[K:, K:], np.sqrt(np.clip(np.diag(A_inv)[K:], 0, None)), beta[:K],
                           float(np.sqrt(np.sum(W * e ** 2) / w_sum)), int(np.unique(labels[W > 0]).size))


def implicit_shifts(H_uu: np.ndarray, H_ut: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """du_opt/dt = −H_uu⁻¹ H_ut (implicit-function theorem at a maximum of J), ``(q, p)``.

    H_uu is inverted on its negative-definite part only (as the sandwich of
    :mod:`suspid.method.identifiability`): along a flat or rising direction the
    maximiser is not defined, and the components that span it get NaN rows.

    :param H_uu: ``(q, q)`` Hessian of J in the normalised identified parameters.
    :param H_ut: ``(q, p)`` mixed second derivatives ∂²J/∂u∂t.
    :returns: ``(G (q, p), flat (q,) bool)``.
    """
    H = 0.5 * (np.asarray(H_uu, float) + np.asarray(H_uu, float).T)
    lam, V = np.linalg.eigh(H)
    scale = np.abs(lam).max() if lam.size else 1.0
    ok = lam < -1e-9 * scale
    inv = np.where(ok, 1.0 / np.minimum(lam, -1e-300), 0.0)
    G = -(V * inv) @ V.T @ np.asarray(H_ut, float)
    flat = (np.abs(V[:, ~ok]) > 0.3).any(axis=1) if (~ok).any() else np.zeros(H.shape[0], bool)
    G[flat] = np.nan
    return G, flat
