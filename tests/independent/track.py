"""Track for the independent train: true irregularities and the recording car's measurement of them.

Written apart from :mod:`suspid.data.track` (numpy/scipy only).

True track
----------
Four channels as functions of distance s (m), in metres: ``vertical`` V (mean
level of the two rails, up positive), ``lateral`` Y (mean alignment, left
positive), ``cross_level`` C (left rail height minus right rail height) and
``gauge`` G (deviation from nominal, wider positive). Rail by rail:
left rail height V + C/2, right V - C/2; left rail lateral position
Y + G/2, right Y - G/2.

Spectra (German low-disturbance, distance domain, one-sided, Omega in rad/m):

- V: A_v Wc^2 / ((W^2 + Wr^2)(W^2 + Wc^2)), A_v = 4.032e-7 m rad;
- Y: the same shape with A_a = 2.119e-7 m rad;
- C: the published cross-level spectrum (A_v / b^2) Wc^2 W^2 / ((W^2 + Wr^2)(W^2 + Wc^2)(W^2 + Ws^2))
  is a PSD of the track's roll *angle* (rad^2/(rad/m)); the rail height
  difference is that angle times 2b (b = 0.75 m), so S_C = 4 A_v Wc^2 W^2 / (...);
- G: A_g Wc^2 W^2 / (...), A_g = 0.532e-7 m rad;

with Wc = 0.8246, Wr = 0.0206, Ws = 0.4380 rad/m.

A realisation is periodic over its length (``n`` samples every ``dx``): a
sum of cosines at W_k = 2 pi k / (n dx) with complex Gaussian coefficients
(E|amplitude|^2 = 2 S(W_k) dW, so the variance is the integral of S), made
with one inverse real FFT per channel. A periodic track lets the vehicle
model compute its exact steady-state response by FFT (no start transient).

Recording car (:func:`record`)
------------------------------
The "measured track" written next to the accelerations is not the true track:

- the recording car's chain has a high-pass (2nd-order Butterworth, zero
  phase, cut-off wavelength ``highpass_wavelength_m``, 300 m by default);
- it samples every ``dx_m`` (0.25 m), a different grid from the true track's;
- its odometer places the samples with a constant offset (metres, drawn per
  segment, std ``odometry_std_m``);
- each sample carries white noise (std ``noise_std_m``, 0.1 mm).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

CHANNELS = ("vertical", "lateral", "cross_level", "gauge")
"""Track channels, in the order of every ``(4, n)`` array of this package."""

OMEGA_C, OMEGA_R, OMEGA_S, HALF_GAUGE_B = 0.8246, 0.0206, 0.4380, 0.75
"""German spectra constants: rad/m, rad/m, rad/m, and b in m."""

LOW_DISTURBANCE = {"vertical": 4.032e-7, "lateral": 2.119e-7, "gauge": 0.532e-7}
"""A_v, A_a, A_g of the German low-disturbance spectra, m rad."""


def german_low_psd(channel: str, omega: np.ndarray) -> np.ndarray:
    """One-sided PSD ``(n,)`` in m^2/(rad/m) of one channel at wavenumbers ``omega`` ``(n,)`` rad/m."""
    w2 = np.asarray(omega, dtype=float) ** 2
    base = OMEGA_C ** 2 / ((w2 + OMEGA_R ** 2) * (w2 + OMEGA_C ** 2))
    if channel == "vertical":
        return LOW_DISTURBANCE["vertical"] * base
    if channel == "lateral":
        return LOW_DISTURBANCE["lateral"] * base
    shaped = base * w2 / (w2 + OMEGA_S ** 2)
    if channel == "cross_level":
        return 4.0 * LOW_DISTURBANCE["vertical"] * shaped   # angle PSD (A_v / b^2) times (2 b)^2
    if channel == "gauge":
        return LOW_DISTURBANCE["gauge"] * shaped
    raise ValueError(f"unknown track channel '{channel}'; channels: {', '.join(CHANNELS)}")


def true_track(n: int, dx: float, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
    """A periodic realisation ``(4, n)`` m of the four channels on ``s = dx * arange(n)``.

    :param n: number of samples (the period is ``n * dx`` m).
    :param dx: distance step, m.
    :param scale: factor on the amplitudes (0 gives a perfect track).
    """
    k = np.arange(n // 2 + 1)
    d_omega = 2.0 * np.pi / (n * dx)
    omega = k * d_omega
    out = np.empty((len(CHANNELS), n))
    for i, ch in enumerate(CHANNELS):
        s = np.zeros_like(omega)
        s[1:] = german_low_psd(ch, omega[1:])
        if n % 2 == 0:
            s[-1] = 0.0                      # no Nyquist line
        coef = np.sqrt(s * d_omega) * (rng.standard_normal(omega.size) + 1j * rng.standard_normal(omega.size))
        out[i] = np.fft.irfft(coef * (n / 2.0), n) * scale
    return out


@dataclass(frozen=True)
class RecordingCar:
    """How the track geometry is measured (see the module docstring). Lengths in m."""

    dx_m: float = 0.25
    noise_std_m: float = 1.0e-4
    odometry_std_m: float = 0.5
    highpass_wavelength_m: float = 300.0


def record(track: np.ndarray, dx: float, start_m: float, length_m: float, car: RecordingCar,
           rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The recording car's measurement of one segment of a periodic true track.

    :param track: ``(4, n)`` m, periodic true track on ``s = dx * arange(n)``.
    :param start_m: position of the segment's first sample on that axis, m.
    :param length_m: segment length, m (a multiple of ``car.dx_m``).
    :returns: ``offsets`` ``(n_x,)`` m from the segment start (``0, dx_m, ...,
        length_m``) and ``measured`` ``(4, n_x)`` m.
    """
    n = track.shape[1]
    period = n * dx
    k = np.fft.rfftfreq(n, d=dx)                     # cycles per metre
    spec = np.fft.rfft(track, axis=1)
    if car.highpass_wavelength_m > 0:
        r = (k * car.highpass_wavelength_m) ** 2     # (k / k_c)^2
        spec = spec * (r ** 2 / (1.0 + r ** 2))       # |H|^2 of a 2nd-order Butterworth high-pass (zero phase)
    # band-limited interpolation: 8x oversampling by zero padding, then a cubic spline
    up = 8
    fine = np.fft.irfft(spec, n * up, axis=1) * up
    s_fine = np.arange(n * up + 1) * (dx / up)
    fine = np.concatenate([fine, fine[:, :1]], axis=1)   # periodic closure
    n_x = int(round(length_m / car.dx_m)) + 1
    offsets = np.arange(n_x) * car.dx_m
    shift = rng.normal(0.0, car.odometry_std_m) if car.odometry_std_m > 0 else 0.0
    where = np.mod(start_m + offsets + shift, period)
    spline = CubicSpline(s_fine, fine, axis=1, bc_type="periodic")
    measured = spline(where) + rng.normal(0.0, car.noise_std_m, size=(len(CHANNELS), n_x))
    return offsets, measured
