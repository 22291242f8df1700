"""The log-likelihood objective Ψ_k of paper eq. 6, registered as ``likelihood``.

    Ψ_k(w) = (1/|Ω|) ∫_Ω log Π_{i=1}^{v} p_{Y_k^mod}(y_k^{mes,i}(ω); ω, w) dω        (eq. 6)

p_{Y_k^mod}(·; ω, w) is the Gaussian kernel density estimate of the modelled
samples y_mod_i = y_sim_i(w) + b_i at (k, ω), evaluated exactly at every
measured point (:func:`suspid.method.kde.log_kde`: a Gaussian mixture, its log
formed safely where it underflows; by a compiled numba kernel, or with
``kernel: numpy`` by the vectorised numpy reference, which agrees to ~1e-14). As in the paper the log-likelihood is
summed over the v measured samples, not averaged, so Ψ_k grows with v; the
ω integral is the trapezoidal rule over the grid. Units: p in 1/dB, so Ψ_k is
a sum of logs of densities in 1/dB. Higher is better.

Select it with ``objective: {plugin: likelihood, options: {bandwidth: silverman}}``.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from suspid import hookimpl
from suspid.options import parse_options
from suspid.interfaces import Objective
from suspid.method.kde import KdeOptions, bandwidths, frequency_mean, log_kde, prepare


class LikelihoodOptions(KdeOptions):
    """``objective.options`` of ``likelihood``: the bandwidth rule of the KDE of Y_mod and its floor."""

    kernel: Literal["auto", "numpy"] = Field(
        default="auto", description="evaluation of the KDE: 'auto' the compiled kernel when numba is "
                                    "installed, 'numpy' the vectorised reference (same values to ~1e-14)")


class LikelihoodObjective(Objective):
    """Ψ_k of eq. 6: log-likelihood of the measured samples under the KDE of the modelled ones."""

    name = "likelihood"
    Options = LikelihoodOptions

    def psi(self, y_mes: np.ndarray, y_mod: np.ndarray, freqs: np.ndarray) -> np.ndarray:
        """Ψ_k for every channel (eq. 6).

        :param y_mes: ``(n_mes, n_channels, n_freqs)`` measured spectra in dB.
        :param y_mod: ``(n_mod, n_channels, n_freqs)`` modelled spectra in dB, n_mod >= 2.
        :param freqs: ``(n_freqs,)`` in Hz, strictly increasing.
        :returns: ``(n_channels,)``, sums over the measured samples of log p (p in 1/dB),
            averaged over Ω.
        :raises DataError: shapes or values that do not fit; ``ConfigError`` for bad options.
        """
        opt = parse_options(LikelihoodOptions, self.options, "objective.options")
        x, y, freqs, grid = prepare(y_mes, y_mod, freqs, min_mes=1)
        h = bandwidths(y, opt.bandwidth, opt.min_bandwidth_db)
        log_likelihood = log_kde(x, y, h, method=opt.kernel).sum(axis=1)
        return frequency_mean(log_likelihood.reshape(grid), freqs)


@hookimpl
def suspid_register_objectives(register):
    """Register :class:`LikelihoodObjective` as ``likelihood``."""
    register(LikelihoodObjective)
