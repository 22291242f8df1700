"""Spectra of accelerations in dB on one frequency grid Ω (paper §2.2, eq. 1-2).

For one record A(t) of duration T, sampled at fs (Hz) over [0, T],

    Â(ω) = (1/√T) ∫_0^T A(t) e^{-iωt} dt          (eq. 2)
    Y(ω) = 10 log10 |Â(ω)|                         (eq. 1)

Y is **10 log10 of an amplitude**, as the paper defines it (not 20 log10, not
a power spectral density): a gain of g dB in Y multiplies |Â| by 10^(g/10).
With accelerations in m/s^2, Â is in m s^-1.5 and Y in dB re 1 m s^-1.5.

Discretisation. With samples a_n = A(n/fs), n = 0..N-1, T = N/fs and the
DFT X_k = Σ_n a_n e^{-2πi kn/N}, the rectangle rule gives
Â(f_k) = X_k / (fs √T) at f_k = k/T (Hz). Parseval then reads
(1/T) ∫ A² dt = Σ_k |Â(f_k)|² / T over the two-sided DFT, i.e. |Â|² is a
power spectral density (two-sided, (m/s²)²/Hz) whose expectation does not
depend on T for a stationary signal: that is what the 1/√T of eq. 2 buys.

Common grid Ω. Segments differ in length (T, hence the native resolution
1/T) and in speed, so their native frequencies differ. Every spectrum is
brought onto the grid Ω of ``spectra:`` (:class:`SpectraOptions`) by
**band-averaging the power**: each grid frequency f_j owns a cell
[lower_j, upper_j) (cells tile the band; the midpoints between neighbouring
grid points are the edges, geometric midpoints on a log grid), and

    Y(f_j) = 10 log10 sqrt( mean_{f_k in cell j} |Â(f_k)|² ),

the 10 log10 of the RMS amplitude over the cell. Why this and not
interpolation of |Â|: interpolation at a grid coarser than 1/T would skip
most native lines (the random spectrum would be aliased), and at a grid finer
than 1/T would invent values; averaging |Â|² uses every line once, keeps the
level of a stationary signal independent of T (the mean of |Â|² estimates
the PSD), and conserves energy (Parseval holds cell by cell). The price: a
sinusoid's peak is diluted by the number of lines M in its cell
(Y drops by 5 log10 M dB), and the log of an average of M lines has a
T-dependent bias for random signals, E[Y] = 5 log10 S + (5/ln 10)(ψ(M) - ln M)
for a Gaussian stationary signal of PSD S (-1.25 dB at M = 1, -0.28 dB at
M = 4); ``log_bias_correction`` removes it. Speed is *not* normalised away:
the paper's ω is a time frequency, and suspension and carbody resonances sit
at fixed frequencies in Hz whatever the speed. Every cell must hold at least
``min_lines_per_cell`` native lines; a record too short for the grid is a
:class:`~suspid.errors.DataError`.

Options also offer smoothing across frequency (cells widened to a band of
constant relative width, in octaves), a Hann window (power-normalised, so
levels and Parseval are kept), and removal of the mean or a linear trend
before the transform. Defaults suit carbody and bogie accelerations: 0.3-30 Hz,
300 linearly spaced frequencies (0.1 Hz cells, records of 10 s or more).
"""

from __future__ import annotations

import math
from typing import Any, Literal, Mapping, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, model_validator
from scipy import fft as sp_fft
from scipy.special import digamma

try:  # numba is a dependency; without it the spectra's derivatives fall back to numpy
    from numba import njit
except ImportError:  # pragma: no cover - exercised only without numba
    njit = None

from suspid.options import parse_options
from suspid.errors import DataError
from suspid.interfaces import Response

AMPLITUDE_FLOOR = 1e-15
"""|Â| floor in m s^-1.5 before the log: Y >= -150 dB, so that an all-zero channel gives no -inf."""


class SpectraOptions(BaseModel):
    """The ``spectra:`` section: the frequency grid Ω and how spectra are put on it.

    Frequencies in Hz. Either ``n_freqs`` or ``df_hz`` fixes the grid (``df_hz``
    only for a linear grid); with neither, 300 frequencies.
    """

    model_config = ConfigDict(extra="forbid")

    f_min_hz: PositiveFloat = Field(default=0.3, description="lowest grid frequency, Hz")
    f_max_hz: PositiveFloat = Field(default=30.0, description="highest grid frequency, Hz")
    n_freqs: int | None = Field(default=None, ge=2, description="number of grid frequencies |Ω|")
    df_hz: PositiveFloat | None = Field(default=None, description="grid spacing for a linear grid, Hz")
    spacing: Literal["linear", "log"] = Field(default="linear", description="grid spacing")
    smoothing_octaves: PositiveFloat | None = Field(
        default=None, le=3.0,
        description="average at least over [f 2^(-b/2), f 2^(b/2)] (constant relative width b, octaves)")
    window: Literal["boxcar", "hann"] = Field(
        default="boxcar", description="boxcar is eq. 2 as written; hann is power-normalised")
    detrend: Literal["none", "mean", "linear"] = Field(
        default="mean", description="removed from each channel before the transform")
    min_lines_per_cell: int = Field(default=1, ge=1, description="native DFT lines every grid cell must hold")
    log_bias_correction: bool = Field(
        default=False, description="remove the bias (5/ln10)(ψ(M) - ln M) dB of the log of an M-line average")

    @model_validator(mode="after")
    def _check_grid(self) -> "SpectraOptions":
        if not self.f_max_hz > self.f_min_hz:
            raise ValueError(f"f_max_hz ({self.f_max_hz:g}) must be above f_min_hz ({self.f_min_hz:g})")
        if self.n_freqs is not None and self.df_hz is not None:
            raise ValueError("give either n_freqs or df_hz, not both")
        if self.df_hz is not None:
            if self.spacing == "log":
                raise ValueError("df_hz needs spacing: linear (a log grid is fixed by n_freqs)")
            if self.df_hz > self.f_max_hz - self.f_min_hz:
                raise ValueError(f"df_hz ({self.df_hz:g}) leaves fewer than 2 frequencies in the band")
        return self


def frequency_grid(options: SpectraOptions | Mapping[str, Any] | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid Ω and the band each grid frequency averages over.

    :returns: ``freqs``, ``lower``, ``upper``, each ``(n_freqs,)`` in Hz; the
        line f_k belongs to grid point j when ``lower[j] <= f_k < upper[j]``.
        Without smoothing the cells tile [lower[0], upper[-1]).
    """
    opt = parse_options(SpectraOptions, options, "spectra")
    f0, f1 = opt.f_min_hz, opt.f_max_hz
    if opt.spacing == "log":
        n = opt.n_freqs or 300
        freqs = np.geomspace(f0, f1, n)
        half_step = (f1 / f0) ** (0.5 / (n - 1))
        lower, upper = freqs / half_step, freqs * half_step
    else:
        if opt.df_hz is not None:
            n = int(math.floor((f1 - f0) / opt.df_hz + 1e-9)) + 1
            freqs = f0 + opt.df_hz * np.arange(n)
        else:
            freqs = np.linspace(f0, f1, opt.n_freqs or 300)
        step = freqs[1] - freqs[0]
        lower, upper = freqs - step / 2, freqs + step / 2
    if opt.smoothing_octaves is not None:
        half_band = 2.0 ** (opt.smoothing_octaves / 2)
        lower, upper = np.minimum(lower, freqs / half_band), np.maximum(upper, freqs * half_band)
    return freqs, np.maximum(lower, 0.0), upper


def _prepare(a: np.ndarray, options: SpectraOptions) -> np.ndarray:
    """Detrended and windowed copy of ``a`` ``(n_channels, n_t)``."""
    n_t = a.shape[-1]
    if options.detrend == "mean":
        a = a - a.mean(axis=-1, keepdims=True)
    elif options.detrend == "linear":
        t = np.arange(n_t) - (n_t - 1) / 2
        slope = (a @ t) / (t @ t)
        a = a - a.mean(axis=-1, keepdims=True) - slope[:, None] * t
    if options.window == "hann":
        w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(n_t) / n_t)  # periodic ("DFT-even") Hann
        a = a * (w / np.sqrt(np.mean(w * w)))  # power-normalised: E|Â|² of a stationary signal is kept
    return a


def fourier_amplitude(accelerations: np.ndarray, fs: float,
                      options: SpectraOptions | Mapping[str, Any] | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Â(f_k) of eq. 2 at the native one-sided frequencies f_k = k/T, k = 0..N//2.

    :param accelerations: ``(n_channels, n_t)`` or ``(n_t,)`` in m/s^2, sampled at ``fs``.
    :param fs: sampling rate in Hz.
    :param options: only ``window`` and ``detrend`` are used (default: the
        :class:`SpectraOptions` defaults; pass ``{"detrend": "none"}`` for eq. 2 verbatim).
    :returns: ``f`` ``(N//2 + 1,)`` in Hz and complex ``Â`` ``(n_channels, N//2 + 1)``
        (or ``(N//2 + 1,)``) in m s^-1.5, Â(f_k) = X_k / (fs √T).
    """
    opt = parse_options(SpectraOptions, options, "spectra")
    a = np.asarray(accelerations, dtype=float)
    n_t = a.shape[-1]
    a2 = _prepare(a.reshape(-1, n_t), opt)
    spectrum = np.fft.rfft(a2, axis=-1) / (fs * math.sqrt(n_t / fs))
    return np.fft.rfftfreq(n_t, 1.0 / fs), spectrum.reshape(a.shape[:-1] + (n_t // 2 + 1,))


def grid_lines(n_t: int, fs: float, options: SpectraOptions | Mapping[str, Any] | None = None,
               what: str = "record") -> tuple[np.ndarray, np.ndarray]:
    """Which native DFT lines of a record of ``n_t`` samples at ``fs`` Hz fall in each cell of Ω.

    Needs only the record's length, so that a dry run can check a run's records
    before anything is simulated.

    :returns: ``(start, stop)``, each ``(n_freqs,)``: cell j holds lines k = start_j + 1 .. stop_j
        (line 0, DC, is never in Ω).
    :raises DataError: the grid reaches above the Nyquist frequency, or a cell holds fewer
        than ``min_lines_per_cell`` lines (the record is too short for the grid).
    """
    opt = parse_options(SpectraOptions, options, "spectra")
    freqs, lower, upper = frequency_grid(opt)
    duration = n_t / fs
    if upper[-1] > fs / 2:
        raise DataError(f"{what}: the grid reaches {upper[-1]:.4g} Hz, above the Nyquist frequency "
                        f"fs/2 = {fs / 2:.4g} Hz; lower spectra.f_max_hz or sample faster")
    f_native = np.fft.rfftfreq(n_t, 1.0 / fs)
    # native line k >= 1 (DC is never in Ω) is in cell j when lower[j] <= f_k < upper[j]
    start = np.searchsorted(f_native[1:], lower, side="left")
    stop = np.searchsorted(f_native[1:], upper, side="left")
    count = stop - start
    short = np.flatnonzero(count < opt.min_lines_per_cell)
    if short.size:
        j = short[0]
        raise DataError(
            f"{what} is too short for the frequency grid: T = {duration:.4g} s gives lines every "
            f"{1 / duration:.4g} Hz, but the cell at {freqs[j]:.4g} Hz ({upper[j] - lower[j]:.4g} Hz wide) "
            f"holds {count[j]} (at least {opt.min_lines_per_cell} needed); use longer records, fewer "
            f"frequencies (spectra.n_freqs) or spectra.smoothing_octaves")
    return start, stop


def cell_means(power: np.ndarray, start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """Mean of ``power (..., N//2 + 1)`` over the native lines of each cell of Ω (lines start+1 .. stop,
    :func:`grid_lines`): ``(..., n_freqs)``. Linear in ``power``: the spectra's derivatives use it too."""
    lines = power[..., 1:]
    lines = np.concatenate([lines, np.zeros(lines.shape[:-1] + (1,))], axis=-1)  # reduceat may index the end
    # exact sums over [start, stop) per cell (cells may overlap with smoothing): every other reduceat slot
    sums = np.add.reduceat(lines, np.column_stack([start, stop]).ravel(), axis=-1)[..., ::2]
    return sums / (stop - start)


def _checked(accelerations: np.ndarray, fs: float, what: str) -> np.ndarray:
    """The record as a float array, or a :class:`DataError` naming it."""
    a = np.asarray(accelerations, dtype=float)
    if a.ndim != 2 or a.shape[1] < 2:
        raise DataError(f"{what}: accelerations must be (n_channels, n_t) with n_t >= 2, got shape {a.shape}")
    if not (math.isfinite(fs) and fs > 0):
        raise DataError(f"{what}: sampling rate must be a positive number of Hz, got {fs!r}")
    if not np.all(np.isfinite(a)):
        raise DataError(f"{what}: accelerations contain NaN or infinite values")
    return a


def record_spectrum(accelerations: np.ndarray, fs: float,
                    options: SpectraOptions | Mapping[str, Any] | None = None,
                    name: str = "") -> np.ndarray:
    """Y on the grid Ω for one record (eq. 1-2, band-averaged as in the module docstring).

    :param accelerations: ``(n_channels, n_t)`` in m/s^2, sampled at ``fs`` Hz.
    :param name: the record's name for error messages (the segment).
    :returns: ``(n_channels, n_freqs)`` in dB re 1 m s^-1.5.
    :raises DataError: non-finite samples, a band above the Nyquist frequency,
        or a record too short for the grid.
    """
    opt = parse_options(SpectraOptions, options, "spectra")
    what = f"record '{name}'" if name else "record"
    a = _checked(accelerations, fs, what)
    return _record_power(a, fs, opt, what)[0]


def _record_power(a: np.ndarray, fs: float, opt: SpectraOptions, what: str = "record"
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(y, mean_power, a_hat, start, stop)`` of a checked record ``(n_channels, n_t)`` (:func:`record_spectrum`)."""
    start, stop = grid_lines(a.shape[1], fs, opt, what)
    count = stop - start
    f_native, a_hat = fourier_amplitude(a, fs, opt)
    mean_power = cell_means(np.abs(a_hat) ** 2, start, stop)
    y = 5.0 * np.log10(np.maximum(mean_power, AMPLITUDE_FLOOR ** 2))
    if opt.log_bias_correction:
        y -= (5.0 / math.log(10.0)) * (digamma(count) - np.log(count))
    return y, mean_power, a_hat, start, stop


def record_spectrum_derivatives(accelerations: np.ndarray, d_accelerations: np.ndarray, fs: float,
                                options: SpectraOptions | Mapping[str, Any] | None = None,
                                name: str = "", out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Y (:func:`record_spectrum`) and its derivatives from those of the accelerations.

    Detrend, window and transform are linear, so dÂ is the amplitude of dA; with P_j the mean of |Â|² over
    cell j, Y_j = 5 log10 P_j and dY_j = (5 / ln 10) dP_j / P_j, dP_j the cell mean of 2 Re(conj(Â) dÂ)
    (0 where P_j sits at the amplitude floor).

    :param d_accelerations: ``(n_p, n_channels, n_t)``, (m/s²) per unit of each parameter; single precision
        is kept (the transform and the products in float32, the sums over each cell in double).
    :param out: where to write dY, ``(n_p, n_channels, n_freqs)`` float (a view of a larger array: a caller's
        Jacobian in its own layout), or ``None``.
    :returns: ``Y (n_channels, n_freqs)`` dB and ``dY (n_p, n_channels, n_freqs)`` dB per unit.
    """
    opt = parse_options(SpectraOptions, options, "spectra")
    what = f"record '{name}'" if name else "record"
    a = _checked(accelerations, fs, what)
    y, mean, a_hat, start, stop = _record_power(a, fs, opt, what)
    d = np.asarray(d_accelerations)
    if d.dtype not in (np.float32, np.float64):
        d = d.astype(float)
    n_t = d.shape[-1]
    scale = 1.0 / (fs * math.sqrt(n_t / fs))
    if opt.detrend == "mean" and opt.window == "boxcar":
        # removing a constant moves line 0 alone, which no cell of Ω holds: the transform of d as it is, in
        # d's own precision (single-precision records of a simulator's derivatives stay single)
        da_hat = sp_fft.rfft(d, axis=-1)
    else:
        da_hat = sp_fft.rfft(_prepare(d.reshape(-1, n_t), opt), axis=-1).reshape(d.shape[:-1] + (-1,))
    dy = np.empty(da_hat.shape[:-1] + (start.size,)) if out is None else out
    _cell_derivatives(np.ascontiguousarray(a_hat), da_hat.reshape(-1, *a_hat.shape), start, stop, mean,
                      scale, dy.reshape(-1, *mean.shape) if out is None else dy)
    return y, dy


def _cell_derivatives_numpy(a_hat: np.ndarray, da_hat: np.ndarray, start: np.ndarray, stop: np.ndarray,
                            mean: np.ndarray, scale: float, out: np.ndarray) -> None:
    """out ``(n_p, n_channels, n_freqs)`` = (5 / ln 10) ∂P / P with ∂P the cell means of 2 Re(conj(Â) scale dÂ)
    (0 where P sits at the amplitude floor); ``a_hat (n_channels, n_lines)``, ``da_hat (n_p, n_channels,
    n_lines)`` unscaled. The reference of the compiled :func:`_cell_derivatives`."""
    top = int(np.max(stop)) + 1                   # lines above the grid's last cell are not read
    a_top, da_top = a_hat[:, :top], da_hat[..., :top]
    dmean = cell_means(2.0 * scale * (a_top.real[None] * da_top.real + a_top.imag[None] * da_top.imag),
                       start, stop)
    live = mean > AMPLITUDE_FLOOR ** 2
    out[...] = np.where(live[None], (5.0 / math.log(10.0)) * dmean / np.where(live, mean, 1.0)[None], 0.0)


if njit is not None:
    @njit(cache=True, nogil=True)
    def _cell_derivatives(a_hat, da_hat, start, stop, mean, scale, out):  # pragma: no cover - compiled
        factor = 2.0 * scale * 5.0 / math.log(10.0)
        floor = AMPLITUDE_FLOOR ** 2
        n_p, n_ch = da_hat.shape[0], da_hat.shape[1]
        for k in range(n_p):
            for c in range(n_ch):
                for j in range(start.size):
                    if not mean[c, j] > floor:
                        out[k, c, j] = 0.0
                        continue
                    acc = 0.0
                    for line in range(start[j] + 1, stop[j] + 1):
                        x, dx = a_hat[c, line], da_hat[k, c, line]
                        acc += x.real * dx.real + x.imag * dx.imag
                    out[k, c, j] = factor * acc / ((stop[j] - start[j]) * mean[c, j])
else:  # pragma: no cover - without numba
    _cell_derivatives = _cell_derivatives_numpy


def compute_spectra(responses: Sequence[Response],
                    options: SpectraOptions | Mapping[str, Any] | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Spectra Y (eq. 1-2) of several records on the common grid Ω.

    :param responses: one :class:`~suspid.interfaces.Response` per track
        segment, all with the same channels in the same order; lengths and
        sampling rates may differ.
    :param options: the ``spectra:`` section.
    :returns: ``y`` ``(n_samples, n_channels, n_freqs)`` in dB re 1 m s^-1.5
        and ``freqs`` ``(n_freqs,)`` in Hz.
    :raises DataError: no records, differing channels, or a record that does
        not fit the grid (see :func:`record_spectrum`).
    """
    opt = parse_options(SpectraOptions, options, "spectra")
    if len(responses) == 0:
        raise DataError("no records to compute spectra from")
    channels = tuple(responses[0].channels)
    for i, r in enumerate(responses):
        if np.shape(r.accelerations)[:1] != (len(r.channels),):
            raise DataError(f"record '{r.segment or i}': accelerations of shape {np.shape(r.accelerations)} "
                            f"do not match its {len(r.channels)} channels")
        if tuple(r.channels) != channels:
            raise DataError(f"record '{r.segment}' has channels {list(r.channels)}, "
                            f"but record '{responses[0].segment}' has {list(channels)}")
    y = np.stack([record_spectrum(r.accelerations, r.fs, opt, name=r.segment or str(i))
                  for i, r in enumerate(responses)])
    return y, frequency_grid(opt)[0]
