"""The discrepancy workflow (issue 8): locate, name, add, re-identify (``suspid diagnose``).

An identification is only as good as its model: discrepancy a model ignores
is silently absorbed into the physical parameters (Kennedy and O'Hagan 2001;
Brynjarsdóttir and O'Hagan 2014). This workflow finds where the model and
the measurements disagree, names the physical effect that is missing (from
the effect registry, ``railway-data.md`` §3), adds it to the model and shows
the gap shrink.

1. **Base model.** The config's model at the identified parameters (a
   ``suspid run`` in ``<run dir>/before/``; ``diagnose.at: identified``) or at
   the nominal ones (``at: nominal``).

2. **Locate.** Residuals r_i = y_mes_i - y_sim_i(w) - μ_B (dB, segment i, μ_B
   the noise model's mean), averaged over the segments of each speed group:
   r̄ per (group, channel, frequency bin). *Cells*: speed group × channel ×
   band, bands of ``1/bands_per_octave`` octave merged until each holds
   ``min_bins_per_band`` bins (a single bin's log spectrum scatters by about
   2.8 dB: bins are aggregated). Two statistics per cell:

   - the *mean test*: the band mean m_c of r̄ (a broad shift, e.g. a missing
     resonance); null N(0, s_c²) with s_c² = u_cᵀ Σ_B u_c (1/v_g + 1/v0):
     Σ_B the noise covariance (low rank plus diagonal, never formed densely),
     u_c the band average, v_g the group's segments, v0 the reference-date
     paths (μ_B is estimated from them);
   - the *shape test*: Q_c = Σ_f (r̄_f / σ_f)² over the band's bins (a change
     of shape, e.g. a resonance that moved, where a band mean cancels); null
     a χ²_ν scaled by a (Satterthwaite: the bins are correlated through B);
   - the *peak test*: the largest |r̄_f| / σ_f of the band (a narrow line,
     e.g. a wheel polygon's, which both other statistics dilute); p by
     Bonferroni over the band's bins (conservative under their correlation).

   The nulls hold when the measurements are Y_mod = y_sim + B. *Calibration
   by parametric bootstrap* (``n_bootstrap`` replicates): draw v0 reference
   paths and v measured residuals from the noise model and compute both
   statistics with the replicate's own estimates of μ_B and of the
   covariance; the RMS of the replicate z-scores per cell, κ_c (floored at 1:
   never less conservative than the analytic null), scales s_c (and likewise
   per bin for the peak test), and a_c, ν_c match the replicates' mean and
   variance of Q_c. p_c = min(1, 3 min(p_mean, p_shape, p_peak)) (Bonferroni
   over the three). *False discoveries* over all cells: Benjamini-Yekutieli (valid
   under any dependence; the cells are correlated through B),
   ``scipy.stats.false_discovery_control(p, "by")``; a cell is flagged when
   its adjusted p-value is below ``alpha``. The map reports each cell's sign
   and magnitude in dB (the band mean where the mean test decided, else the
   most deviant bin). Gap measures: the share of flagged cells, and the
   integrated discrepancy Σ Δf max(0, |r̄_f| - t σ_f) in dB·Hz over every
   channel and bin (t the two-sided 5 % Bonferroni bound over all bins: 0
   under the null with probability 95 %). With an identified model the null
   is conservative (w was fitted to these data).

3. **Name.** Every registered effect the simulator supports is a candidate.
   Its signature must cover at least one flagged cell (channel, band at the
   cell's speed), else it is ranked "excluded by signature". A candidate's
   parameters are fitted by minimising the discrepancy D = Σ (m / σ)² over
   all channels and frequencies: its ``candidates()`` give starting points (discrete
   choices such as a polygon's order and wheelset, and grid values of the
   main parameter, from the flagged cells and the speeds), each evaluated
   with one simulator call on the segments, then the best ``n_starts`` are
   refined by Nelder-Mead on the continuous ``fitted`` parameters (normalised
   to their bounds, log scale where declared). D is evaluated per frequency
   bin, not per band (:class:`Discrepancy`: the fit of a frequency needs the
   grid's resolution). Score = ΔD - p ln(n) with n the number of (group,
   channel, bin) terms (a BIC-type penalty, p = continuous plus discrete
   parameters). The
   *generic bump* of the same size p is a Gaussian bump in log-frequency added
   in dB to the flagged channels (amplitude; centre; width; further
   amplitudes for the most discrepant channels), fitted by least squares with
   the same D. Data at several speeds enter jointly: an effect is simulated at
   each segment's speed (a polygon moves ∝ v, a mode stays), while the bump
   stays at one frequency in Hz. The winner is **named** only when (i) cells
   are flagged, (ii) it beats the runner-up effect and (iii) the bump of its
   size by at least ``margin`` in score, and (iv) it explains at least
   ``min_explained`` of D in the flagged cells. Otherwise the report gives an
   unexplained discrepancy with its map. ΔJ (the run's objective) is reported
   for each fitted candidate.

4. **Add and re-identify.** ``augmented.yaml``: the config with the named
   effect and its fitted parameters under ``simulator.options.effects``, the
   noise model of the base run (``noise.path``, so the measurements and B are
   unchanged), run again (``after/``) when ``reidentify``; the map is computed
   again with the augmented model at its identified (or nominal) parameters.

Outputs in the run directory: ``diagnosis.json`` (``flagged``, ``ranking``,
``named``, ``gap_before``, ``gap_after``, ``augmented_config``, the maps),
``diagnosis.md`` with ``diagnosis_map_before.png``, ``diagnosis_map_after.png``
and ``diagnosis_spectra.png``.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import yaml

from suspid import registry
from suspid.config import Config, load_config, validate_options
from suspid.errors import ConfigError, SimulatorError, UnknownPluginError
from suspid.infra.files import pyplot, save_figure, write_json, write_text
from suspid.infra.ledger import Ledger
from suspid.infra.seeds import rng as named_rng
from suspid.infra.threads import single_blas_thread
from suspid.sections import DiagnoseOptions, OutputSection
from suspid.workflows.evaluation import j_of_spectra
from suspid.workflows.identify import run
from suspid.workflows.problem import build_problem, simulate_spectra
from suspid.workflows.report import markdown_table

Z95 = 1.959963984540054
"""Two-sided 95 % normal quantile."""


# ====================================================================================== cells
@dataclass
class CellGrid:
    """Cells: speed group × channel × band, flattened in that order.

    :ivar speeds: ``(G,)`` m/s of the speed groups; :ivar group_of: ``(v,)`` group of each segment.
    :ivar band_edges: ``(B, 2)`` Hz; :ivar average: ``(F, B)`` band-average matrix over the grid Ω.
    """

    channels: list[str]
    freqs: np.ndarray
    speeds: np.ndarray
    group_of: np.ndarray
    band_edges: np.ndarray
    average: np.ndarray

    @property
    def n_cells(self) -> int:
        return len(self.speeds) * len(self.channels) * self.band_edges.shape[0]

    def index(self, c: int) -> tuple[int, int, int]:
        """(group, channel, band) of cell ``c``."""
        K, B = len(self.channels), self.band_edges.shape[0]
        return c // (K * B), (c // B) % K, c % B

    def group_means(self, r: np.ndarray) -> np.ndarray:
        """``(G, K, F)``: mean of ``r`` ``(v, K, F)`` over each group's segments."""
        return np.array([r[self.group_of == g].mean(axis=0) for g in range(len(self.speeds))])

    def cell_means(self, r: np.ndarray) -> np.ndarray:
        """``(n_cells,)``: mean of ``r`` ``(v, K, F)`` over each group's segments and each band."""
        return (self.group_means(r) @ self.average).ravel()

    def cell_to_bins(self, values: np.ndarray) -> np.ndarray:
        """``(G, K, F)``: each bin takes the value of its cell (``values`` ``(n_cells,)``)."""
        G, K, B = len(self.speeds), len(self.channels), self.band_edges.shape[0]
        band_of_bin = np.argmax(self.average > 0, axis=1)
        return values.reshape(G, K, B)[:, :, band_of_bin]


def make_cells(channels: Sequence[str], freqs: np.ndarray, segment_speeds: Sequence[float],
               bands_per_octave: float = 3.0, min_bins: int = 3) -> CellGrid:
    """Bands of constant relative width over the grid ``freqs`` (Hz), each with at least ``min_bins`` bins."""
    f = np.asarray(freqs, dtype=float)
    half = np.diff(f) / 2
    lower = np.concatenate([[f[0] - half[0]], f[:-1] + half])
    upper = np.concatenate([f[:-1] + half, [f[-1] + half[-1]]])
    lower = np.maximum(lower, 0.0)
    ratio = 2.0 ** (1.0 / bands_per_octave)
    band_of = np.floor(np.log(f / f[0]) / np.log(ratio) + 1e-9).astype(int)
    groups: list[list[int]] = []
    for b in np.unique(band_of):
        idx = list(np.nonzero(band_of == b)[0])
        if groups and len(groups[-1]) < min_bins:
            groups[-1] += idx
        else:
            groups.append(idx)
    if len(groups) > 1 and len(groups[-1]) < min_bins:
        groups[-2] += groups.pop()
    average = np.zeros((f.size, len(groups)))
    edges = np.zeros((len(groups), 2))
    for b, idx in enumerate(groups):
        average[idx, b] = 1.0 / len(idx)
        edges[b] = lower[idx[0]], upper[idx[-1]]
    speeds_all = np.round(np.asarray(segment_speeds, dtype=float), 3)
    speeds = np.unique(speeds_all)
    group_of = np.searchsorted(speeds, speeds_all)
    return CellGrid(list(channels), f, speeds, group_of, edges, average)


# ====================================================================================== null
@dataclass
class NullCalibration:
    """The null distributions of the two statistics of each cell (see :func:`locate`).

    :ivar sd: ``(n_cells,)`` analytic null sd s_c of the cell mean (dB).
    :ivar kappa: ``(n_cells,)`` bootstrap scale κ_c >= 1 of the mean test.
    :ivar shape_scale, shape_dof: ``(n_cells,)`` the shape statistic Q_c is a χ²_ν scaled by a under the null.
    :ivar bin_sd: ``(G, K, F)`` null sd of the mean residual at each bin (dB).
    :ivar bin_kappa: ``(G, K, F)`` bootstrap scale (>= 1) of the bin z-scores, for the peak test.
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


def analytic_null(grid: CellGrid, noise_model) -> NullCalibration:
    """The analytic null: s_c of the band mean, and Q_c ~ a χ²_ν by Satterthwaite (E Q = n_b, Var Q = 2 tr R²)."""
    v0 = noise_model.n_samples_
    factor = 1.0 / _counts(grid) + 1.0 / v0                           # (G,)
    var_mean, tr2 = _band_variances(grid, noise_model)
    n_b = (grid.average > 0).sum(axis=0).astype(float)                # (B,)
    sd = np.concatenate([np.sqrt(var_mean * f).ravel() for f in factor])
    a = np.tile((tr2 / n_b).ravel(), len(factor))
    dof = np.tile((n_b ** 2 / tr2).ravel(), len(factor))
    bin_sd = np.sqrt(noise_model.variance_[None] * factor[:, None, None])
    return NullCalibration(sd, np.ones_like(sd), a, dof, bin_sd, 0)


def shape_statistic(grid: CellGrid, r_bar: np.ndarray, bin_sd: np.ndarray) -> np.ndarray:
    """Q_c = Σ_{f in band} (r̄_f / σ_f)² per cell, from bin means ``r_bar`` and null sds ``bin_sd`` ``(G, K, F)``."""
    return (((r_bar / bin_sd) ** 2) @ (grid.average > 0)).ravel()


def calibrate_null(grid: CellGrid, noise_model, n_bootstrap: int, rng: np.random.Generator) -> NullCalibration:
    """The analytic null, calibrated by a parametric bootstrap (module docstring, step 2).

    Each replicate draws v0 reference paths b0 from the noise model and v
    measured residuals from it, and computes both statistics as the analysis
    does, with the replicate's own estimates: its sample mean for μ_B and its
    sample covariance (what the noise model keeps, up to its truncation and
    shrinkage) for the null sds. The mean test's scale κ_c is the RMS of the
    replicate z-scores (floored at 1); the shape statistic's a_c and ν_c match
    the replicates' mean and variance of Q_c.
    """
    null = analytic_null(grid, noise_model)
    if n_bootstrap <= 0:
        return null
    v0 = noise_model.n_samples_
    v = grid.group_of.size
    factor = 1.0 / _counts(grid) + 1.0 / v0
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
        mu = b0.mean(axis=0)
        dev = b0 - mu
        var_bin = (dev ** 2).sum(axis=0) / (v0 - 1)                       # (K, F)
        var_band = ((dev @ grid.average) ** 2).sum(axis=0) / (v0 - 1)     # (K, B)
        r_bar = grid.group_means(bm - mu[None])
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
                           null_rate=null_rate)


# ====================================================================================== locate
@dataclass
class DiscrepancyMap:
    """Per cell: the two tests, the BY-adjusted q and the flag; see :func:`locate`.

    :ivar mean_db: band mean of the residual (dB); :ivar peak_db: the residual at the band's most
        deviant bin (dB); :ivar magnitude_db: the magnitude of what was detected: ``mean_db`` where the
        mean test is the more significant, else ``peak_db``.
    :ivar p_mean, p_shape, p_peak: p of the three tests; :ivar p: 3 min of them (Bonferroni).
    :ivar bin_residual: ``(G, K, F)`` mean residual per bin (dB), :ivar bin_sd: its null sd.
    """

    grid: CellGrid
    mean_db: np.ndarray
    peak_db: np.ndarray
    scale_db: np.ndarray
    p_mean: np.ndarray
    p_shape: np.ndarray
    p_peak: np.ndarray
    p: np.ndarray
    q: np.ndarray
    flagged: np.ndarray
    bin_residual: np.ndarray
    bin_sd: np.ndarray
    J: float | None = None

    @property
    def test(self) -> np.ndarray:
        """The deciding test of each cell: ``mean``, ``shape`` or ``peak``."""
        stack = np.array([self.p_mean, self.p_shape, self.p_peak])
        return np.array(["mean", "shape", "peak"])[np.argmin(stack, axis=0)]

    @property
    def magnitude_db(self) -> np.ndarray:
        return np.where(self.test == "mean", self.mean_db, self.peak_db)

    @property
    def z(self) -> np.ndarray:
        """The mean test's z-score (signed)."""
        return self.mean_db / self.scale_db

    @property
    def evidence(self) -> np.ndarray:
        """-log10 p of each cell (what the maps and rankings of channels use)."""
        return -np.log10(np.maximum(self.p, 1e-300))

    @property
    def share_flagged(self) -> float:
        return float(np.mean(self.flagged))

    @property
    def integrated_db_hz(self) -> float:
        """Integrated discrepancy, dB·Hz: Σ over channels and bins of Δf max(0, |r̄_f| - t σ_f), averaged over
        speed groups; t the two-sided Bonferroni bound over all bins at 5 % (under the null the sum is 0 with
        probability 95 %)."""
        from scipy.stats import norm

        t = norm.isf(0.025 / self.bin_residual.size)
        df = np.gradient(self.grid.freqs) if self.grid.freqs.size > 1 else np.ones(1)
        excess = np.maximum(0.0, np.abs(self.bin_residual) - t * self.bin_sd)
        return float(np.sum(excess * df[None, None]) / len(self.grid.speeds))

    def rows(self, only_flagged: bool = False) -> list[dict[str, Any]]:
        out = []
        magnitude, test = self.magnitude_db, self.test
        for c in range(self.grid.n_cells):
            if only_flagged and not self.flagged[c]:
                continue
            g, k, b = self.grid.index(c)
            lo, hi = self.grid.band_edges[b]
            out.append({"channel": self.grid.channels[k], "f_low_hz": round(float(lo), 4),
                        "f_high_hz": round(float(hi), 4), "speed_kmh": round(float(self.grid.speeds[g] * 3.6), 3),
                        "sign": "+" if magnitude[c] > 0 else "-", "magnitude_db": round(float(magnitude[c]), 4),
                        "mean_db": round(float(self.mean_db[c]), 4), "peak_db": round(float(self.peak_db[c]), 4),
                        "test": str(test[c]), "z": round(float(self.z[c]), 3), "p": float(self.p[c]),
                        "q": float(self.q[c]), "flagged": bool(self.flagged[c])})
        return out

    def gap(self) -> dict[str, Any]:
        return {"share_flagged": self.share_flagged, "n_flagged": int(self.flagged.sum()),
                "n_cells": int(self.grid.n_cells), "integrated_db_hz": self.integrated_db_hz, "J": self.J}

    def flagged_cells(self) -> list[tuple[str, float, float, float]]:
        """``(channel, f_low, f_high, speed_mps)`` of the flagged cells (what effects' candidates read)."""
        out = []
        for c in np.nonzero(self.flagged)[0]:
            g, k, b = self.grid.index(int(c))
            out.append((self.grid.channels[k], float(self.grid.band_edges[b, 0]), float(self.grid.band_edges[b, 1]),
                        float(self.grid.speeds[g])))
        return out


def locate(grid: CellGrid, null: NullCalibration, y_mes: np.ndarray, y_sim: np.ndarray, noise_mean: np.ndarray,
           alpha: float = 0.05) -> DiscrepancyMap:
    """The discrepancy map (module docstring, step 2).

    Three tests per cell on the residual r = y_mes - y_sim - μ_B: the *mean
    test* (band mean m_c against N(0, κ_c² s_c²): a broad shift, e.g. a
    missing resonance), the *shape test* (Q_c = Σ_f (r̄_f / σ_f)² over the
    band's bins against a_c χ²_ν_c: a moved resonance) and the *peak test*
    (the largest |r̄_f| / (κ_f σ_f), Bonferroni over the band's bins: a narrow
    line such as a wheel polygon's); p_c = min(1, 3 min(p_mean, p_shape,
    p_peak)), then Benjamini-Yekutieli over all cells.

    :param y_mes, y_sim: ``(v, n_channels, n_freqs)`` dB on the same segments, in the same order.
    :param noise_mean: ``(n_channels, n_freqs)`` dB, μ_B.
    """
    from scipy.stats import chi2, false_discovery_control, norm

    r_bar = grid.group_means(y_mes - y_sim - noise_mean[None])             # (G, K, F)
    mean = (r_bar @ grid.average).ravel()
    scale = null.scale
    p_mean = np.clip(2.0 * norm.sf(np.abs(mean) / scale), 1e-300, 1.0)
    Q = shape_statistic(grid, r_bar, null.bin_sd)
    p_shape = np.clip(chi2.sf(Q / null.shape_scale, null.shape_dof), 1e-300, 1.0)
    # the most deviant bin of each band, and the peak test
    z_bin = np.abs(r_bar / (null.bin_sd * null.bin_kappa))
    G, K, B = len(grid.speeds), len(grid.channels), grid.band_edges.shape[0]
    peak = np.empty((G, K, B))
    p_peak = np.empty((G, K, B))
    for b in range(B):
        idx = np.nonzero(grid.average[:, b] > 0)[0]
        j = idx[np.argmax(z_bin[:, :, idx], axis=2)]                        # (G, K)
        peak[:, :, b] = np.take_along_axis(r_bar, j[:, :, None], axis=2)[:, :, 0]
        z_max = np.take_along_axis(z_bin, j[:, :, None], axis=2)[:, :, 0]
        p_peak[:, :, b] = np.minimum(1.0, idx.size * 2.0 * norm.sf(z_max))
    p_peak = np.clip(p_peak.ravel(), 1e-300, 1.0)
    p = np.minimum(1.0, 3.0 * np.minimum(np.minimum(p_mean, p_shape), p_peak))
    q = false_discovery_control(p, method="by")
    return DiscrepancyMap(grid, mean, peak.ravel(), scale, p_mean, p_shape, p_peak, p, q, q < alpha, r_bar,
                          null.bin_sd)


# ====================================================================================== name
@dataclass
class Candidate:
    """One ranked explanation: an effect with fitted parameters, or the generic bump."""

    effect: str
    status: str
    n_parameters: int = 0
    parameters: dict[str, Any] = field(default_factory=dict)
    D: float = math.inf
    delta_D: float = -math.inf
    delta_D_flagged: float = -math.inf
    explained: float = 0.0
    score: float = -math.inf
    delta_J: float | None = None
    evaluations: int = 0
    signature: dict[str, Any] | None = None
    y_sim: np.ndarray | None = None

    def as_dict(self) -> dict[str, Any]:
        def num(x):
            return None if x is None or not math.isfinite(x) else round(float(x), 6)

        return {"effect": self.effect, "status": self.status, "score": num(self.score),
                "parameters": _jsonable(self.parameters), "n_parameters": self.n_parameters,
                "D": num(self.D), "delta_D": num(self.delta_D), "delta_D_flagged": num(self.delta_D_flagged),
                "explained": num(self.explained), "delta_J": num(self.delta_J), "evaluations": self.evaluations,
                "signature": self.signature}


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    return value


class Discrepancy:
    """D = Σ (m / σ)² over every (speed group, channel, frequency bin), and over the bins of the flagged cells.

    m = mean over the group's segments of y_mes - y_sim - μ_B (dB) at each grid
    frequency, σ² = Var B (1/v_g + 1/v0) its null variance (the noise model's
    marginal variance). Bins,
    not bands: the fit of a frequency needs the grid's resolution; the bands
    serve the tests of :func:`locate`. ``D0`` and ``D0_flagged`` are the base
    model's (``y_base``).
    """

    def __init__(self, grid: CellGrid, null: NullCalibration, y_mes: np.ndarray, noise_model,
                 flagged: np.ndarray, y_base: np.ndarray) -> None:
        self.grid = grid
        self.target = grid.group_means(y_mes - noise_model.mean_[None])          # m = target - mean(y_sim)
        self.scale = null.bin_sd
        self.flagged = grid.cell_to_bins(flagged.astype(float)) > 0
        self.base_means = grid.group_means(y_base)
        self.D0, self.D0_flagged = self.of_means(self.target - self.base_means)

    @property
    def n_terms(self) -> int:
        return int(self.target.size)

    def of_means(self, m: np.ndarray) -> tuple[float, float]:
        z2 = (m / self.scale) ** 2
        return float(z2.sum()), float(z2[self.flagged].sum())

    def __call__(self, y_sim: np.ndarray) -> tuple[float, float]:
        return self.of_means(self.target - self.grid.group_means(y_sim))


class EffectFitter:
    """Fits effects' parameters to the measurements at fixed suspension parameters ``w`` (frequency solver)."""

    def __init__(self, config: Config, problem, w: dict[str, float], discrepancy: Discrepancy,
                 flagged: list[tuple[str, float, float, float]], options: DiagnoseOptions,
                 log: Callable[[str], None] = lambda s: None) -> None:
        self.config, self.problem, self.w, self.disc, self.flagged, self.opts, self.log = (
            config, problem, dict(w), discrepancy, flagged, options, log)
        self.sim_cls = type(problem.simulator)
        self.file = str(config.source_file)
        self._sims: dict[str, Any] = {}
        self.evaluations = 0

    def simulator_with(self, spec: dict[str, Any]):
        """The configured simulator with one more effect ``spec`` (validated; cached by spec)."""
        key = json.dumps(_jsonable(spec), sort_keys=True)
        if key not in self._sims:
            options = dict(self.config.simulator.options)
            options["effects"] = list(options.get("effects") or []) + [spec]
            validated = validate_options(self.sim_cls, options, file=self.file, key="simulator.options")
            self._sims[key] = self.sim_cls(**validated)
        return self._sims[key]

    def simulate(self, sim, w_effect: dict[str, float]) -> np.ndarray | None:

        self.evaluations += 1
        try:
            return simulate_spectra(sim, self.w | w_effect, self.problem.segments, self.config.spectra)[0]
        except SimulatorError:
            return None       # e.g. an unstable vehicle: not a candidate there

    def fit(self, cls) -> Candidate:
        """Fit one effect class (see the module docstring, step 3)."""
        effect = cls()
        speeds = sorted({float(s.mean_speed) for s in self.problem.segments})
        sigs = {f"{v * 3.6:.1f} km/h": _signature_dict(effect.signature(v)) for v in speeds}
        matching = [(ch, lo, hi, v) for ch, lo, hi, v in self.flagged
                    if effect.signature(v).matches_channel(ch) and effect.signature(v).overlaps(lo, hi)]
        if not matching:
            return Candidate(cls.name, "excluded by signature (no flagged cell in its channels and band)",
                             signature=sigs)
        starts = effect.candidates(speeds, self.flagged, self.problem.channels)
        if not starts:
            return Candidate(cls.name, "no starting point in the flagged cells", signature=sigs)
        defaults = cls.defaults()
        fitted = list(cls.fitted)
        structural = sorted({k for s in starts for k in s if k not in fitted})
        n_params = len(fitted) + len(structural)
        transforms = [_Transform(cls, p) for p in fitted]
        n0 = self.evaluations
        # 1. every starting point
        evaluated = []
        for start in starts:
            spec = {"name": cls.name, **defaults, **{k: start[k] for k in structural if k in start}}
            try:
                sim = self.simulator_with(spec)
            except ConfigError:
                continue
            x = np.array([start.get(p, defaults[p]) for p in fitted], dtype=float)
            y = self.simulate(sim, self._w_effect(cls.name, fitted, x))
            if y is not None:
                evaluated.append((self.disc(y)[0], spec, x, y))
        if not evaluated:
            return Candidate(cls.name, "failed: no starting point could be simulated", n_params, signature=sigs,
                             evaluations=self.evaluations - n0)
        evaluated.sort(key=lambda e: e[0])
        # 2. refine the best starts on the continuous parameters
        best = evaluated[0]
        for D0, spec, x0, y0 in evaluated[: self.opts.n_starts]:
            if not fitted:
                continue
            result = self._refine(cls.name, fitted, transforms, spec, x0, D0, y0)
            if result[0] < best[0]:
                best = result
        D, spec, x, y = best
        params = dict(spec)
        params.pop("name")
        params.update({p: float(v) for p, v in zip(fitted, x)})
        D_all, D_f = self.disc(y)
        return Candidate(cls.name, "fitted", n_params, params, D_all, evaluations=self.evaluations - n0,
                         signature=sigs, y_sim=y, delta_D_flagged=self.disc.D0_flagged - D_f)

    @staticmethod
    def _w_effect(name: str, fitted: list[str], x: np.ndarray) -> dict[str, float]:
        return {f"{name}/{p}": float(v) for p, v in zip(fitted, x)}

    def _refine(self, name, fitted, transforms, spec, x0, D0, y0):
        from scipy.optimize import minimize

        sim = self.simulator_with(spec)
        u0 = np.array([t.to_unit(v) for t, v in zip(transforms, x0)])
        cache: dict[tuple, tuple[float, np.ndarray | None]] = {}

        def objective(u):
            u = np.clip(u, 0.0, 1.0)
            key = tuple(np.round(u, 10))
            if key not in cache:
                x = np.array([t.from_unit(ui) for t, ui in zip(transforms, u)])
                y = self.simulate(sim, self._w_effect(name, fitted, x))
                cache[key] = (math.inf if y is None else self.disc(y)[0], y)
            return cache[key][0]

        cache[tuple(np.round(np.clip(u0, 0, 1), 10))] = (D0, y0)
        simplex = [u0] + [np.clip(u0 + 0.04 * e * (1 if u0[i] < 0.5 else -1), 0, 1)
                          for i, e in enumerate(np.eye(len(u0)))]
        res = minimize(objective, u0, method="Nelder-Mead",
                       options={"initial_simplex": np.array(simplex), "maxfev": self.opts.max_evaluations,
                                "xatol": 2e-3, "fatol": 1e-3 * max(D0, 1.0)})
        u = np.clip(res.x, 0.0, 1.0)
        D, y = cache.get(tuple(np.round(u, 10)), (math.inf, None))
        if y is None or D > D0:
            return D0, spec, x0, y0
        return D, spec, np.array([t.from_unit(ui) for t, ui in zip(transforms, u)]), y


class _Transform:
    """A fitted parameter <-> [0, 1] (linear or log between its bounds)."""

    def __init__(self, cls, parameter: str) -> None:
        self.lo, self.hi = cls.bounds(parameter)
        self.log = cls.log_scale(parameter) and self.lo > 0
        if not (math.isfinite(self.lo) and math.isfinite(self.hi)):
            raise ConfigError(f"effect {cls.name}: fitted parameter '{parameter}' needs finite bounds (ge/le)")

    def to_unit(self, v: float) -> float:
        v = min(max(float(v), self.lo), self.hi)
        if self.log:
            return math.log(v / self.lo) / math.log(self.hi / self.lo)
        return (v - self.lo) / (self.hi - self.lo)

    def from_unit(self, u: float) -> float:
        u = min(max(float(u), 0.0), 1.0)
        if self.log:
            return self.lo * (self.hi / self.lo) ** u
        return self.lo + u * (self.hi - self.lo)


def _signature_dict(sig) -> dict[str, Any]:
    lo, hi = sig.band_hz
    return {"bodies": list(sig.bodies), "directions": list(sig.directions),
            "band_hz": [round(float(lo), 3), None if not math.isfinite(hi) else round(float(hi), 3)],
            "speed_dependence": sig.speed_dependence}


def fit_bump(disc: Discrepancy, dmap: DiscrepancyMap, n_parameters: int) -> Candidate:
    """The generic discrepancy bump with ``n_parameters`` parameters (see the module docstring, step 3).

    bump(k, f) = a_g(k) exp(-½ (log2(f / f_c) / w)²) dB on the flagged channels:
    p = 1: one amplitude, f_c at the most significant flagged cell, w = 1/6 octave;
    p = 2: f_c free too; p >= 3: w free too, and p - 2 amplitude groups (the
    most discrepant flagged channels get their own, the others share the last).
    Amplitudes by weighted least squares; f_c and w on grids.
    """
    grid = disc.grid
    G, K = len(grid.speeds), len(grid.channels)
    flagged_c = np.nonzero(dmap.flagged)[0]
    if flagged_c.size == 0:
        return Candidate("generic-bump", "nothing flagged", n_parameters)
    per_channel: dict[int, float] = {}
    for c in flagged_c:
        k = grid.index(int(c))[1]
        per_channel[k] = per_channel.get(k, 0.0) + float(dmap.evidence[c])
    order = sorted(per_channel, key=lambda k: -per_channel[k])
    n_amp = max(1, n_parameters - 2)
    groups = [[k] for k in order[: n_amp - 1]] + [order[n_amp - 1:]] if len(order) >= n_amp else [[k] for k in order]
    top = flagged_c[np.argmax(dmap.evidence[flagged_c])]
    f_top = float(np.sqrt(np.prod(grid.band_edges[grid.index(int(top))[2]])))
    f_lo = float(min(grid.band_edges[grid.index(int(c))[2], 0] for c in flagged_c))
    f_hi = float(max(grid.band_edges[grid.index(int(c))[2], 1] for c in flagged_c))
    centres = [f_top] if n_parameters < 2 else list(np.geomspace(max(f_lo, grid.freqs[0]), f_hi, 48))
    widths = [1 / 6] if n_parameters < 3 else [1 / 12, 1 / 6, 1 / 3, 2 / 3, 1.0, 2.0]
    m0 = (disc.target - disc.base_means).ravel()
    weight = 1.0 / disc.scale.ravel() ** 2
    best = (math.inf, None, None)
    F = grid.freqs.size
    for fc in centres:
        for w in widths:
            shape = np.exp(-0.5 * (np.log2(np.maximum(grid.freqs, 1e-9) / fc) / w) ** 2)      # (F,)
            columns = []
            for members in groups:
                col = np.zeros((G, K, F))
                col[:, members, :] = shape
                columns.append(col.ravel())
            X = np.array(columns).T                                  # (n_bins, n_amp)
            Xw = X * weight[:, None]
            a = np.linalg.solve(X.T @ Xw + 1e-12 * np.eye(X.shape[1]), Xw.T @ m0)
            D, D_f = disc.of_means((m0 - X @ a).reshape(G, K, F))
            if D < best[0]:
                best = (D, {"centre_hz": round(fc, 4), "width_octaves": w,
                            "amplitudes_db": {",".join(grid.channels[k] for k in g): round(float(ai), 4)
                                              for g, ai in zip(groups, a)}}, D_f)
    D, params, D_f = best
    return Candidate("generic-bump", "fitted", n_parameters, params, D, delta_D_flagged=disc.D0_flagged - D_f)


def rank_effects(config: Config, problem, w: dict[str, float], y_sim: np.ndarray, dmap: DiscrepancyMap,
                 null: NullCalibration, options: DiagnoseOptions, log: Callable[[str], None] = lambda s: None
                 ) -> tuple[list[Candidate], dict[int, Candidate], str | None, str]:
    """Fit every candidate effect and the bumps, rank them, and decide which (if any) is named.

    :returns: ``(ranking, bumps by size, named or None, reason)``.
    """

    disc = Discrepancy(dmap.grid, null, problem.y_mes, problem.noise_model, dmap.flagged, y_sim)
    D0, D0_f = disc.D0, disc.D0_flagged
    flagged = dmap.flagged_cells()
    penalty = math.log(disc.n_terms)
    names = options.effects if options.effects is not None else registry.names("effect")
    supported = _supported_effects(problem.simulator)
    J0 = j_of_spectra(problem, y_sim)[0]
    ranking: list[Candidate] = []
    fitter = EffectFitter(config, problem, w, disc, flagged, options, log)
    for name in names:
        try:
            cls = registry.get("effect", name)
        except UnknownPluginError as exc:
            raise ConfigError(str(exc), file=str(config.source_file), key="diagnose.effects") from None
        if supported is not None and name not in supported:
            ranking.append(Candidate(name, f"not supported by simulator {config.simulator.plugin}"))
            continue
        if not flagged:
            ranking.append(Candidate(name, "not fitted: no flagged cell"))
            continue
        t0 = time.perf_counter()
        cand = fitter.fit(cls)
        if cand.status == "fitted":
            cand.delta_D = D0 - cand.D
            cand.explained = cand.delta_D_flagged / D0_f if D0_f > 0 else 0.0
            cand.score = cand.delta_D - penalty * cand.n_parameters
            cand.delta_J = j_of_spectra(problem, cand.y_sim)[0] - J0
        log(f"  {name}: {cand.status}, score {cand.score:.1f} ({cand.evaluations} simulations, "
            f"{time.perf_counter() - t0:.1f} s)")
        ranking.append(cand)
    ranking.sort(key=lambda c: -c.score)
    bumps: dict[int, Candidate] = {}
    for p in sorted({c.n_parameters for c in ranking if c.status == "fitted"}):
        b = fit_bump(disc, dmap, p)
        if b.status == "fitted":
            b.delta_D = D0 - b.D
            b.explained = b.delta_D_flagged / D0_f if D0_f > 0 else 0.0
            b.score = b.delta_D - penalty * p
        bumps[p] = b
    named, reason = decide(ranking, bumps, dmap, options)
    return ranking, bumps, named, reason


def decide(ranking: list[Candidate], bumps: dict[int, Candidate], dmap: DiscrepancyMap,
           options: DiagnoseOptions) -> tuple[str | None, str]:
    """The naming rule (module docstring, step 3): ``(name or None, reason)``."""
    if not dmap.flagged.any():
        return None, "no cell is flagged: no discrepancy beyond the noise model"
    fitted = [c for c in ranking if c.status == "fitted"]
    if not fitted:
        return None, "unexplained discrepancy: no effect's signature covers the flagged cells"
    best = fitted[0]
    if len(fitted) > 1 and best.score - fitted[1].score < options.margin:
        return None, (f"unexplained discrepancy: {best.effect} does not beat {fitted[1].effect} clearly "
                      f"(scores {best.score:.1f} and {fitted[1].score:.1f}, margin {options.margin:g})")
    bump = bumps.get(best.n_parameters)
    if bump is not None and bump.status == "fitted" and best.score - bump.score < options.margin:
        return None, (f"unexplained discrepancy: {best.effect} does not beat a generic bump of "
                      f"{best.n_parameters} parameters clearly (scores {best.score:.1f} and {bump.score:.1f})")
    if best.explained < options.min_explained:
        return None, (f"unexplained discrepancy: {best.effect} explains only {100 * best.explained:.0f} % of the "
                      f"flagged discrepancy (needs {100 * options.min_explained:.0f} %)")
    runner = f"{fitted[1].effect} ({fitted[1].score:.1f})" if len(fitted) > 1 else "no other candidate"
    return best.effect, (f"{best.effect} scores {best.score:.1f}, against {runner} and a generic bump of "
                         f"{best.n_parameters} parameters ({bump.score:.1f}); it explains "
                         f"{100 * best.explained:.0f} % of the flagged discrepancy")


def _supported_effects(simulator) -> set[str] | None:
    """Effects the simulator implements: none without an ``effects`` option, its ``supported_effects()``
    when it has that method, else ``None`` (unknown: every candidate is tried, a refusal ranks it unsupported)."""
    model = getattr(type(simulator), "Options", None)
    if model is None or "effects" not in getattr(model, "model_fields", {}):
        return set()
    supported = getattr(simulator, "supported_effects", None)
    return set(supported()) if callable(supported) else None


# ====================================================================================== workflow
@dataclass
class Stage:
    """One model of the comparison: its problem (data, noise model), parameters, spectra and map."""

    label: str
    config: Config
    problem: Any
    w: dict[str, float]
    y_sim: np.ndarray
    result: dict[str, Any] | None = None
    dmap: DiscrepancyMap | None = None

    def gap(self) -> dict[str, Any]:
        out = self.dmap.gap() if self.dmap is not None else {}
        out["w"] = {k: float(v) for k, v in self.w.items()}
        if self.result is not None and "errors_percent" in self.result:
            out["errors_percent"] = self.result["errors_percent"]
            out["w_ref"] = self.result.get("w_ref")
        return out


def _with_output(config: Config, run_dir: Path) -> Config:
    return config.model_copy(update={"output": OutputSection(dir=run_dir, figure_channel=config.output.figure_channel)})


def make_stage(label: str, config: Config, identify: bool, run_dir: Path, *, fresh: bool, progress: bool,
               log: Callable[[str], None]) -> Stage:
    """The model of ``config`` at its identified parameters (a full run in ``run_dir``) or at the nominal ones."""
    cfg = _with_output(config, run_dir)
    if identify:
        log(f"{label}: identification (suspid run in {run_dir})")
        out = run(cfg, fresh=fresh, progress=progress, log=log)
        problem, result, w = out.problem, out.to_dict(), dict(out.w_opt)
    else:
        run_dir.mkdir(parents=True, exist_ok=True)
        ledger = Ledger(run_dir / "ledger.sqlite")
        if fresh:
            ledger.clear()
        problem, result, w = build_problem(cfg, ledger, log), None, {}
        problem.noise_model.save(run_dir / "noise_model.npz")
    y_sim = simulate_spectra(problem.simulator, w, problem.segments, cfg.spectra)[0]
    return Stage(label, cfg, problem, w, y_sim, result)


def write_augmented(config: Config, candidate: Candidate, out_dir: Path, noise_path: Path) -> Path:
    """``augmented.yaml``: the config with the named effect and the base run's noise model (see step 4)."""
    data = config.model_dump(mode="json", exclude={"source_file"})
    options = dict(data["simulator"].get("options") or {})
    options["effects"] = list(options.get("effects") or []) + [{"name": candidate.effect,
                                                                **_jsonable(candidate.parameters)}]
    data["simulator"]["options"] = options
    data["noise"] = {**(data.get("noise") or {}), "path": str(noise_path)}
    data["name"] = config.name if config.name.endswith("-augmented") else f"{config.name}-augmented"
    data["output"] = {"dir": str(out_dir / "after"), "figure_channel": config.output.figure_channel}
    path = out_dir / "augmented.yaml"
    header = (f"# Written by suspid diagnose from {config.source_file}:\n"
              f"# the model with the named effect '{candidate.effect}' and its fitted parameters,\n"
              f"# and the noise model of the base run (the measurements and B are unchanged).\n")
    return write_text(path, header + yaml.safe_dump(data, sort_keys=False))


@dataclass
class DiagnosisResult:
    """A finished diagnosis: its folder and the content of ``diagnosis.json``."""

    out_dir: Path
    diagnosis: dict[str, Any]

    @property
    def named(self) -> str | None:
        """The named effect, or None."""
        return self.diagnosis["named"]


def run_diagnose(source: str | Path | Any, overrides: Sequence[str], config: Config, *, fresh: bool = False,
                 progress: bool = False, log: Callable[[str], None] = lambda s: None) -> DiagnosisResult:
    """The whole workflow (module docstring): writes diagnosis.json, diagnosis.md and figures.

    :param config: the config, loaded from ``source`` with ``overrides``.
    """
    t_start = time.perf_counter()
    opts = config.diagnose
    out_dir = config.run_dir()
    out_dir.mkdir(parents=True, exist_ok=True)
    before = make_stage("before", config, opts.at == "identified", out_dir / "before", fresh=fresh,
                        progress=progress, log=log)
    problem = before.problem
    grid = make_cells(problem.channels, problem.freqs, [s.mean_speed for s in problem.segments],
                      opts.bands_per_octave, opts.min_bins_per_band)
    log(f"locate: {grid.n_cells} cells, null calibrated by {opts.n_bootstrap} bootstrap replicates")
    with single_blas_thread():     # small products: OpenBLAS threads only contend (suspid.infra.threads)
        null = calibrate_null(grid, problem.noise_model, opts.n_bootstrap,
                              named_rng(config.seed, "diagnose-bootstrap"))
        mu = problem.noise_model.mean_
        before.dmap = locate(grid, null, problem.y_mes, before.y_sim, mu, opts.alpha)
        before.dmap.J = j_of_spectra(problem, before.y_sim)[0]
        log(f"located: {int(before.dmap.flagged.sum())} flagged cells; ranking the effects")
        t_rank = time.perf_counter()
        ranking, bumps, named, reason = rank_effects(config, problem, before.w, before.y_sim, before.dmap, null,
                                                     opts, log)
        rank_s = time.perf_counter() - t_rank
    log(f"named: {named or 'nothing'} ({reason})")
    after, aug_path = None, None
    if named is not None:
        cand = next(c for c in ranking if c.effect == named)
        aug_path = write_augmented(config, cand, out_dir, out_dir / "before" / "noise_model.npz")
        aug = load_config(aug_path)
        if opts.reidentify:
            after = make_stage("after", aug, True, out_dir / "after", fresh=fresh, progress=progress, log=log)
        else:
            after = Stage("after", aug, problem, before.w, cand.y_sim, None)
        after.dmap = locate(grid, null, after.problem.y_mes, after.y_sim, after.problem.noise_model.mean_,
                            opts.alpha)
        after.dmap.J = j_of_spectra(after.problem, after.y_sim)[0]
    diagnosis = {
        "name": config.name,
        "config": str(config.source_file),
        "base_model": opts.at,
        "flagged": [{k: r[k] for k in ("channel", "f_low_hz", "f_high_hz", "sign", "magnitude_db", "test", "z", "q",
                                       "speed_kmh")} for r in before.dmap.rows(only_flagged=True)],
        "ranking": [c.as_dict() for c in ranking],
        "generic_bumps": {str(p): b.as_dict() for p, b in bumps.items()},
        "named": named,
        "reason": reason,
        "named_parameters": next((_jsonable(c.parameters) for c in ranking if c.effect == named), None),
        "gap_before": before.gap(),
        "gap_after": after.gap() if after is not None else None,
        "augmented_config": str(aug_path) if aug_path is not None else None,
        "statistics": {
            "cells": "speed group x channel x band", "n_cells": grid.n_cells,
            "bands_hz": grid.band_edges.round(4).tolist(),
            "statistic": "per cell: band mean of r = y_mes - y_sim - mu_B (mean test), sum of squared "
                         "standardised bin means (shape test), largest standardised bin mean (peak test); "
                         "p = min(1, 3 min(p_mean, p_shape, p_peak))",
            "null": "mean: N(0, kappa_c^2 s_c^2), s_c from the noise covariance; shape: a_c chi2(nu_c); "
                    "peak: Bonferroni over the band's bins; kappa, a_c, nu_c from a parametric bootstrap",
            "n_bootstrap": null.n_bootstrap, "kappa_median": float(np.median(null.kappa)),
            "kappa_raw_median": None if null.kappa_raw is None else float(np.median(null.kappa_raw)),
            "bootstrap_null_rate_at_5pct": null.null_rate, "fdr": "Benjamini-Yekutieli", "alpha": opts.alpha,
            "penalty_per_parameter": math.log(grid.n_cells // grid.band_edges.shape[0] * grid.freqs.size),
            "margin": opts.margin,
            "min_explained": opts.min_explained},
        "map_before": before.dmap.rows(),
        "map_after": after.dmap.rows() if after is not None else None,
        "wall_time_s": None, "ranking_time_s": round(rank_s, 2),
    }
    diagnosis["wall_time_s"] = round(time.perf_counter() - t_start, 2)
    write_json(out_dir / "diagnosis.json", _jsonable(diagnosis))
    write_diagnosis_report(out_dir, diagnosis, before, after, ranking, bumps)
    return DiagnosisResult(out_dir, json.loads(json.dumps(_jsonable(diagnosis))))


# ====================================================================================== report
def figure_map(path: Path, dmap: DiscrepancyMap, title: str, limit_db: float | None = None) -> Path:
    """Heat map of the cell magnitudes (dB, + measured above the model) per speed group; flagged cells framed."""
    plt = pyplot()
    grid = dmap.grid
    G, K, B = len(grid.speeds), len(grid.channels), grid.band_edges.shape[0]
    m = dmap.magnitude_db.reshape(G, K, B)
    fl = dmap.flagged.reshape(G, K, B)
    lim = limit_db or max(1.0, float(np.max(np.abs(m))))
    fig, axes = plt.subplots(G, 1, figsize=(max(7, 0.42 * B + 3), 0.38 * K * G + 1.6), squeeze=False)
    centres = np.sqrt(grid.band_edges[:, 0] * np.maximum(grid.band_edges[:, 1], 1e-9))
    for g, ax in enumerate(axes[:, 0]):
        im = ax.imshow(m[g], cmap="RdBu_r", vmin=-lim, vmax=lim, aspect="auto")
        for k, b in zip(*np.nonzero(fl[g])):
            ax.add_patch(plt.Rectangle((b - 0.5, k - 0.5), 1, 1, fill=False, lw=1.6, ec="black"))
        ax.set_yticks(range(K), grid.channels, fontsize=7)
        ax.set_xticks(range(B), [f"{c:.3g}" for c in centres], rotation=90, fontsize=7)
        ax.set_title(f"{title}: {grid.speeds[g] * 3.6:.0f} km/h" if G > 1 else title, fontsize=9)
        fig.colorbar(im, ax=ax, label="y_mes - y_sim - μ_B (dB): band mean or peak bin", fraction=0.04)
    axes[-1, 0].set_xlabel("band centre (Hz); framed: flagged (BY)")
    fig.tight_layout()
    return save_figure(fig, path)


def figure_spectra_gap(path: Path, stage_before: Stage, stage_after: Stage | None, channel: int,
                       dmap: DiscrepancyMap) -> Path:
    """Mean measured spectrum against the modelled mean y_sim + μ_B before and after, one channel."""
    plt = pyplot()
    p = stage_before.problem
    f = p.freqs
    mu = p.noise_model.mean_[channel]
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(f, p.y_mes[:, channel].mean(axis=0), color="black", lw=1.5, label="Y_mes (mean)")
    ax.plot(f, stage_before.y_sim[:, channel].mean(axis=0) + mu, color="tab:red", lw=1.2,
            label="Y_sim + μ_B, base model")
    if stage_after is not None:
        ax.plot(f, stage_after.y_sim[:, channel].mean(axis=0) + stage_after.problem.noise_model.mean_[channel],
                color="tab:blue", lw=1.2, ls="--", label="Y_sim + μ_B, augmented model")
    grid = dmap.grid
    for c in np.nonzero(dmap.flagged)[0]:
        g, k, b = grid.index(int(c))
        if k == channel:
            ax.axvspan(*grid.band_edges[b], color="orange", alpha=0.2, lw=0)
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("Y (dB)")
    ax.set_title(f"channel {p.channels[channel]} (shaded: flagged bands before)")
    if f[-1] / max(f[0], 1e-9) > 20:
        ax.set_xscale("log")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(fig, path)


def _fmt_params(params: dict[str, Any]) -> str:
    out = []
    for k, v in params.items():
        if isinstance(v, float):
            out.append(f"{k}={v:.4g}")
        elif isinstance(v, dict):
            out.append(f"{k}={{{', '.join(f'{a}: {b:.3g}' if isinstance(b, float) else f'{a}: {b}' for a, b in v.items())}}}")
        else:
            out.append(f"{k}={v}")
    return ", ".join(out)


def write_diagnosis_report(out_dir: Path, diagnosis: dict[str, Any], before: Stage, after: Stage | None,
                           ranking: list[Candidate], bumps: dict[int, Candidate]) -> Path:
    """``diagnosis.md`` and its figures."""

    dmap = before.dmap
    lim = max(1.0, float(np.max(np.abs(dmap.magnitude_db))))
    figure_map(out_dir / "diagnosis_map_before.png", dmap, "before (base model)", lim)
    if after is not None:
        figure_map(out_dir / "diagnosis_map_after.png", after.dmap, "after (augmented model)", lim)
    per_channel = np.zeros(len(before.problem.channels))
    for c in np.nonzero(dmap.flagged)[0]:
        per_channel[dmap.grid.index(int(c))[1]] += dmap.evidence[c]
    channel = int(np.argmax(per_channel)) if dmap.flagged.any() else dmap.grid.index(int(np.argmax(dmap.evidence)))[1]
    figure_spectra_gap(out_dir / "diagnosis_spectra.png", before, after, channel, dmap)

    flagged = sorted(dmap.rows(only_flagged=True), key=lambda r: r["p"])
    flag_rows = [[r["channel"], f"{r['f_low_hz']:.3g}-{r['f_high_hz']:.3g}", f"{r['speed_kmh']:.0f}", r["sign"],
                  f"{r['magnitude_db']:+.2f}", r["test"], f"{r['q']:.2g}"] for r in flagged[:30]]
    rank_rows = []
    for c in ranking:
        score = f"{c.score:.1f}" if math.isfinite(c.score) else "-"
        main = ""
        if c.status == "fitted":
            cls = registry.get("effect", c.effect)
            main = f"{cls.main_parameter} = {c.parameters.get(cls.main_parameter)}"
            if isinstance(c.parameters.get(cls.main_parameter), float):
                main = f"{cls.main_parameter} = {c.parameters[cls.main_parameter]:.4g}"
        rank_rows.append([f"**{c.effect}**" if c.effect == diagnosis["named"] else c.effect, c.status, score,
                          c.n_parameters or "-", f"{c.delta_D:.1f}" if math.isfinite(c.delta_D) else "-",
                          f"{100 * c.explained:.0f} %" if c.status == "fitted" else "-",
                          f"{c.delta_J:+.4f}" if c.delta_J is not None else "-", main,
                          _fmt_params(c.parameters) if c.status == "fitted" else ""])
    for p, b in sorted(bumps.items()):
        rank_rows.append([f"generic bump ({p} parameters)", b.status, f"{b.score:.1f}" if math.isfinite(b.score)
                          else "-", p, f"{b.delta_D:.1f}" if math.isfinite(b.delta_D) else "-",
                          f"{100 * b.explained:.0f} %" if b.status == "fitted" else "-", "-", "",
                          _fmt_params(b.parameters) if b.status == "fitted" else ""])
    gb, ga = diagnosis["gap_before"], diagnosis["gap_after"]

    def shrink(a, b):
        return f"{100 * (1 - b / a):.0f} %" if a and b is not None and a > 0 else "-"

    gap_rows = [["flagged cells", f"{gb['n_flagged']} of {gb['n_cells']} ({100 * gb['share_flagged']:.1f} %)",
                 f"{ga['n_flagged']} ({100 * ga['share_flagged']:.1f} %)" if ga else "-",
                 shrink(gb["share_flagged"], ga["share_flagged"]) if ga else "-"],
                ["integrated discrepancy (dB·Hz)", f"{gb['integrated_db_hz']:.2f}",
                 f"{ga['integrated_db_hz']:.2f}" if ga else "-",
                 shrink(gb["integrated_db_hz"], ga["integrated_db_hz"]) if ga else "-"],
                ["J (run objective)", f"{gb['J']:.5g}", f"{ga['J']:.5g}" if ga else "-", ""]]
    if "errors_percent" in gb or (ga and "errors_percent" in ga):
        names = list((ga or gb).get("errors_percent", gb.get("errors_percent", {})))
        for n in names:
            eb = gb.get("errors_percent", {}).get(n)
            ea = (ga or {}).get("errors_percent", {}).get(n)
            gap_rows.append([f"error of {n} (% of interval)", f"{eb:.2f}" if eb is not None else "-",
                             f"{ea:.2f}" if ea is not None else "-", ""])
    named = diagnosis["named"]
    verdict = (f"**Named: `{named}`** with {_fmt_params(diagnosis['named_parameters'])}. {diagnosis['reason']}."
               if named else f"**Nothing named.** {diagnosis['reason']}.")
    st = diagnosis["statistics"]
    text = f"""# Discrepancy diagnosis `{diagnosis['name']}`

Base model: the config's model at its {'identified' if diagnosis['base_model'] == 'identified' else 'nominal'}
parameters. Measurements: {before.problem.y_mes.shape[0]} segments, {len(before.problem.channels)} channels,
{before.problem.freqs.size} frequencies. Wall time {diagnosis['wall_time_s']:.0f} s (ranking {diagnosis['ranking_time_s']:.0f} s).

{verdict}

## 1. Where the model and the measurements disagree

{gb['n_flagged']} of {gb['n_cells']} cells (speed group × channel × band) are flagged at a false discovery rate
of {st['alpha']:g} (Benjamini-Yekutieli); integrated discrepancy {gb['integrated_db_hz']:.2f} dB·Hz. Sign +: the
measurements are above the model; magnitude: the band mean (mean test) or the most deviant bin (shape and
peak tests: a moved resonance, a narrow line). Null calibrated by {st['n_bootstrap']} parametric-bootstrap replicates
(median scale κ {st['kappa_median']:.3f}, unfloored {st['kappa_raw_median'] if st['kappa_raw_median'] is None else round(st['kappa_raw_median'], 3)}).

{markdown_table(['channel', 'band (Hz)', 'km/h', 'sign', 'magnitude (dB)', 'test', 'q (BY)'], flag_rows) if flag_rows else '(no flagged cell)'}
{f'(and {len(flagged) - 30} more)' if len(flagged) > 30 else ''}

![map before](diagnosis_map_before.png)

## 2. Which effect is missing

Each candidate's parameters are fitted to minimise D = Σ z² over every channel and frequency (z: the mean
residual over its null standard deviation); score = ΔD - p ln(n) ({st['penalty_per_parameter']:.2f} per
parameter p); a generic bump of the same size is the yardstick. Named
only with a margin of {st['margin']:g} over the runner-up and the bump, explaining at least
{100 * st['min_explained']:.0f} % of the flagged discrepancy.

{markdown_table(['candidate', 'status', 'score', 'p', 'ΔD', 'explained', 'ΔJ', 'main parameter', 'parameters'], rank_rows)}

## 3. The gap before and after adding the effect

{f"Augmented config: `{diagnosis['augmented_config']}`" if diagnosis['augmented_config'] else 'No augmented config (nothing named).'}

{markdown_table(['', 'before', 'after', 'shrink'], gap_rows)}

{'![map after](diagnosis_map_after.png)' if after is not None else ''}

![spectra](diagnosis_spectra.png)

Method: `docs/diagnose.md`.
"""
    return write_text(out_dir / "diagnosis.md", text)
