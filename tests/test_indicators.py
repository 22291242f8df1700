"""Standard indicators: known answers of the EN 14363 instability rms, the EN 12299 weightings and N_MV."""

from __future__ import annotations

import numpy as np
import pytest

from suspid.indicators import WB, WD, compute_indicators, instability, instability_limit, sliding_rms, weight
from suspid.indicators.standard import block_rms, comfort_nmv
from suspid.interfaces import Response, TrackSegment


def test_weighting_gains_match_the_tabulated_values():
    """ISO 8041 gives each weighting's value at its reference frequency 100 rad/s (15.915 Hz): Wb 0.8126,
    Wd 0.1261; ISO 2631-1 Table 3 tabulates Wd (x 1000) 853 at 0.5 Hz, 1011 at 1 Hz, 890 at 2 Hz, 512 at 4 Hz."""
    f_ref = 100.0 / (2 * np.pi)
    assert WB.gain(f_ref) == pytest.approx(0.8126, abs=5e-4)
    assert WD.gain(f_ref) == pytest.approx(0.1261, abs=5e-4)
    np.testing.assert_allclose(WD.gain([0.5, 1.0, 2.0, 4.0]), [0.853, 1.011, 0.890, 0.512], atol=1.5e-3)
    assert WB.gain(0.01) < 1e-3 and WD.gain(0.01) < 1e-3          # band limited


def test_weighting_a_sine_scales_it_by_the_gain():
    fs, f = 100.0, 4.0
    t = np.arange(int(20 * fs)) / fs
    y = weight(np.sin(2 * np.pi * f * t), fs, WB)
    assert np.sqrt(np.mean(y**2)) == pytest.approx(WB.gain(f) / np.sqrt(2), rel=1e-3)


def test_instability_of_a_pure_sine_at_the_hunting_frequency_is_its_rms():
    """A sine of amplitude A at f0 passes the f0 +- 2 Hz band whole: every 100 m sliding rms is A / sqrt 2."""
    fs, f0, amp, v = 100.0, 6.0, 3.0, 80.0
    t = np.arange(int(30 * fs)) / fs
    x = amp * np.sin(2 * np.pi * f0 * t) + 2.0 * np.sin(2 * np.pi * 0.8 * t)   # + a carbody sway out of band
    peak, f_used, s = instability(x, fs, v, bogie_mass_kg=3500.0)
    assert f_used == pytest.approx(f0, abs=0.15)                     # the spectral peak found f0
    assert s.size == 1 + (x.size - 125) // 12                        # 100 m = 125 samples, 10 m = 12 samples
    np.testing.assert_allclose(s[5:-5], amp / np.sqrt(2), rtol=0.01)
    assert peak == pytest.approx(amp / np.sqrt(2), rel=0.02)


def test_instability_limit_from_the_bogie_mass():
    assert instability_limit(3500.0) == pytest.approx(0.5 * (12 - 3.5 / 5))   # 5.65 m/s^2
    assert instability_limit(5000.0) == pytest.approx(5.5)


def test_sliding_rms_windows_in_distance():
    x = np.r_[np.zeros(100), np.ones(100)]
    s = sliding_rms(x, fs=10.0, speed_mps=10.0, window_m=10.0, step_m=10.0)  # 10-sample windows, no overlap
    np.testing.assert_allclose(s, np.r_[np.zeros(10), np.ones(10)])


def test_mean_comfort_of_sines():
    """N_MV = 6 sqrt(aY95^2 + aZ95^2): a 1 Hz lateral sine of 0.1 m/s^2 and a 4 Hz vertical one of 0.2 m/s^2."""
    fs = 100.0
    t = np.arange(int(30 * fs)) / fs
    y, z = 0.1 * np.sin(2 * np.pi * 1.0 * t), 0.2 * np.sin(2 * np.pi * 4.0 * t)
    expected = 6 * np.hypot(0.1 / np.sqrt(2) * WD.gain(1.0), 0.2 / np.sqrt(2) * WB.gain(4.0))
    ay, az = block_rms(weight(y, fs, WD), fs), block_rms(weight(z, fs, WB), fs)
    assert ay.size == 6
    assert comfort_nmv(float(np.percentile(ay, 95)), float(np.percentile(az, 95))) == pytest.approx(expected, rel=0.01)


def test_compute_indicators_per_segment_and_per_run():
    """Two segments: the run's instability is the worst segment's, its comfort pools both segments' blocks."""
    fs, v = 100.0, 80.0
    t = np.arange(int(30 * fs)) / fs
    channels = ("carbody_lateral", "carbody_vertical", "bogie_lateral")
    segs, resps = [], []
    for i, amp in enumerate((2.0, 7.0)):       # the second exceeds the 5.65 m/s^2 limit of a 3.5 t bogie
        acc = np.vstack([0.1 * np.sin(2 * np.pi * t), 0.2 * np.sin(2 * np.pi * 4 * t),
                         amp * np.sqrt(2) * np.sin(2 * np.pi * 7.0 * t)])
        segs.append(TrackSegment(f"s{i}", np.arange(10) * 0.25, np.zeros((4, 10)), v))
        resps.append(Response(channels, fs, acc, f"s{i}"))
    out = compute_indicators(segs, resps, bogie_mass_kg=3500.0)
    inst = {v.segment: v for v in out if v.name == "en14363-instability"}
    assert inst["s0"].value == pytest.approx(2.0, rel=0.02) and inst["s0"].verdict == "ok"
    assert inst["s1"].value == pytest.approx(7.0, rel=0.02) and inst["s1"].verdict == "alarm"
    assert inst[None].value == inst["s1"].value and inst[None].limit == pytest.approx(5.65)
    comfort = {v.segment: v for v in out if v.name == "en12299-comfort"}
    expected = 6 * np.hypot(0.1 / np.sqrt(2) * WD.gain(1.0), 0.2 / np.sqrt(2) * WB.gain(4.0))
    assert comfort[None].value == pytest.approx(expected, rel=0.01) and comfort[None].verdict == "ok"
    assert comfort[None].detail["n_blocks"] == 12
    unassessed = compute_indicators(segs, resps, bogie_mass_kg=None)
    assert {v.verdict for v in unassessed if v.name == "en14363-instability"} == {"not assessable"}

