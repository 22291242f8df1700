"""Synthetic track: spectra formulas, realisations against their target PSD, seeding, options."""

from __future__ import annotations

import math

import numpy as np
import pytest

from suspid.errors import ConfigError
from suspid.interfaces import IRREGULARITY_CHANNELS
from suspid.data.track import GERMAN, GERMAN_A, SPECTRA, TrackOptions, psd, realise, synthetic_segments


def test_german_and_fra_formulas_at_a_point():
    w = 1.0
    oc, orr, os_ = GERMAN["omega_c"], GERMAN["omega_r"], GERMAN["omega_s"]
    a = GERMAN_A["german-low"]
    base = oc ** 2 / ((w ** 2 + orr ** 2) * (w ** 2 + oc ** 2))
    assert psd("german-low", "vertical", w) == pytest.approx(a["vertical"] * base)
    assert psd("german-low", "lateral", w) == pytest.approx(a["lateral"] * base)
    shape = base * w ** 2 / (w ** 2 + os_ ** 2)
    assert psd("german-low", "gauge", w) == pytest.approx(a["gauge"] * shape)
    # cross-level: the angle PSD (A_v / b^2) times (2 b)^2 gives the rail height difference
    assert psd("german-low", "cross_level", w) == pytest.approx(4 * a["vertical"] * shape)
    # FRA class 6 vertical, cm^2 -> m^2
    s_cm2 = 0.25 * 0.0339 * 0.8245 ** 2 / (w ** 2 * (w ** 2 + 0.8245 ** 2))
    assert psd("fra-6", "vertical", w) == pytest.approx(s_cm2 * 1e-4)
    # unconfirmed FRA channels fall back to the German spectra
    assert psd("fra-2", "lateral", w) == psd("german-high", "lateral", w)
    assert psd("fra-5", "gauge", w) == psd("german-low", "gauge", w)
    assert psd("german-high", "vertical", w) > psd("german-low", "vertical", w)
    with pytest.raises(ValueError, match="unknown spectrum"):
        psd("fra-7", "vertical", w)
    with pytest.raises(ValueError, match="unknown channel"):
        psd("german-low", "twist", w)


@pytest.mark.parametrize("spectrum", ["german-low", "german-high", "fra-4"])
def test_realisations_match_the_target_psd_within_sampling_error(spectrum):
    """Periodogram of K segments, averaged over octave bands of M lines: mean ratio 1 +- 4/sqrt(KM)."""
    n, dx, k_seg = 4000, 0.25, 24
    rng = np.random.default_rng(7)
    x = np.array([realise(spectrum, n, dx, rng) for _ in range(k_seg)])      # (K, 4, n)
    omega = 2 * math.pi * np.fft.rfftfreq(n, dx)
    d_omega = omega[1]
    # one-sided periodogram in m^2/(rad/m): |X|^2 / (N^2 dOmega) x 2, and the mean over segments
    periodogram = 2 * np.abs(np.fft.rfft(x, axis=2)) ** 2 / (n ** 2 * d_omega)
    est = periodogram.mean(axis=0)
    edges = 2 * math.pi / np.array([400.0, 200, 100, 50, 25, 12.5, 6.25, 3.125, 1.6, 0.8, 0.55])
    for c, ch in enumerate(IRREGULARITY_CHANNELS):
        target = np.zeros_like(omega)
        target[1:] = psd(spectrum, ch, omega[1:])
        for lo, hi in zip(edges[:-1], edges[1:]):
            band = (omega >= lo) & (omega < hi)
            m = int(band.sum())
            ratio = np.mean(est[c, band] / target[band])
            assert abs(ratio - 1) < 4 / math.sqrt(k_seg * m), (ch, lo, hi, ratio)
        # and the variance over the band of the realisation equals the integral of the PSD
        var = np.mean(np.var(x[:, c], axis=1))
        assert var == pytest.approx(np.sum(target[1:-1]) * d_omega, rel=0.15)


def test_segments_are_seeded_named_and_sized():
    opts = {"spectrum": "german-high", "n_segments": 3, "length_m": 500.0, "dx_m": 0.25, "speed_kmh": 288.0,
            "seed": 5}
    a = synthetic_segments(opts)
    b = synthetic_segments(opts)
    c = synthetic_segments({**opts, "seed": 6})
    assert [s.name for s in a] == ["seg-001", "seg-002", "seg-003"]
    assert all(s.irregularities.shape == (4, 2001) for s in a)
    assert a[0].distance[-1] == pytest.approx(500.0)
    assert a[0].speed == pytest.approx(80.0)
    assert a[0].dx == pytest.approx(0.25)
    assert all(np.array_equal(s.irregularities, t.irregularities) for s, t in zip(a, b))
    assert not np.allclose(a[0].irregularities, c[0].irregularities)
    assert not np.allclose(a[0].irregularities, a[1].irregularities)      # independent segments
    # a generator can be given instead of the seed (e.g. a named stream of the run)
    d = synthetic_segments(opts, rng=np.random.default_rng(5))
    assert np.array_equal(d[1].irregularities, a[1].irregularities)
    assert TrackOptions(speed_mps=50.0).speed == 50.0
    assert TrackOptions().speed == pytest.approx(300 / 3.6)


@pytest.mark.parametrize("options, key", [
    ({"speed_kmh": 300.0, "speed_mps": 80.0}, "data.track"),
    ({"spectrum": "fra-9"}, "data.track.spectrum"),
    ({"length_m": 0.5, "dx_m": 0.25}, "data.track"),
    ({"n_segments": 0}, "data.track.n_segments"),
    ({"colour": "red"}, "data.track.colour"),
])
def test_bad_options_name_the_key(options, key):
    with pytest.raises(ConfigError) as err:
        synthetic_segments(options)
    assert f"key '{key}'" in str(err.value)


def test_every_spectrum_realises_finite_millimetre_track():
    """In the 1-120 m band every spectrum gives sub-millimetre to centimetre irregularities."""
    for name in SPECTRA:
        (seg,) = synthetic_segments({"spectrum": name, "n_segments": 1, "length_m": 1000.0, "seed": 1,
                                     "min_wavelength_m": 1.0, "max_wavelength_m": 120.0})
        std = seg.irregularities.std(axis=1)
        assert np.all(np.isfinite(seg.irregularities))
        assert np.all((std > 1e-4) & (std < 0.03)), (name, std)


def test_wavelength_band_removes_the_long_waves():
    opts = {"spectrum": "german-low", "n_segments": 1, "length_m": 2000.0, "seed": 2}
    (full,) = synthetic_segments(opts)
    (band,) = synthetic_segments({**opts, "max_wavelength_m": 120.0})
    spectrum = np.abs(np.fft.rfft(band.irregularities[0])) ** 2
    wavelength = 1 / np.maximum(np.fft.rfftfreq(band.distance.size, band.dx), 1e-12)
    assert np.all(spectrum[(wavelength > 121.0)] < 1e-20)
    assert band.irregularities[0].std() < full.irregularities[0].std()
    with pytest.raises(ConfigError, match="min_wavelength_m must be below"):
        synthetic_segments({**opts, "min_wavelength_m": 50.0, "max_wavelength_m": 10.0})
