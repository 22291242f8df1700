"""The discrepancy map: the three tests per cell, false discovery control, the gap measures.

Overview: ``docs/diagnose.md``, "How it works", step 2.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import chi2, false_discovery_control, norm

from .cells import CellGrid
from .null import NullCalibration, shape_statistic


@dataclass
class DiscrepancyMap:
    """Per cell: the three tests, the BY-adjusted q and the flag; see :func:`locate`.

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
           alpha: float = 0.05, min_db: float = 0.0) -> DiscrepancyMap:
    """The discrepancy map of the residual r = y_mes - y_sim - μ_B: mean, shape and peak tests per cell,
    Benjamini-Yekutieli over all cells, a cell flagged when its adjusted p-value is below ``alpha``.

    With a relevance margin ``min_db`` = δ > 0 each test asks whether the discrepancy exceeds δ, not 0 (the
    null |mean discrepancy| <= δ): the mean test's p is P(|N(δ, s)| >= |m|), the peak test's the same per bin,
    and the shape test sums the squared standardised excesses max(0, |r̄_f| - δ) / σ_f against its null for
    δ = 0 (conservative). A model is never exactly right: with enough data every model-form difference of a
    few tenths of a dB is significant, and δ says which size of discrepancy is worth a diagnosis.

    :param y_mes, y_sim: ``(v, n_channels, n_freqs)`` dB on the same segments, in the same order.
    :param noise_mean: μ_B, dB: ``(G, n_channels, n_freqs)`` per speed group (``null.noise_mean``), or
        ``(n_channels, n_freqs)`` for all.
    :param min_db: δ, dB (>= 0).
    """
    r_bar = grid.group_means(y_mes - y_sim) - np.asarray(noise_mean)        # (G, K, F)
    mean = (r_bar @ grid.average).ravel()
    scale = null.scale
    p_mean = np.clip(_two_sided(np.abs(mean), min_db, scale), 1e-300, 1.0)
    excess = np.sign(r_bar) * np.maximum(0.0, np.abs(r_bar) - min_db)
    Q = shape_statistic(grid, excess, null.bin_sd)
    p_shape = np.clip(chi2.sf(Q / null.shape_scale, null.shape_dof), 1e-300, 1.0)
    # the most deviant bin of each band, and the peak test
    bin_scale = null.bin_sd * null.bin_kappa
    z_bin = np.abs(excess) / bin_scale
    G, K, B = len(grid.speeds), len(grid.channels), grid.band_edges.shape[0]
    peak = np.empty((G, K, B))
    p_peak = np.empty((G, K, B))
    for b in range(B):
        idx = np.nonzero(grid.average[:, b] > 0)[0]
        j = idx[np.argmax(z_bin[:, :, idx], axis=2)]                        # (G, K)
        pick = lambda a: np.take_along_axis(a, j[:, :, None], axis=2)[:, :, 0]  # noqa: E731
        peak[:, :, b] = pick(r_bar)
        p_peak[:, :, b] = np.minimum(1.0, idx.size * _two_sided(np.abs(pick(r_bar)), min_db, pick(bin_scale)))
    p_peak = np.clip(p_peak.ravel(), 1e-300, 1.0)
    p = np.minimum(1.0, 3.0 * np.minimum(np.minimum(p_mean, p_shape), p_peak))
    q = false_discovery_control(p, method="by")
    return DiscrepancyMap(grid, mean, peak.ravel(), scale, p_mean, p_shape, p_peak, p, q, q < alpha, r_bar,
                          null.bin_sd)


def _two_sided(x: np.ndarray, delta: float, scale: np.ndarray) -> np.ndarray:
    """P(|N(δ, scale)| >= x): the two-sided p-value of |x| at the boundary |μ| = δ of the null |μ| <= δ."""
    return norm.sf((x - delta) / scale) + norm.sf((x + delta) / scale)
