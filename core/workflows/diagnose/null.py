"""The null distributions of the cell statistics: analytic, then calibrated by a parametric bootstrap.

Overview: ``docs/diagnose.md``, "How it works", step 2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .cells import CellGrid

Z95 = 1.959963984540054
"""Two-sided 95 % normal quantile."""


@dataclass
class NullCalibration:
    """The null distributions of the mean, shape and peak statistics of each cell.

    :ivar sd: ``(n_cells,)`` analytic null sd s_c of the cell mean (dB).
    :ivar kappa: ``(n_cells,)`` bootstrap scale κ_c >= 1 of the mean test.
    :ivar shape_scale, shape_dof: ``(n_cells,)`` the shape statistic Q_c is a χ²_ν scaled by a under the null.
    :ivar bin_sd: ``(G, K, F)`` null sd of the mean residual at each bin (dB).
    :ivar bin_kappa: ``(G, K, F)`` bootstrap scale (>= 1) of the bin z-scores, for the peak test.
    :ivar noise_mean: ``(G, K, F)`` dB, μ_B of each speed group (the noise model's mean at that speed).
    :ivar reference_counts: ``(G,)`` the reference-date segments behind each group's μ_B (v0 when pooled).
    """

    sd: np.ndarray
    kappa: np.ndarray
    shape_scale: np.ndarray
    shape_dof: np.ndarray
    bin_sd: np.ndarray
    n_bootstrap: int
    bin_kappa: np.ndarray | float = 1.0
    kappa_raw: np.ndarray | None = None
    null_rate: float | None = None
    noise_mean: np.ndarray | None = None
    reference_counts: np.ndarray | None = None

    @property
    def scale(self) -> np.ndarray:
        """κ_c s_c, the calibrated null standard deviation of the cell mean (dB)."""
        return self.sd * self.kappa


def _band_variances(grid: CellGrid, noise_model) -> tuple[np.ndarray, np.ndarray]:
    """Var of a band average ``(K, B)`` and Σ_f,f' R² within each band ``(K, B)`` (R: bin correlations),
    from the noise covariance (low rank plus diagonal, never formed densely)."""
    K, F = len(grid.channels), grid.freqs.size
    comps = noise_model.components_.reshape(-1, K, F)                  # (r, K, F)
    lam = (1.0 - noise_model.shrinkage_) * noise_model.eigenvalues_    # (r,)
    d = noise_model.residual_variance_                                # (K, F)
    P = np.einsum("rkf,fb->rkb", comps, grid.average)
    var_mean = np.einsum("r,rkb->kb", lam, P * P) + d @ (grid.average ** 2)
    # tr(R_band²) with R = S^-1/2 C S^-1/2, C = Φᵀ Λ Φ + diag(d), S = diag(C)
    sd = np.sqrt(np.maximum(noise_model.variance_, 1e-30))
    Phi = comps / sd[None]                                             # scaled components (r, K, F)
    dd = d / sd ** 2                                                  # (K, F)
    tr2 = np.zeros((K, grid.average.shape[1]))
    for b in range(grid.average.shape[1]):
        idx = grid.average[:, b] > 0
        A = Phi[:, :, idx]                                            # (r, K, n_b)
        gram = np.einsum("rkf,skf->krs", A, A)                         # (K, r, r)
        low = np.einsum("r,krs,s->k", lam, gram * gram, lam) if lam.size else np.zeros(K)
        cross = 2 * np.einsum("r,rkf->k", lam, A * A * dd[None, :, idx])
        tr2[:, b] = low + cross + np.sum(dd[:, idx] ** 2, axis=1)
    return var_mean, tr2


def _counts(grid: CellGrid) -> np.ndarray:
    return np.array([np.sum(grid.group_of == g) for g in range(len(grid.speeds))], dtype=float)


def _reference(grid: CellGrid, noise_model) -> tuple[np.ndarray, np.ndarray]:
    """μ_B ``(G, K, F)`` and the reference-date segments behind it ``(G,)`` at each speed group's speed (the
    noise model's speed groups where it has them: ``mean_for``; else its one mean and v0)."""
    return noise_model.mean_for(grid.speeds), noise_model.reference_counts(grid.speeds).astype(float)


def analytic_null(grid: CellGrid, noise_model) -> NullCalibration:
    """The analytic null: s_c of the band mean, and Q_c ~ a χ²_ν by Satterthwaite (E Q = n_b, Var Q = 2 tr R²).

    Per speed group g the residual's mean over v_g segments minus the estimate of μ_B from v0_g reference
    segments (its speed group's, or all v0) has the variance of B times 1/v_g + 1/v0_g."""
    mu, v0 = _reference(grid, noise_model)
    factor = 1.0 / _counts(grid) + 1.0 / v0                           # (G,)
    var_mean, tr2 = _band_variances(grid, noise_model)
    n_b = (grid.average > 0).sum(axis=0).astype(float)                # (B,)
    sd = np.concatenate([np.sqrt(var_mean * f).ravel() for f in factor])
    a = np.tile((tr2 / n_b).ravel(), len(factor))
    dof = np.tile((n_b ** 2 / tr2).ravel(), len(factor))
    bin_sd = np.sqrt(noise_model.variance_[None] * factor[:, None, None])
    return NullCalibration(sd, np.ones_like(sd), a, dof, bin_sd, 0, noise_mean=mu, reference_counts=v0)


def shape_statistic(grid: CellGrid, r_bar: np.ndarray, bin_sd: np.ndarray) -> np.ndarray:
    """Q_c = Σ_{f in band} (r̄_f / σ_f)² per cell, from bin means ``r_bar`` and null sds ``bin_sd`` ``(G, K, F)``."""
    return (((r_bar / bin_sd) ** 2) @ (grid.average > 0)).ravel()


def calibrate_null(grid: CellGrid, noise_model, n_bootstrap: int, rng: np.random.Generator) -> NullCalibration:
    """The analytic null calibrated by ``n_bootstrap`` parametric-bootstrap replicates (0: the analytic null).

    Sets κ_c, κ_f (floored at 1), a_c and ν_c from the replicates; ``rng`` draws them. A replicate draws v0
    reference paths; a speed group's μ_B is estimated from v0_g of them, as the analysis estimates it.
    """
    null = analytic_null(grid, noise_model)
    if n_bootstrap <= 0:
        return null
    v0 = noise_model.n_samples_
    v0_g = null.reference_counts.astype(int)                          # (G,)
    v = grid.group_of.size
    factor = 1.0 / _counts(grid) + 1.0 / v0_g
    z = np.empty((n_bootstrap, null.sd.size))
    Q = np.empty((n_bootstrap, null.sd.size))
    z2_bin = np.zeros(null.bin_sd.shape)
    chunk = max(1, min(n_bootstrap, 2_000_000 // ((v0 + v) * noise_model.mean_.size)))
    draws = None
    for b in range(n_bootstrap):
        if b % chunk == 0:   # one large draw per chunk of replicates: a few big products instead of many small
            n = min(chunk, n_bootstrap - b)
            draws = noise_model.sample(n * (v0 + v), rng).reshape((n, v0 + v) + noise_model.mean_.shape)
        b0, bm = draws[b % chunk, :v0], draws[b % chunk, v0:]
        dev = b0 - b0.mean(axis=0)
        var_bin = (dev ** 2).sum(axis=0) / (v0 - 1)                       # (K, F)
        var_band = ((dev @ grid.average) ** 2).sum(axis=0) / (v0 - 1)     # (K, B)
        mu = np.array([b0[:n].mean(axis=0) for n in v0_g])               # (G, K, F)
        r_bar = grid.group_means(bm) - mu
        sd = np.concatenate([np.sqrt(var_band * f).ravel() for f in factor])
        z[b] = (r_bar @ grid.average).ravel() / sd
        bin_sd = np.sqrt(var_bin[None] * factor[:, None, None])
        Q[b] = shape_statistic(grid, r_bar, bin_sd)
        z2_bin += (r_bar / bin_sd) ** 2
    raw = np.sqrt(np.mean(z * z, axis=0))
    kappa = np.maximum(raw, 1.0)
    mean_q, var_q = Q.mean(axis=0), Q.var(axis=0, ddof=1)
    a = var_q / (2 * mean_q)
    dof = 2 * mean_q ** 2 / var_q
    null_rate = float(np.mean(np.abs(z / kappa) > Z95))
    bin_kappa = np.maximum(np.sqrt(z2_bin / n_bootstrap), 1.0)
    return NullCalibration(null.sd, kappa, a, dof, null.bin_sd, n_bootstrap, bin_kappa=bin_kappa, kappa_raw=raw,
                           null_rate=null_rate, noise_mean=null.noise_mean, reference_counts=null.reference_counts)
