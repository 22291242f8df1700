"""A baseline objective: least squares between mean spectra, registered as ``mean-spectrum``.

    Ψ_k(w) = -(1/|Ω|) ∫_Ω (ȳ_k^mes(ω) - ȳ_k^mod(ω, w))² / σ_k²(ω) dω

ȳ^mes and ȳ^mod are the means over segments of the measured and modelled
log-spectra (dB) at (k, ω), σ_k²(ω) the noise model's variance there (dB²): the
sample variance of the run's noise paths b_i, which
:class:`~suspid.method.objective.ObjectiveFunction` passes in
(``uses_noise_variance``), floored at ``min_variance_db2``. Called without it
(e.g. by hand) every weight is 1/dB². This is what an engineer would try
first: it compares only the first moment of the two distributions at each
frequency, where ``likelihood`` and ``overlap`` (paper eq. 6-8) compare their
densities. A uniform shift of d dB gives Ψ_k = -d²/σ²; identical means give
the maximum 0. Dimensionless, higher is better.

Select it with ``objective: {plugin: mean-spectrum}``.
"""

from __future__ import annotations

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from suspid import hookimpl
from suspid.errors import DataError
from suspid.interfaces import Objective
from suspid.method.kde import frequency_mean, prepare
from suspid.options import parse_options


class MeanSpectrumOptions(BaseModel):
    """``objective.options`` of ``mean-spectrum``."""

    model_config = ConfigDict(extra="forbid")

    min_variance_db2: float = Field(default=1e-3, gt=0.0,
                                    description="floor of the noise variance σ² (dB²), so a channel "
                                                "without noise cannot divide by zero")


class MeanSpectrumObjective(Objective):
    """Ψ_k = -mean over Ω of the squared difference of mean log-spectra over the noise variance."""

    name = "mean-spectrum"
    Options = MeanSpectrumOptions
    uses_noise_variance = True

    def psi(self, y_mes: np.ndarray, y_mod: np.ndarray, freqs: np.ndarray,
            noise_variance: np.ndarray | None = None) -> np.ndarray:
        """Ψ_k for every channel.

        :param y_mes: ``(n_mes, n_channels, n_freqs)`` measured spectra in dB.
        :param y_mod: ``(n_mod, n_channels, n_freqs)`` modelled spectra in dB, n_mod >= 2.
        :param freqs: ``(n_freqs,)`` in Hz, strictly increasing.
        :param noise_variance: ``(n_channels, n_freqs)`` dB², σ²; ``None``: 1 dB² everywhere.
        :returns: ``(n_channels,)``, <= 0, dimensionless.
        :raises DataError: shapes or values that do not fit; ``ConfigError`` for bad options.
        """
        opt = parse_options(MeanSpectrumOptions, self.options, "objective.options")
        x, y, freqs, grid = prepare(y_mes, y_mod, freqs, min_mes=1)
        variance = np.ones(grid) if noise_variance is None else np.asarray(noise_variance, dtype=float)
        if variance.shape != grid or not np.all(np.isfinite(variance)):
            raise DataError(f"noise_variance must be finite with shape {grid} (n_channels, n_freqs), "
                            f"got {variance.shape}")
        d2 = (x.mean(axis=1) - y.mean(axis=1)) ** 2 / np.maximum(variance.ravel(), opt.min_variance_db2)
        return -frequency_mean(d2.reshape(grid), freqs)


@hookimpl
def suspid_register_objectives(register):
    """Register :class:`MeanSpectrumObjective` as ``mean-spectrum``."""
    register(MeanSpectrumObjective)
