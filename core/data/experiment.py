"""The numerical experiment of paper §3.3, and its reference date.

Two dates are simulated:

1. **Reference date** (identifies the noise model B, paper §2.3). The
   "measurements" must not be the very simulations they are compared with,
   or B would be zero. They are the model at w0 on the reference-date track,
   made into a measurement by a prescribed, documented model-error process
   (:class:`ReferenceOptions`), applied to the accelerations:

   - a *systematic* model error: a smooth gain g_k(f) in dB per channel, the
     same on every segment (what a rigid model misses in a structured way:
     unmodelled flexibility, sensor transfer functions); a stationary
     Gaussian process in log2(f) with rms ``model_error_db`` and a
     squared-exponential correlation of ``correlation_octaves``;
   - a *random* model error: another such gain, drawn anew for every segment
     with rms ``model_error_scatter_db`` (varying operating conditions);
   - *sensor noise*: white acceleration noise of rms ``sensor_noise_rms``
     (m/s^2) added to every channel.

   The gains multiply the amplitude |Â(ω)|: in the paper's unit
   Y = 10 log10 |Â| (eq. 1) a gain of g dB adds g to Y.

2. **Measurement date**: the track measured on that date (its own
   realisations) and y_ref_i = y_sim_i(w_ref) + b_i (eq. 10), with b_i drawn
   from the identified noise model, independent of the paths used in Y_mod.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from suspid.options import Section
from suspid.interfaces import Response


class ReferenceOptions(Section):
    """``data.reference``: how the reference-date measurements are made (numerical experiment)."""

    n_segments: int | None = Field(default=None, ge=4,
                                   description="v0, segments at the reference date (default: as the measurement date)")
    sensor_noise_rms: float = Field(default=0.005, ge=0, description="white acceleration noise, m/s^2 rms")
    model_error_db: float = Field(default=1.5, ge=0, description="systematic gain error per channel, dB rms")
    model_error_scatter_db: float = Field(default=1.0, ge=0, description="per-segment gain error, dB rms")
    correlation_octaves: float = Field(default=0.7, gt=0, description="correlation length of the gains, octaves")
    simulator_options: dict = Field(
        default_factory=dict,
        description="options merged into the simulator's for the reference date (a richer model, e.g. effects)")


class MeasurementOptions(Section):
    """``data.measurement``: how the measurement-date 'measurements' of eq. 10 are simulated (numerical experiment).

    ``simulator_options`` are merged into the simulator's options for y_sim(w_ref)
    only: the "real" vehicle may have what the identification model lacks, e.g.
    a hidden effect (``{effects: [{name: carbody-bending, frequency_hz: 9.5}]}``),
    the test case of ``suspid diagnose``.
    """

    simulator_options: dict = Field(
        default_factory=dict, description="options merged into the simulator's for the measurement-date data")


def smooth_gain_db(rng: np.random.Generator, freqs: np.ndarray, n_channels: int, rms_db: float,
                   correlation_octaves: float, f_floor: float = 0.05) -> np.ndarray:
    """Random smooth gains in dB, ``(n_channels, n_freqs)``, a stationary GP in log2(f).

    Drawn exactly on a grid of 96 log-spaced points (Cholesky of the
    squared-exponential covariance, with a 1e-8 jitter) and interpolated
    linearly in log2(f) onto ``freqs`` (Hz). Frequencies below ``f_floor`` take
    the value at ``f_floor``.
    """
    f = np.maximum(np.asarray(freqs, dtype=float), f_floor)
    lo, hi = np.log2(f.min()), np.log2(max(f.max(), f.min() * 1.001))
    grid = np.linspace(lo, hi, 96)
    cov = np.exp(-0.5 * ((grid[:, None] - grid[None, :]) / correlation_octaves) ** 2)
    chol = np.linalg.cholesky(cov + 1e-8 * np.eye(grid.size))
    draws = rms_db * (chol @ rng.standard_normal((grid.size, n_channels))).T
    return np.array([np.interp(np.log2(f), grid, d) for d in draws])


def systematic_grid(fs: float) -> np.ndarray:
    """``(512,)`` Hz: the grid on which :func:`apply_model_error` draws the systematic gain."""
    return np.geomspace(0.05, fs / 2, 512)


def apply_model_error(responses: list[Response], options: ReferenceOptions,
                      rng: np.random.Generator, systematic: np.ndarray | None = None) -> list[Response]:
    """Turn simulated responses into reference-date 'measurements' (see the module docstring).

    :param responses: simulations at w0, accelerations ``(n_channels, n_t)`` m/s^2.
    :param systematic: ``(n_channels, 512)`` dB, the systematic gain on :func:`systematic_grid`
        (another date of the same vehicle keeps it); default: drawn first from ``rng``.
    :returns: new responses of the same shapes.
    """
    if not responses:
        return []
    n_ch = responses[0].accelerations.shape[0]
    # the systematic gain is drawn on a reference grid common to all segments
    f_ref = systematic_grid(responses[0].fs)
    if systematic is None:
        systematic = smooth_gain_db(rng, f_ref, n_ch, options.model_error_db, options.correlation_octaves)
    out = []
    for r in responses:
        n_t = r.accelerations.shape[1]
        f = np.fft.rfftfreq(n_t, 1.0 / r.fs)
        f_log = np.log2(np.maximum(f, 0.05))
        sys_here = np.array([np.interp(f_log, np.log2(f_ref), g) for g in systematic])
        scatter = smooth_gain_db(rng, f, n_ch, options.model_error_scatter_db, options.correlation_octaves)
        gain = 10.0 ** ((sys_here + scatter) / 10.0)  # Y = 10 log10|A|: g dB multiplies |A| by 10^(g/10)
        a = np.fft.irfft(np.fft.rfft(r.accelerations, axis=1) * gain, n=n_t, axis=1)
        a = a + options.sensor_noise_rms * rng.standard_normal(a.shape)
        out.append(Response(r.channels, r.fs, a, r.segment))
    return out
