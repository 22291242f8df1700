"""Spectra (paper eq. 1-2) against analytic cases: sinusoids, Parseval, white noise."""

import math

import numpy as np
import pytest
from scipy.special import digamma

from suspid.errors import ConfigError, DataError
from suspid.interfaces import Response
from suspid.method.spectra import (SpectraOptions, compute_spectra, fourier_amplitude, frequency_grid,
                            record_spectrum)

DB = 5.0 / math.log(10.0)  # d(5 log10 x)/d(ln x): natural-log units to dB of an amplitude


def sinusoid(amplitude, f0, fs, duration, phase=0.3):
    t = np.arange(int(round(fs * duration))) / fs
    return amplitude * np.cos(2 * np.pi * f0 * t + phase)


def peak_db(amplitude, duration):
    """|Â(f0)| = a √T / 2 for a cos of amplitude a on a DFT line: Y = 10 log10 of it."""
    return 10 * math.log10(amplitude * math.sqrt(duration) / 2)


@pytest.mark.parametrize("fs, duration, f0, amplitude", [(200.0, 40.0, 5.0, 2.0), (128.0, 25.0, 12.4, 0.05)])
def test_sinusoid_one_line_per_cell_gives_the_exact_peak(fs, duration, f0, amplitude):
    a = np.vstack([sinusoid(amplitude, f0, fs, duration), np.zeros(int(fs * duration))])
    opts = {"f_min_hz": 1.0, "f_max_hz": 20.0, "df_hz": 1.0 / duration}
    freqs = frequency_grid(opts)[0]
    y = record_spectrum(a, fs, opts)
    j = int(np.argmax(y[0]))
    assert freqs[j] == pytest.approx(f0, abs=1e-9)
    assert y[0, j] == pytest.approx(peak_db(amplitude, duration), abs=1e-9)
    assert np.all(y[0, np.arange(y.shape[1]) != j] < y[0, j] - 100)  # leakage-free on a DFT line
    assert np.all(y[1] == pytest.approx(-150.0))  # the documented floor, no -inf


def test_band_average_dilutes_a_line_by_the_number_of_lines_in_its_cell():
    fs, duration, f0 = 100.0, 20.0, 6.0
    a = sinusoid(1.0, f0, fs, duration)[None]
    opts = {"f_min_hz": 2.0, "f_max_hz": 10.0, "df_hz": 4 / duration}  # cells of 4 lines
    y = record_spectrum(a, fs, opts)[0]
    assert y.max() == pytest.approx(peak_db(1.0, duration) - 5 * math.log10(4), abs=1e-9)


def test_hann_window_keeps_the_power_of_a_line_within_its_cell():
    """Periodic Hann spreads an on-line sinusoid over 3 lines; power-normalised, their total is kept."""
    fs, duration, f0 = 100.0, 20.0, 6.0
    a = sinusoid(1.0, f0, fs, duration)[None]
    opts = {"f_min_hz": 2.0, "f_max_hz": 10.0, "df_hz": 5 / duration}  # 5 lines per cell, f0 at a centre
    y_box = record_spectrum(a, fs, opts)[0]
    y_hann = record_spectrum(a, fs, {**opts, "window": "hann"})[0]
    assert y_hann.max() == pytest.approx(y_box.max(), abs=1e-9)
    assert y_box.max() == pytest.approx(peak_db(1.0, duration) - 5 * math.log10(5), abs=1e-9)


def test_smoothing_band_of_constant_relative_width():
    fs, duration, f0 = 100.0, 20.0, 8.0
    a = sinusoid(1.0, f0, fs, duration)[None]
    opts = {"f_min_hz": 4.0, "f_max_hz": 12.0, "df_hz": 1 / duration, "smoothing_octaves": 0.5}
    freqs = frequency_grid(opts)[0]
    y = record_spectrum(a, fs, opts)[0]
    j = int(np.argmin(np.abs(freqs - f0)))
    lines = np.arange(1, int(fs * duration) // 2 + 1) / duration
    in_band = np.count_nonzero((lines >= f0 * 2 ** -0.25) & (lines < f0 * 2 ** 0.25))
    assert in_band == 56  # 6.75 to 9.50 Hz in steps of 0.05 Hz, in [6.727, 9.514)
    assert y[j] == pytest.approx(peak_db(1.0, duration) - 5 * math.log10(in_band), abs=1e-9)


@pytest.mark.parametrize("n_t", [1000, 1001])
def test_parseval_for_the_discrete_transform(n_t):
    """Δt Σ a_n² = Σ over the two-sided DFT of |Â_k|² (eq. 2 by the rectangle rule)."""
    fs = 50.0
    a = np.random.default_rng(3).normal(0.1, 0.7, size=(3, n_t))
    f, a_hat = fourier_amplitude(a, fs, {"detrend": "none"})
    assert f[1] == pytest.approx(fs / n_t)
    p = np.abs(a_hat) ** 2
    two_sided = p[:, 0] + 2 * p[:, 1:].sum(axis=1)
    if n_t % 2 == 0:  # the Nyquist line is not mirrored
        two_sided -= p[:, -1]
    np.testing.assert_allclose(two_sided, (a ** 2).sum(axis=1) / fs, rtol=1e-12)


def test_white_noise_level_is_independent_of_record_length():
    """E|Â|² = σ²/fs for white noise; the log of an M-line mean is biased by (5/ln10)(ψ(M) - ln M)."""
    fs, sigma = 100.0, 0.3
    opts = {"f_min_hz": 1.0, "f_max_hz": 30.9, "df_hz": 0.1}  # 300 cells of 0.1 Hz
    rng = np.random.default_rng(11)
    expected = 5 * math.log10(sigma ** 2 / fs)
    for duration, lines in ((20.0, 2), (80.0, 8)):
        a = sigma * rng.standard_normal((4, int(fs * duration)))
        y = record_spectrum(a, fs, opts)
        y_corrected = record_spectrum(a, fs, {**opts, "log_bias_correction": True})
        # per cell the dB value scatters by DB * sqrt(ψ'(M)); 1200 independent cells
        stderr = DB * math.sqrt(float(np.pi ** 2 / 6 - sum(1 / k ** 2 for k in range(1, lines)))) / math.sqrt(y.size)
        bias = DB * (digamma(lines) - math.log(lines))
        assert y.mean() == pytest.approx(expected + bias, abs=4 * stderr)
        assert y_corrected.mean() == pytest.approx(expected, abs=4 * stderr)


def test_compute_spectra_puts_records_of_different_lengths_and_rates_on_one_grid():
    rng = np.random.default_rng(0)
    records = [Response(("carbody_z", "bogie_y"), fs, rng.normal(size=(2, int(fs * dur))), f"s{i}")
               for i, (fs, dur) in enumerate([(100.0, 30.0), (128.0, 47.3), (256.0, 12.0)])]
    y, freqs = compute_spectra(records)
    assert y.shape == (3, 2, 300)
    assert freqs[0] == pytest.approx(0.3) and freqs[-1] == pytest.approx(30.0)
    assert np.all(np.isfinite(y))


def test_log_grid_cells_have_constant_relative_width():
    freqs, lower, upper = frequency_grid({"spacing": "log", "n_freqs": 41, "f_min_hz": 0.5, "f_max_hz": 32.0})
    ratio = 64 ** (1 / 40)
    np.testing.assert_allclose(upper / lower, ratio)
    np.testing.assert_allclose(upper[:-1], lower[1:])  # cells tile the band
    np.testing.assert_allclose(np.sqrt(lower * upper), freqs)


def test_impossible_inputs_are_one_line_errors():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(2, 2000))
    with pytest.raises(DataError, match="Nyquist"):
        record_spectrum(a, 50.0, {"f_max_hz": 30.0}, name="seg-7")
    with pytest.raises(DataError, match=r"too short .* 0\.3 Hz"):
        record_spectrum(a[:, :500], 100.0)  # T = 5 s: lines every 0.2 Hz, cells 0.1 Hz wide
    bad = a.copy()
    bad[1, 10] = np.nan
    with pytest.raises(DataError, match="NaN"):
        record_spectrum(bad, 100.0)
    with pytest.raises(DataError, match="channels"):
        compute_spectra([Response(("a", "b"), 100.0, a, "s1"), Response(("a", "c"), 100.0, a, "s2")])
    with pytest.raises(DataError, match="no records"):
        compute_spectra([])
    with pytest.raises(ConfigError, match="spectra'.*f_max_hz"):
        frequency_grid({"f_min_hz": 5.0, "f_max_hz": 1.0})
    with pytest.raises(ConfigError, match="spectra.windw"):
        frequency_grid({"windw": "hann"})
    with pytest.raises(ConfigError, match="not both"):
        frequency_grid({"n_freqs": 10, "df_hz": 0.1})
    assert SpectraOptions().model_dump()["f_min_hz"] == 0.3
