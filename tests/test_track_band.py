"""Track records with their band: the EN 13848, chord and user transfer functions, the band a record supports
at a speed, the model's input filtered as the record, and the identification it gives (known answers)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

import suspid
from suspid.data.track import TrackBand, band_note, filter_track, synthetic_segments
from suspid.errors import ConfigError
from suspid.interfaces import TrackSegment
from suspid.method.spectra import compute_spectra
from suspid.plugins.simulators.exudyn_train import ExudynTrain


def _sine(wavelength: float, length: float = 2000.0, dx: float = 0.25) -> TrackSegment:
    x = np.arange(0.0, length, dx)
    irr = np.tile(np.sin(2 * np.pi * x / wavelength), (4, 1))
    return TrackSegment("sine", x, irr, 80.0)


def _gain(band: TrackBand, wavelength: float) -> float:
    """Amplitude ratio of a filtered sine over the middle of the segment (away from the ends)."""
    seg = _sine(wavelength)
    out = filter_track(seg, band).irregularities[0]
    mid = slice(seg.distance.size // 4, 3 * seg.distance.size // 4)
    return float(np.std(out[mid]) / np.std(seg.irregularities[0][mid]))


def test_en13848_d1_d2_passes_the_band_and_is_3_db_down_at_its_edges():
    band = TrackBand(filter="en13848", bands=["D1", "D2"])
    assert _gain(band, 12.0) == pytest.approx(1.0, abs=0.01)
    assert _gain(band, 70.0) == pytest.approx(1 / math.sqrt(2), abs=0.02)    # -3 dB at the band's edges
    assert _gain(band, 3.0) == pytest.approx(1 / math.sqrt(2), abs=0.02)
    assert _gain(band, 250.0) < 0.01                                         # order 4: (70/250)^4 = 0.006
    short, long = band.supported_wavelengths()
    assert 3.0 < short < 6.0 and 35.0 < long < 70.0


def test_chord_transfer_function_is_the_versine_closed_form():
    band = TrackBand(filter="chord", chord_m=10.0)
    for wavelength in (10.0, 20.0, 40.0):                  # symmetric chord: |H| = 1 - cos(pi L / wavelength)
        assert _gain(band, wavelength) == pytest.approx(1 - math.cos(math.pi * 10.0 / wavelength), abs=0.01)
    short, long = band.supported_wavelengths()              # only where |H| is within [0.99, 1/0.99]: near 2 L
    assert short < 20.0 < long and long - short < 2.0


def test_user_transfer_function_is_interpolated_in_log_wavelength():
    band = TrackBand(filter="transfer", transfer_wavelength_m=[2.0, 5.0, 100.0, 200.0], transfer_gain=[0, 1, 1, 0])
    assert _gain(band, 20.0) == pytest.approx(1.0, abs=0.01)
    assert _gain(band, 150.0) == pytest.approx(1 - math.log(1.5) / math.log(2.0), abs=0.03)
    assert band.supported_wavelengths()[0] == pytest.approx(5.0, rel=0.02)


def test_supported_band_at_a_speed_restricts_the_spectra_and_says_so():
    band = TrackBand(filter="en13848", bands=["D1", "D2"])
    short, long = band.supported_wavelengths()
    lo, hi, note = band_note(band, np.array([300 / 3.6, 270 / 3.6]), 0.4, 30.0)
    assert lo == pytest.approx((300 / 3.6) / long) and hi == pytest.approx(min(30.0, (270 / 3.6) / short))
    assert "spectra restricted from 0.4-30 Hz" in note
    assert band_note(TrackBand(), np.array([80.0]), 0.4, 30.0) == (0.4, 30.0, "")
    unrestricted = band_note(band.model_copy(update={"restrict": False}), np.array([80.0]), 0.4, 30.0)
    assert unrestricted[:2] == (0.4, 30.0) and "NOT restricted" in unrestricted[2]


@pytest.mark.parametrize("band, message", [
    ({"filter": "en13848", "bands": ["D1", "D3"]}, "contiguous"),
    ({"filter": "chord"}, "chord_m"),
    ({"filter": "transfer", "transfer_wavelength_m": [3.0, 1.0], "transfer_gain": [1, 1]}, "increase"),
    ({"filter": "fir"}, "filter"),
])
def test_a_wrong_track_band_is_a_config_error_naming_the_key(band, message):
    with pytest.raises(ConfigError, match=rf"data\.track_band.*{message}"):
        suspid.validate({"data": {"track_band": band}})


def test_validate_restricts_the_spectra_of_an_experiment_and_says_so():
    cfg = {"name": "band", "parameters": {"c_sec_z": {}}, "data": {"track": {"n_segments": 4, "speed_kmh": 300.0},
                                    "track_band": {"filter": "en13848", "bands": ["D1", "D2"]}},
           "spectra": {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 100, "window": "hann"}}
    checked = suspid.validate(cfg).config
    short, long = TrackBand(filter="en13848").supported_wavelengths()
    lo, hi = (300 / 3.6) / long, (300 / 3.6) / short          # 1.94 and 17.07 Hz
    step = (20.0 - 0.4) / 99
    s = checked.spectra                            # the configured grid's points within the band: same spacing
    assert lo <= s.f_min_hz < lo + step and hi - step < s.f_max_hz <= hi
    assert (s.f_max_hz - s.f_min_hz) / (s.n_freqs - 1) == pytest.approx(step)
    assert len(checked._notes) == 1 and "spectra restricted from 0.4-20 Hz to the" in checked._notes[0]
    cfg["data"]["track_band"] = {"filter": "en13848", "bands": ["D1"]}
    cfg["spectra"] = {"f_min_hz": 0.4, "f_max_hz": 1.0, "n_freqs": 10}
    with pytest.raises(ConfigError, match=r"data\.track_band.*leaves nothing of the spectra's 0.4-1 Hz"):
        suspid.validate(cfg)


def test_identification_on_a_d1_d2_record_equals_the_full_band_where_the_unrestricted_one_is_biased():
    """Known answer: the vehicle runs on a full-band track T (German low); the record is T filtered as D1+D2.

    The estimate of c_sec_z (minimum of the mean squared dB difference of the spectra) from the model on T
    over the whole band is the truth; from the model on the D1+D2 record over the band the record supports
    it is the truth too; over the whole band, where the record lacks the long wavelengths, it is biased.
    """
    sim = ExudynTrain(solver="frequency", fs_hz=100.0)
    nominal = {p.name: p.nominal for p in sim.parameters()}["c_sec_z"]
    truth = 0.75 * nominal
    track = synthetic_segments({"spectrum": "german-low", "n_segments": 6, "length_m": 1000.0,
                                "speed_kmh": 300.0, "seed": 3})
    band = TrackBand(filter="en13848", bands=["D1", "D2"])
    record = [filter_track(s, band) for s in track]
    full = {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 120, "window": "hann"}
    lo, hi, _ = band_note(band, np.array([s.mean_speed for s in track]), 0.4, 20.0)
    restricted = dict(full, f_min_hz=lo, f_max_hz=hi)

    def estimate(model_input, spectra) -> float:
        y_mes = compute_spectra(sim.simulate({"c_sec_z": truth}, track), spectra)[0]
        r = minimize_scalar(lambda u: float(np.mean((compute_spectra(sim.simulate(
            {"c_sec_z": u * nominal}, model_input), spectra)[0] - y_mes) ** 2)), bounds=(0.4, 1.2),
            method="bounded", options={"xatol": 1e-3})
        return r.x * nominal / truth - 1.0

    assert abs(estimate(track, full)) < 0.005
    assert abs(estimate(record, restricted)) < 0.01
    assert abs(estimate(record, full)) > 0.04          # -7 % when written


@pytest.mark.parametrize("suffix", ["csv", "h5"])
def test_curvature_and_cant_round_trip_through_the_track_files(tmp_path, suffix):
    from suspid.data.files import read_track, write_track, write_track_csv

    x = np.arange(0.0, 100.0, 0.25)
    seg = TrackSegment("curve", x, np.zeros((4, x.size)), 80.0, curvature=np.full(x.size, 1 / 3000.0),
                       cant=np.linspace(0.0, 0.15, x.size))
    plain = TrackSegment("straight", x, np.zeros((4, x.size)), 80.0)
    if suffix == "csv":
        (tmp_path / "t").mkdir()
        write_track_csv(seg, tmp_path / "t" / "curve.csv")
        write_track_csv(plain, tmp_path / "t" / "straight.csv")
        back = read_track(tmp_path / "t")
    else:
        back = read_track(write_track([seg, plain], tmp_path / "t.h5"))
    by = {s.name: s for s in back}
    np.testing.assert_allclose(by["curve"].curvature, seg.curvature)
    np.testing.assert_allclose(by["curve"].cant, seg.cant)
    assert by["straight"].curvature is None and by["straight"].cant is None
