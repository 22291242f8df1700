"""The numerical experiment of paper §3.3: its two dates and their measurement process.

Two dates are simulated, both through one documented **measurement process**
(:class:`ReferenceOptions`, ``data.reference``) applied to the simulated
accelerations, so that the "measurements" are not the very simulations they
are compared with (or B would be zero) and carry what real records bring:

- *fixed gains*, the same on every segment and on both dates (the same vehicle
  and the same sensors): a flat gain per channel, different between channels
  (a sensor's calibration, rms ``channel_gain_db``), times a smooth gain
  g_k(f) per channel (what a rigid model misses in a structured way:
  unmodelled flexibility, sensor transfer functions; a stationary Gaussian
  process in log2(f) with rms ``model_error_db`` and a squared-exponential
  correlation of ``correlation_octaves``);
- *per-segment gains*, drawn anew for every segment of every date: a flat gain
  per channel (mounting, temperature, rms ``segment_gain_db``) and a smooth
  one (varying operating conditions, rms ``model_error_scatter_db``);
- a *sensor-noise floor*: white acceleration noise of rms ``sensor_noise_rms``
  (m/s^2) added to every channel, which adds power where the vehicle's
  response is weak and is not a gain.

The gains multiply the amplitude |Â(ω)|: in the paper's unit
Y = 10 log10 |Â| (eq. 1) a gain of g dB adds g to Y. So the noise model B
(eq. 3) identified at the reference date absorbs the fixed gains in its mean
and the per-segment gains in its covariance; the floor it absorbs only at
w0 (``noise.floor`` models it apart).

1. **Reference date** (identifies B, paper §2.3): the model at w0 on the
   reference-date track through the process.
2. **Measurement date**: the track measured on that date (its own
   realisations) and, by default (``data.measurement.errors: process``), the
   model at w_ref through the same process: the same fixed gains, new
   per-segment gains and sensor noise. With ``errors: noise-model`` it is the
   paper's eq. 10 instead, y_ref_i = y_sim_i(w_ref) + b_i with b_i drawn from
   the identified B (a measurement date that B describes exactly).

Every draw comes from the config's seed: the fixed gains from one stream
shared by every date (:func:`fixed_gains_db`), the per-segment parts from a
stream per date.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from suspid.options import Section
from suspid.interfaces import Response


class ReferenceOptions(Section):
    """``data.reference``: the measurement process of the numerical experiment (both dates), and the reference
    date's size and model."""

    n_segments: int | None = Field(default=None, ge=4,
                                   description="v0, segments at the reference date (default: as the measurement date)")
    sensor_noise_rms: float = Field(default=0.005, ge=0, description="white acceleration noise, m/s^2 rms "
                                    "(the sensors' noise floor)")
    channel_gain_db: float = Field(default=1.0, ge=0, description="fixed flat gain of each channel (calibration), "
                                   "dB rms; the same on both dates")
    segment_gain_db: float = Field(default=0.5, ge=0, description="flat gain of each channel on each segment "
                                   "(mounting, temperature), dB rms")
    model_error_db: float = Field(default=1.5, ge=0, description="systematic gain error per channel, dB rms")
    model_error_scatter_db: float = Field(default=1.0, ge=0, description="per-segment gain error, dB rms")
    correlation_octaves: float = Field(default=0.7, gt=0, description="correlation length of the gains, octaves")
    simulator_options: dict = Field(
        default_factory=dict,
        description="options merged into the simulator's for the reference date (a richer model, e.g. effects)")


class MeasurementOptions(Section):
    """``data.measurement``: how the measurement-date 'measurements' are simulated (numerical experiment).

    ``errors: process`` (the default) passes y_sim(w_ref)'s accelerations through the
    measurement process of ``data.reference`` (the same fixed gains as the reference
    date); ``errors: noise-model`` is the paper's eq. 10, y_sim_i(w_ref) + b_i with b_i
    drawn from the identified noise model.

    ``simulator_options`` are merged into the simulator's options for y_sim(w_ref)
    only: the "real" vehicle may have what the identification model lacks, e.g.
    a hidden effect (``{effects: [{name: carbody-bending, frequency_hz: 9.5}]}``),
    the test case of ``suspid diagnose``.
    """

    errors: Literal["process", "noise-model"] = Field(
        default="process", description="process: the reference date's measurement process (same fixed gains, new "
        "per-segment gains and sensor noise); noise-model: eq. 10, noise paths drawn from B")
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


def fixed_gains_db(rng: np.random.Generator, fs: float, n_channels: int, options: ReferenceOptions) -> np.ndarray:
    """``(n_channels, 512)`` dB on :func:`systematic_grid`: the gains that stay the same on every segment and date.

    The smooth systematic gain (rms ``model_error_db``) drawn first, then a flat gain
    per channel (rms ``channel_gain_db``) added to it.
    """
    f_ref = systematic_grid(fs)
    smooth = smooth_gain_db(rng, f_ref, n_channels, options.model_error_db, options.correlation_octaves)
    return smooth + options.channel_gain_db * rng.standard_normal(n_channels)[:, None]


def measurement_process(responses: list[Response], options: ReferenceOptions, rng: np.random.Generator,
                        fixed_seed: int) -> list[Response]:
    """:func:`apply_model_error` with the fixed gains drawn from ``fixed_seed`` (:func:`fixed_gains_db`).

    Every date of one experiment passes the same ``fixed_seed`` (one vehicle, one set of
    sensors) and its own ``rng`` (the per-segment gains and the sensor noise).
    """
    if not responses:
        return []
    fixed = fixed_gains_db(np.random.default_rng(fixed_seed), responses[0].fs,
                           responses[0].accelerations.shape[0], options)
    return apply_model_error(responses, options, rng, fixed)


def apply_model_error(responses: list[Response], options: ReferenceOptions,
                      rng: np.random.Generator, systematic: np.ndarray | None = None) -> list[Response]:
    """Turn simulated responses into 'measurements' through the measurement process (module docstring).

    :param responses: simulations, accelerations ``(n_channels, n_t)`` m/s^2.
    :param systematic: ``(n_channels, 512)`` dB, the fixed gains on :func:`systematic_grid`
        (another date of the same vehicle keeps them); default: drawn first from ``rng``
        (:func:`fixed_gains_db`).
    :returns: new responses of the same shapes.
    """
    if not responses:
        return []
    n_ch = responses[0].accelerations.shape[0]
    # the fixed gains are drawn on a reference grid common to all segments
    f_ref = systematic_grid(responses[0].fs)
    if systematic is None:
        systematic = fixed_gains_db(rng, responses[0].fs, n_ch, options)
    out = []
    for r in responses:
        n_t = r.accelerations.shape[1]
        f = np.fft.rfftfreq(n_t, 1.0 / r.fs)
        f_log = np.log2(np.maximum(f, 0.05))
        sys_here = np.array([np.interp(f_log, np.log2(f_ref), g) for g in systematic])
        scatter = smooth_gain_db(rng, f, n_ch, options.model_error_scatter_db, options.correlation_octaves)
        flat = options.segment_gain_db * rng.standard_normal(n_ch)[:, None]
        gain = 10.0 ** ((sys_here + scatter + flat) / 10.0)  # Y = 10 log10|A|: g dB multiplies |A| by 10^(g/10)
        a = np.fft.irfft(np.fft.rfft(r.accelerations, axis=1) * gain, n=n_t, axis=1)
        a = a + options.sensor_noise_rms * rng.standard_normal(a.shape)
        out.append(Response(r.channels, r.fs, a, r.segment))
    return out
