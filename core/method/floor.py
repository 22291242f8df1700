"""An additive sensor-noise floor in power under the multiplicative model error (beyond the paper).

The paper's noise B is additive in dB (eq. 3-4): y_mod = y_sim + b, the same
for every parameter vector w and speed. A sensor's noise is additive in
*power*: where it dominates a cell, the measured level does not follow
y_sim(w) at all. This module separates the two, per channel and frequency::

    P_mod = g(ω) P_sim(ω; w) + N(ω)          (power, (m/s²)²/Hz two-sided)
    y_mod = 5 log10(10^{(y_sim + m)/5} + N) + e,   m = 5 log10 g (dB), e the zero-mean GP residual.

Units: Y = 10 log10 |Â| (eq. 1) and |Â|² is a two-sided power spectral
density (:mod:`suspid.method.spectra`), so P = |Â|² = 10^{Y/5} and a gain of
m dB in Y multiplies P by 10^{m/5}. With N = 0, y_mod = y_sim + m + e = y_sim + b,
today's model exactly.

**Estimation at the reference date** (``noise.floor: auto``). Across the v0
segments the excitation changes (track, speed), so per channel k and
frequency ω the measured levels y_mes_i regress on the simulated ones: a floor
shows as measured levels that stop following y_sim_i where y_sim_i is low. For
each candidate N on a log grid (per channel) m is fitted by Gauss-Newton to
minimise RSS(N) = Σ_i (y_mes_i - 5 log10(10^{(y_sim_i + m)/5} + N))²; N is
then chosen per cell by the profile likelihood pooled over a window of
``floor_octaves`` around ω (one N shared by the window: the floor is smooth in
frequency), −2 log Λ(N) = Σ_window v0 ln(RSS(N) / RSS(0)). Where the best N
does not beat N = 0 by more than :data:`LR_THRESHOLD` (χ² with one degree of
freedom at p = 0.001) the floor is not identifiable there and N = 0. N >= 0 by
construction.

**From a sensor specification** (``noise.floor: spec``): the sensors' noise
density ``sensor_noise_density`` in (m/s²)²/Hz, one-sided as data sheets
give it, for all channels or per channel; N is half of it (two-sided) at every
frequency, and m is fitted with N fixed.

Where the floor dominates every segment m is not identified by the data (the
fit has no sensitivity to it, :data:`MIN_INFORMATION`); there m is
interpolated over frequency from the cells of the channel where it is, so
that a later rise of y_sim above the floor is modelled with the model error
of the neighbouring frequencies, not with a value the noise chose.

Either way the GP paths are then b_i = m + e_i with e_i = y_mes_i -
5 log10(10^{(y_sim_i + m)/5} + N), and :class:`NoiseFloor.effective` maps
y_sim to the spectrum that plays the role of y_sim in y_mod = y_sim + b.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from suspid.errors import ConfigError, DataError

LR_THRESHOLD = 10.83
"""−2 log Λ needed to accept a floor over N = 0 (χ²₁ quantile at p = 0.001)."""

N_GRID = 48
"""Candidate floors per channel (log-spaced), plus N = 0."""

MIN_INFORMATION = 0.25
"""Mean of a_i² = (g P_sim_i / (g P_sim_i + N))² below which m is not identified in a cell (the floor
dominates the segments there: on average the signal is below the floor)."""


@dataclass(frozen=True)
class NoiseFloor:
    """The fitted floor: ``power`` N ``(n_channels, n_freqs)`` (m/s²)²/Hz two-sided, and ``gain_db`` m
    ``(n_channels, n_freqs)`` dB, the multiplicative model error it was fitted with."""

    power: np.ndarray
    gain_db: np.ndarray

    def effective(self, y_sim: np.ndarray) -> np.ndarray:
        """5 log10(10^{(y_sim + m)/5} + N) - m: what stands for y_sim in y_mod = y_sim + b.

        :param y_sim: ``(..., n_channels, n_freqs)`` dB.
        :returns: same shape, dB; >= y_sim, equal to it where N = 0.
        """
        y = np.asarray(y_sim, dtype=float)
        return 5.0 * np.log10(10.0 ** ((y + self.gain_db) / 5.0) + self.power) - self.gain_db

    def at(self, freq_index) -> "NoiseFloor":
        """The floor on a subset of the frequencies (an index or mask of the grid)."""
        return NoiseFloor(self.power[:, freq_index], self.gain_db[:, freq_index])

    def paths(self, y_mes: np.ndarray, y_sim: np.ndarray) -> np.ndarray:
        """The noise paths b_i = y_mes_i - effective(y_sim_i) = m + e_i, ``(v0, n_channels, n_freqs)`` dB."""
        return np.asarray(y_mes, dtype=float) - self.effective(y_sim)

    def summary(self, freqs: np.ndarray | None, channels: Sequence[str] | None) -> dict:
        """Per channel: share of frequencies with a floor, its median level (dB, 5 log10 N) and frequency range."""
        out = {}
        n_ch, n_f = self.power.shape
        names = list(channels) if channels is not None else [f"channel {k}" for k in range(n_ch)]
        for k, name in enumerate(names):
            on = self.power[k] > 0
            row = {"share": float(on.mean())}
            if on.any():
                row["median_db"] = float(5 * np.log10(np.median(self.power[k, on])))
                if freqs is not None:
                    row["f_hz"] = [float(freqs[on].min()), float(freqs[on].max())]
            out[name] = row
        return out


def _fit_gain(y_mes: np.ndarray, y_sim: np.ndarray, floor: np.ndarray, m0: np.ndarray,
              iterations: int = 25) -> tuple[np.ndarray, np.ndarray]:
    """m minimising Σ_i (y_mes_i - 5 log10(10^{(y_sim_i + m)/5} + N))² per cell (Gauss-Newton), and that RSS.

    :param y_mes, y_sim: ``(v0, n_ch, n_f)`` dB; ``floor``: ``(n_ch, n_f)``; ``m0``: the N = 0 solution.
    m stays within [m0 - 10, m0 + 1] dB (where the floor dominates every segment m is not identified).
    """
    p_sim = 10.0 ** (y_sim / 5.0)
    m = m0.copy()
    for _ in range(iterations):
        gp = p_sim * 10.0 ** (m / 5.0)
        a = gp / (gp + floor)                                   # d y_mod / d m, in (0, 1]
        r = y_mes - 5.0 * np.log10(gp + floor)
        step = (a * r).sum(axis=0) / np.maximum((a * a).sum(axis=0), 1e-9)
        m = np.clip(m + np.clip(step, -3.0, 3.0), m0 - 10.0, m0 + 1.0)
    r = y_mes - 5.0 * np.log10(p_sim * 10.0 ** (m / 5.0) + floor)
    return m, (r * r).sum(axis=0)


def _fill_unidentified(y_sim: np.ndarray, floor: np.ndarray, m: np.ndarray) -> np.ndarray:
    """m where the data identify it; elsewhere (:data:`MIN_INFORMATION`) interpolated over the frequency
    index from the identified cells of the channel (held constant beyond them; left as is without any)."""
    gp = 10.0 ** ((y_sim + m) / 5.0)
    known = ((gp / (gp + floor)) ** 2).mean(axis=0) >= MIN_INFORMATION
    out = m.copy()
    idx = np.arange(m.shape[1])
    for k in range(m.shape[0]):
        if known[k].any() and not known[k].all():
            out[k, ~known[k]] = np.interp(idx[~known[k]], idx[known[k]], m[k, known[k]])
    return out


def _window(freqs: np.ndarray | None, n_f: int, octaves: float) -> np.ndarray:
    """``(n_f, n_f)`` 0/1: frequencies within ±octaves/2 of each other (the identity without freqs)."""
    if freqs is None or octaves <= 0:
        return np.eye(n_f)
    lf = np.log2(np.maximum(np.asarray(freqs, dtype=float), 1e-12))
    return (np.abs(lf[:, None] - lf[None, :]) <= octaves / 2.0).astype(float)


def estimate_floor(y_mes: np.ndarray, y_sim: np.ndarray, freqs: np.ndarray | None = None,
                   octaves: float = 0.5) -> NoiseFloor:
    """The floor N and gain m from reference-date spectra (module docstring, ``auto``).

    :param y_mes, y_sim: ``(v0, n_channels, n_freqs)`` dB, measured and simulated at w0, v0 >= 3.
    :param freqs: ``(n_freqs,)`` Hz, for the smoothing window (without: no pooling across frequency).
    :param octaves: width of the window over which one N is shared.
    """
    y_mes = np.asarray(y_mes, dtype=float)
    y_sim = np.asarray(y_sim, dtype=float)
    v0, n_ch, n_f = y_mes.shape
    if v0 < 3:
        raise DataError(f"estimating a noise floor takes at least 3 reference segments, got {v0}")
    m0 = (y_mes - y_sim).mean(axis=0)
    rss0 = ((y_mes - y_sim - m0) ** 2).sum(axis=0)
    level = np.median(10.0 ** (y_mes / 5.0), axis=0)             # (n_ch, n_f) measured power
    lo = np.maximum(level.min(axis=1), 1e-30) * 1e-3
    hi = np.maximum(level.max(axis=1), 1e-30)
    grid = np.exp(np.linspace(np.log(lo), np.log(hi), N_GRID))    # (N_GRID, n_ch)
    window = _window(freqs, n_f, octaves)
    best_lr = np.zeros((n_ch, n_f))
    power = np.zeros((n_ch, n_f))
    gain = m0.copy()
    for n_k in grid:
        floor = np.broadcast_to(n_k[:, None], (n_ch, n_f))
        m, rss = _fit_gain(y_mes, y_sim, floor, m0)
        lr = v0 * np.log(np.maximum(rss0, 1e-300) / np.maximum(rss, 1e-300)) @ window   # pooled −2 log Λ
        better = lr > best_lr
        best_lr = np.where(better, lr, best_lr)
        power = np.where(better, floor, power)
        gain = np.where(better, m, gain)
    keep = best_lr > LR_THRESHOLD
    power = np.where(keep, power, 0.0)
    return NoiseFloor(power=power, gain_db=_fill_unidentified(y_sim, power, np.where(keep, gain, m0)))


def density_problem(density: float | Mapping[str, float] | None, channels: Sequence[str]) -> str | None:
    """What is wrong with a per-channel ``sensor_noise_density`` for these channels, or None."""
    if not isinstance(density, Mapping):
        return None
    names = list(channels)
    unknown = sorted(set(density) - set(names))
    missing = [c for c in names if c not in density]
    if not (unknown or missing):
        return None
    return (f"per-channel densities must name every channel once ({', '.join(names)}); "
            f"unknown: {', '.join(unknown) or '-'}, missing: {', '.join(missing) or '-'}")


def spec_floor(y_mes: np.ndarray, y_sim: np.ndarray, density: float | Mapping[str, float],
               channels: Sequence[str] | None) -> NoiseFloor:
    """The floor from a sensor specification (module docstring, ``spec``), m fitted with N fixed.

    :param density: one-sided noise density, (m/s²)²/Hz, for all channels or per channel name.
    :raises ConfigError: a per-channel mapping that names unknown channels or misses some.
    """
    y_mes = np.asarray(y_mes, dtype=float)
    y_sim = np.asarray(y_sim, dtype=float)
    _, n_ch, n_f = y_mes.shape
    if isinstance(density, Mapping):
        problem = density_problem(density, channels or [])
        if problem is not None or not channels:
            raise ConfigError(problem or "per-channel densities need the channel names",
                              key="noise.sensor_noise_density")
        one_sided = np.array([float(density[c]) for c in channels])
    else:
        one_sided = np.full(n_ch, float(density))
    floor = np.broadcast_to(one_sided[:, None] / 2.0, (n_ch, n_f)).copy()
    m0 = (y_mes - y_sim).mean(axis=0)
    m, _ = _fit_gain(y_mes, y_sim, floor, m0)
    return NoiseFloor(power=floor, gain_db=_fill_unidentified(y_sim, floor, m))
