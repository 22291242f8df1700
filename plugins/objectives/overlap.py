"""The overlap objective Ψ_k of paper eq. 7-8, registered as ``overlap``.

    Ψ_k(w) = (1/|Ω|) ∫_Ω OVL(p_{Y_k^mes}(·; ω), p_{Y_k^mod}(·; ω, w)) dω          (eq. 7)
    OVL(p_1, p_2) = 1 - ½ ∫_R |p_1(u) - p_2(u)| du = ∫_R min(p_1, p_2) du          (eq. 8)

Both densities are Gaussian kernel estimates at (k, ω), each with its own
bandwidth, from the measured samples and from the modelled samples
y_mod_i = y_sim_i(w) + b_i. They are evaluated on a grid by linear binning and
FFT smoothing (:func:`suspid.method.kde.overlap_coefficient`): with ``grid_size`` 256
the OVL of v = 100 samples is within about 2e-4 of its exact value (the
error falls as grid_size^-2). Ψ_k is dimensionless in [0, 1]; 1 means the
two densities coincide at every frequency. Higher is better.

Select it with ``objective: {plugin: overlap, options: {grid_size: 256}}``.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from suspid import hookimpl
from suspid.options import parse_options
from suspid.interfaces import Objective
from suspid.method.kde import KdeOptions, bandwidths, frequency_mean, overlap_coefficient, prepare


class OverlapOptions(KdeOptions):
    """``objective.options`` of ``overlap``: bandwidth rule, and the grid the densities are compared on."""

    grid_size: int = Field(default=256, ge=32, le=16384,
                           description="grid points per (channel, ω); error about (256/grid_size)² × 2e-4")
    tail_bandwidths: float = Field(default=6.0, ge=4.0, le=20.0,
                                   description="grid margin beyond the data, in bandwidths")


class OverlapObjective(Objective):
    """Ψ_k of eq. 7-8: frequency-averaged overlap of the measured and modelled densities."""

    name = "overlap"
    Options = OverlapOptions

    def psi(self, y_mes: np.ndarray, y_mod: np.ndarray, freqs: np.ndarray) -> np.ndarray:
        """Ψ_k for every channel (eq. 7-8).

        :param y_mes: ``(n_mes, n_channels, n_freqs)`` measured spectra in dB, n_mes >= 2.
        :param y_mod: ``(n_mod, n_channels, n_freqs)`` modelled spectra in dB, n_mod >= 2.
        :param freqs: ``(n_freqs,)`` in Hz, strictly increasing.
        :returns: ``(n_channels,)`` in [0, 1].
        :raises DataError: shapes or values that do not fit; ``ConfigError`` for bad options.
        """
        opt = parse_options(OverlapOptions, self.options, "objective.options")
        x, y, freqs, grid = prepare(y_mes, y_mod, freqs, min_mes=2)
        ovl = overlap_coefficient(x, y, bandwidths(x, opt.bandwidth, opt.min_bandwidth_db),
                                  bandwidths(y, opt.bandwidth, opt.min_bandwidth_db),
                                  grid_size=opt.grid_size, tail=opt.tail_bandwidths)
        return frequency_mean(ovl.reshape(grid), freqs)


@hookimpl
def suspid_register_objectives(register):
    """Register :class:`OverlapObjective` as ``overlap``."""
    register(OverlapObjective)
