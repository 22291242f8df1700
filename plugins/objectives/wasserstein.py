"""A baseline objective: the Wasserstein-1 distance per frequency, registered as ``wasserstein``.

    Ψ_k(w) = -(1/|Ω|) ∫_Ω W_1(Y_k^mes(ω), Y_k^mod(ω, w)) dω
    W_1(P, Q) = ∫_R |F_P(u) - F_Q(u)| du = ∫_0^1 |F_P⁻¹(t) - F_Q⁻¹(t)| dt

between the empirical distributions of the measured and the modelled samples
in dB at (k, ω), as ``scipy.stats.wasserstein_distance`` defines it. Like the
overlap of paper eq. 7-8 it compares whole distributions, but needs no
kernel or bandwidth. Wasserstein-1 rather than the energy distance: it is in
dB (a uniform shift of d dB gives exactly W_1 = |d|, so Ψ_k reads as the mean
spectral mismatch in dB), where the energy distance is the square root of a
distance in dB and mixes the same CDF difference in quadrature.

Evaluation. The quantile form: both samples are sorted per row and the two
quantile functions, step functions with jumps at i/n_mes and j/n_mod (the
same for every (k, ω)), are compared on the union of their jumps, one
vectorised pass for all rows. It agrees with scipy to ~1e-15 and is 5 to 20
times faster than calling scipy per (k, ω): for 8 channels, 1000 frequencies
and 100 samples each, 0.05-0.13 s against 0.7-1.0 s on a loaded 2-core machine
(``benchmarks/bench_baseline_objectives.py``). Ψ_k <= 0 in dB; 0 means
identical samples. Higher is better.

Select it with ``objective: {plugin: wasserstein}``.
"""

from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict

from suspid import hookimpl
from suspid.interfaces import Objective
from suspid.method.kde import frequency_mean, prepare
from suspid.options import parse_options


class WassersteinOptions(BaseModel):
    """``objective.options`` of ``wasserstein``: none yet (unknown keys are rejected)."""

    model_config = ConfigDict(extra="forbid")


def wasserstein_rows(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """W_1 between the empirical distributions of each row of ``x (n_rows, n_x)`` and ``y (n_rows, n_y)``.

    :returns: ``(n_rows,)`` in the units of the samples.
    """
    n_x, n_y = x.shape[1], y.shape[1]
    t = np.union1d(np.arange(n_x + 1) / n_x, np.arange(n_y + 1) / n_y)  # jumps of both quantile functions
    mid = 0.5 * (t[1:] + t[:-1])
    ix, iy = np.floor(mid * n_x).astype(int), np.floor(mid * n_y).astype(int)
    return np.abs(np.sort(x, axis=1)[:, ix] - np.sort(y, axis=1)[:, iy]) @ np.diff(t)


class WassersteinObjective(Objective):
    """Ψ_k = -mean over Ω of W_1 between the measured and modelled samples (dB)."""

    name = "wasserstein"
    Options = WassersteinOptions

    def psi(self, y_mes: np.ndarray, y_mod: np.ndarray, freqs: np.ndarray) -> np.ndarray:
        """Ψ_k for every channel.

        :param y_mes: ``(n_mes, n_channels, n_freqs)`` measured spectra in dB.
        :param y_mod: ``(n_mod, n_channels, n_freqs)`` modelled spectra in dB, n_mod >= 2.
        :param freqs: ``(n_freqs,)`` in Hz, strictly increasing.
        :returns: ``(n_channels,)`` in dB, <= 0.
        :raises DataError: shapes or values that do not fit; ``ConfigError`` for bad options.
        """
        parse_options(WassersteinOptions, self.options, "objective.options")
        x, y, freqs, grid = prepare(y_mes, y_mod, freqs, min_mes=1)
        return -frequency_mean(wasserstein_rows(x, y).reshape(grid), freqs)


@hookimpl
def suspid_register_objectives(register):
    """Register :class:`WassersteinObjective` as ``wasserstein``."""
    register(WassersteinObjective)
