"""Is the model adequate where a parameter is read? Residuals at w_opt against the noise model B.

Beyond the paper. At the measurement date the modelled process is
Y_mod(w) = Y_sim(w) + B, with B identified at the reference date. If the model
reproduces what changed between the two dates, the mean residual

    r(c, f) = mean_i [y_mes_i(c, f) - y_sim_i(c, f; w_opt)] - μ_B(c, f)

is zero up to sampling, whose scale is set by the spread of the measured
residuals and of B. Where it is not, the model cannot follow the change (a
model-form error), and a parameter whose information about the data comes
mostly from those places is read from the wrong physics: its w_opt is not
to be trusted even if J is sharply peaked there.

The test is made in bands of ``1/bands_per_octave`` octave per channel
(:func:`frequency_bands`), on band averages of the dB spectra, so that the
strong correlation of neighbouring frequencies does not multiply the tests:

    z(c, band) = r̄(c, band) / sqrt(s²_mes / v + a^T C_B a / v0),

s²_mes the sample variance over the v measured segments of the band-averaged
residual, C_B the covariance of B (:meth:`NoiseModel.covariance` in low-rank
form) and a the band-averaging vector. A band is **inadequate** when
|z| > ``z_threshold`` and |r̄| > ``min_db`` (a significant *and* material
discrepancy).

A parameter's information per cell is its spectral sensitivity squared over
B's variance, S_k(c, f)² / Var B(c, f), times the channel weight α_c (the
Fisher information of a Gaussian model with a shifted mean); its
**inadequate share** is the part of that information lying in inadequate
bands (:func:`information_share`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from suspid.method.noise import NoiseModel


def frequency_bands(freqs: np.ndarray, bands_per_octave: float, min_bins: int = 3) -> list[np.ndarray]:
    """Index arrays of ``freqs (n_freqs,)`` Hz grouped in bands of ``1/bands_per_octave`` octave.

    Bands with fewer than ``min_bins`` grid points are merged into the next one
    (the last into the previous one).
    """
    freqs = np.asarray(freqs, float)
    f0 = max(float(freqs[0]), 1e-9)
    edges_idx = np.floor(np.log2(np.maximum(freqs, f0) / f0) * bands_per_octave).astype(int)
    bands, current = [], []
    for label in np.unique(edges_idx):
        current += list(np.flatnonzero(edges_idx == label))
        if len(current) >= min_bins:
            bands.append(np.array(current))
            current = []
    if current:
        if bands:
            bands[-1] = np.concatenate([bands[-1], current])
        else:
            bands.append(np.array(current))
    return bands


@dataclass
class Residuals:
    """Band residuals at w_opt; arrays ``(n_channels, n_bands)``.

    :ivar mean_db: r̄, mean residual after removing μ_B, dB.
    :ivar se_db: its standard error from the measured spread and B's.
    :ivar z: r̄ / se.
    :ivar inadequate: |z| > z_threshold and |r̄| > min_db.
    :ivar bands: the index arrays of the bands on the frequency grid.
    """

    mean_db: np.ndarray
    se_db: np.ndarray
    z: np.ndarray
    inadequate: np.ndarray
    bands: list[np.ndarray]


def band_residuals(y_mes: np.ndarray, y_sim: np.ndarray, noise: NoiseModel, bands: list[np.ndarray],
                   z_threshold: float = 3.0, min_db: float = 0.5, speeds: np.ndarray | None = None) -> Residuals:
    """The band test of the module docstring.

    :param y_mes: ``(v, n_channels, n_freqs)`` dB measured spectra.
    :param y_sim: ``(v, n_channels, n_freqs)`` dB simulated at w_opt on the same segments.
    :param noise: the fitted noise model B (mean, covariance, number of paths v0).
    :param speeds: ``(v,)`` m/s, the segments' speeds: each takes μ_B at its speed (``noise.mean_for``).
    """
    mean_b = noise.mean_[None] if speeds is None else noise.mean_for(speeds)
    d = np.asarray(y_mes, float) - noise.effective(np.asarray(y_sim, float)) - mean_b
    v, n_ch, n_f = d.shape
    # Var of the estimated μ_B averaged over the segments: Σ_g (v_g / v)² / v0_g per unit variance of B
    mu_factor = 1.0 / max(noise.n_samples_, 1)
    if speeds is not None:
        group, counts = noise.speed_group_of(speeds), noise.reference_counts(speeds)
        mu_factor = sum((np.sum(group == g) / v) ** 2 / counts[group == g][0] for g in np.unique(group))
    n_b = len(bands)
    mean, se = np.empty((n_ch, n_b)), np.empty((n_ch, n_b))
    phi = noise.components_.reshape(-1, n_ch, n_f)          # (r, n_ch, n_f)
    lam = (1 - noise.shrinkage_) * noise.eigenvalues_
    for j, idx in enumerate(bands):
        db = d[:, :, idx].mean(axis=2)                      # (v, n_ch)
        mean[:, j] = db.mean(axis=0)
        s2 = db.var(axis=0, ddof=1) if v > 1 else np.zeros(n_ch)
        a = 1.0 / idx.size
        # a^T C_B a per channel: low-rank part plus the diagonal remainder
        proj = phi[:, :, idx].sum(axis=2) * a               # (r, n_ch)
        var_b = (lam[:, None] * proj ** 2).sum(axis=0) + (noise.residual_variance_[:, idx] * a * a).sum(axis=1)
        se[:, j] = np.sqrt(s2 / v + var_b * mu_factor)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(se > 0, mean / se, 0.0)
    inadequate = (np.abs(z) > z_threshold) & (np.abs(mean) > min_db)
    return Residuals(mean, se, z, inadequate, bands)


def information_share(sensitivity: np.ndarray, variance: np.ndarray, weights: np.ndarray,
                      residuals: Residuals) -> tuple[np.ndarray, np.ndarray]:
    """Each parameter's share of information in inadequate bands.

    :param sensitivity: ``(q, n_channels, n_freqs)`` dB per unit of the normalised parameter,
        ∂ mean y_sim / ∂u_k at w_opt.
    :param variance: ``(n_channels, n_freqs)`` dB², Var B.
    :param weights: ``(n_channels,)`` α_k.
    :returns: ``(share (q,), information (q, n_channels, n_bands))``, the information
        normalised per parameter to sum to 1.
    """
    cell = sensitivity ** 2 / np.maximum(variance, 1e-12)[None] * np.asarray(weights, float)[None, :, None]
    info = np.stack([cell[:, :, idx].sum(axis=2) for idx in residuals.bands], axis=2)  # (q, n_ch, n_b)
    total = info.sum(axis=(1, 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        info = np.where(total[:, None, None] > 0, info / total[:, None, None], 0.0)
    share = (info * residuals.inadequate[None]).sum(axis=(1, 2))
    return share, info
