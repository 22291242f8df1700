"""``suspid diagnose`` on hidden effects written by code that is not suspid's (``independent/effects.py``).

The independent train (``tests/independent``) makes the measurements of both
dates; the hidden effects are filters and inputs of its own (a bending mode of
its own modal model, a bracket resonance, a calibration gain, a tilted sensor,
polygonal wheels with their own phases), under its measurement process (fixed
per-channel and per-segment gains, a sensor-noise floor, anti-alias filter).
suspid's rigid exudyn model, identified on these files, is the base model.

Fast tests check the generator and the pieces of the naming rule; the
experiments are slow (each identifies the suspension before and after).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import suspid
from independent import effects as HE
from independent import train as TR

KMH = 1 / 3.6


# ------------------------------------------------------------------------------------------ the generator
def _spectrum(recs, channel: str) -> tuple[np.ndarray, np.ndarray]:
    from scipy.signal import welch

    k = TR.CHANNELS.index(channel)
    f, p = welch(np.array([r.accelerations[k] for r in recs]), fs=recs[0].fs, nperseg=256, axis=-1)
    return f, p.mean(axis=0)


def test_generator_uses_no_suspid_effect_code():
    text = Path(HE.__file__).read_text()
    code = text.split("def prepare", 1)[0]          # prepare() is the consumer side (noise model, config)
    assert "suspid" not in code.replace("suspid's", "").replace("``suspid diagnose``", "")


def test_hidden_effects_show_where_they_should():
    common = dict(seed=1, n_segments=3, speed_mps=300 * KMH, length_m=300.0)
    base = HE.simulate(None, (), **common)
    f, p0 = _spectrum(base, "carbody_middle_vertical")
    _, p1 = _spectrum(HE.simulate(None, (HE.BracketResonance("carbody_middle_vertical", 14.0, 0.05),), **common),
                      "carbody_middle_vertical")
    ratio = 10 * np.log10(p1 / p0)
    assert ratio[np.argmin(np.abs(f - 14.0))] > 10.0 and abs(ratio[np.argmin(np.abs(f - 2.0))]) < 0.5
    _, g1 = _spectrum(HE.simulate(None, (HE.CalibrationGain(("bogie_front_vertical",), 1.25),), **common),
                      "bogie_front_vertical")
    _, g0 = _spectrum(base, "bogie_front_vertical")
    assert np.median(10 * np.log10(g1 / g0)) == pytest.approx(20 * math.log10(1.25), abs=0.05)
    _, t1 = _spectrum(HE.simulate(None, (HE.SensorTilt("bogie_front_lateral", 10.0),), **common),
                      "bogie_front_lateral")
    _, t0 = _spectrum(base, "bogie_front_lateral")
    assert np.max(10 * np.log10(t1 / t0)) > 1.0                   # vertical mixed into lateral
    poly = HE.simulate(None, (HE.WheelPolygon(1, 1e-4, (2, 3)),), **common)
    _, q1 = _spectrum(poly, "bogie_front_vertical")
    j = np.argmin(np.abs(f - 300 * KMH / (math.pi * 0.92)))
    assert 10 * np.log10(q1[j] / g0[j]) > 5.0                     # the 28.8 Hz line


def test_flexible_carbody_is_the_trains_own_mode():
    common = dict(seed=2, n_segments=3, speed_mps=300 * KMH, length_m=300.0)
    f, p0 = _spectrum(HE.simulate(None, (), **common), "carbody_middle_vertical")
    _, p1 = _spectrum(HE.simulate(None, (HE.FlexibleCarbody(9.5, 0.02),), **common), "carbody_middle_vertical")
    r = 10 * np.log10(p1 / p0)
    assert f[np.argmax(r)] == pytest.approx(9.5, abs=0.8) and r.max() > 6.0


# ------------------------------------------------------------------------------------------ pieces of the rule
def test_local_model_takes_a_one_channel_bump_and_a_flat_gain():
    from suspid.workflows.diagnose import fit_local, make_cells
    from suspid.workflows.diagnose.fit import Discrepancy

    class Null:
        pass

    f = np.geomspace(0.5, 30, 120)
    grid = make_cells(["a", "b", "c"], f, [80.0] * 4)
    null = Null()
    null.bin_sd = np.full((1, 3, f.size), 0.2)
    null.noise_mean = np.zeros((1, 3, f.size))                                 # μ_B of the speed group
    nm = type("NM", (), {"mean_": np.zeros((3, f.size)), "floor_": None,  # a noise model without a floor
                         "effective": lambda self, y_sim: y_sim})()
    y_mes = np.zeros((4, 3, f.size))
    y_mes[:, 0] += 6.0 * np.exp(-0.5 * (np.log2(f / 14.0) / (1 / 6)) ** 2)   # a bracket on a
    y_mes[:, 2] += 1.9                                                        # a gain on c
    flagged = np.zeros(grid.n_cells, bool)
    flagged[:] = True
    disc = Discrepancy(grid, null, y_mes, nm, flagged, np.zeros_like(y_mes))
    fit = fit_local(disc, flagged, disc.base_means, math.log(disc.n_terms))
    assert fit.D < 0.05 * disc.D0
    (a, fc, _, _), (c, _, wc, _) = fit.bumps[(0, 0)], fit.bumps[(0, 2)]
    assert fc == pytest.approx(14.0, rel=0.1) and a == pytest.approx(6.0, rel=0.1)
    assert math.isinf(wc) and c == pytest.approx(1.9, rel=0.01) and (0, 1) not in fit.bumps


def test_tilt_start_from_the_vertical_into_lateral_coupling():
    from suspid.plugins.effects.catalogue import SensorTilt

    f = np.geomspace(0.5, 40, 100)
    lat = -30 + 5 * np.sin(np.log(f))                      # dB, model lateral
    vert = -10 + 10 * np.log10(1 + (f / 20) ** 2)          # dB, measured vertical of the point
    alpha = math.radians(6.0)
    mes_lat = 10 * np.log10(math.cos(alpha) ** 2 * 10 ** (lat / 10) + math.sin(alpha) ** 2 * 10 ** (vert / 10))
    channels = ["bogie_front_vertical", "bogie_front_lateral"]
    spectra = {"freqs": f, "channels": channels, "measured": np.array([[vert, mes_lat]]),
               "model": np.array([[vert, lat]])}
    starts = SensorTilt().starts_from_spectra([80.0], [("bogie_front_lateral", 10.0, 40.0, 80.0)], channels, spectra)
    assert len(starts) == 1 and starts[0]["gravity_roll"] is False
    assert starts[0]["angle_deg"] == pytest.approx(6.0, rel=0.03) and starts[0]["coupling_r2"] > 0.99


def test_polygon_candidates_cover_sets_of_wheelsets():
    from suspid.plugins.effects.catalogue import WheelPolygon

    starts = WheelPolygon().candidates([300 * KMH], [("bogie_front_vertical", 25.0, 32.0, 300 * KMH)], [])
    sets = {tuple(s["wheelsets"]) for s in starts}
    assert {(1,), (2, 3), (1, 2), (3, 4), (1, 2, 3, 4)} <= sets


# ------------------------------------------------------------------------------------------ experiments
def run_case(tmp_path: Path, case: str, seed: int, **kw) -> tuple[dict, dict]:
    c = HE.CASES[case]
    path = HE.prepare(tmp_path / f"{case}-{seed}", c.hidden, seed=seed, speeds_kmh=c.speeds, w_ref=c.w_ref,
                      noise_asd=c.noise_asd, **kw)
    d = suspid.diagnose(path).diagnosis
    errors = HE.parameter_errors(d, path.parent / "measurement" / "truth.json",
                                 path.parent / "runs" / "config" / "before" / "result.json")
    return d, errors


def _main(d: dict, name: str) -> float:
    effect = next(e for e in d["effects"] if e["name"] == name)
    from suspid import registry

    return effect["parameters"][registry.get("effect", name).main_parameter]


SEEDS = [3, 4, 5]


@pytest.mark.slow
@pytest.mark.acceptance
@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("case, effect, truth, tol", [
    ("bending", "carbody-bending", 9.5, 0.05),
    ("tilt", "sensor-tilt", 6.0, 0.10),
    ("polygon", "wheel-polygon", 1, 0.0),
])
def test_independent_hidden_effect_is_named(tmp_path, case, effect, truth, tol, seed):
    d, errors = run_case(tmp_path, case, seed)
    assert effect in d["named_effects"], d["reason"]
    assert abs(_main(d, effect) - truth) <= tol * truth, d["effects"]
    identifiable = d["gap_after"]["suspension_fit"]["identifiable"]          # under the data-group check
    assert sum(identifiable.values()) >= 2, identifiable                  # not a verdict of "nothing is known"
    assert max(abs(e) for n, e in errors["gap_after_interval"].items() if identifiable[n]) < 3.0, (errors,
                                                                                                   identifiable)


@pytest.mark.slow
@pytest.mark.acceptance
@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("case, channel, band", [
    ("bracket", "carbody_middle_vertical", 14.0),
    ("gain", "bogie_front_vertical", None),
])
def test_independent_out_of_catalogue_is_reported_unexplained(tmp_path, case, channel, band, seed):
    d, _ = run_case(tmp_path, case, seed)
    assert d["named_effects"] == [], d["reason"]
    hits = [u for u in d["unexplained"] if u["channel"] == channel
            and (band is None or u["f_low_hz"] <= band <= u["f_high_hz"])]
    assert hits and "no catalogue effect fits" in hits[0]["text"], d["unexplained"]


@pytest.mark.slow
@pytest.mark.acceptance
@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("case", ["none", "two-speeds", "other-suspension"])
def test_independent_null_names_nothing(tmp_path, case, seed):
    d, _ = run_case(tmp_path, case, seed)
    assert d["named_effects"] == [], d["reason"]
    assert d["gap_before"]["share_flagged"] <= 0.02


@pytest.mark.slow
@pytest.mark.parametrize("case, seed", [("other-suspension", SEEDS[0])] + [
    pytest.param(c, s, marks=pytest.mark.long) for c in ("two-speeds", "other-suspension") for s in SEEDS
    if (c, s) != ("other-suspension", SEEDS[0])])
def test_null_at_the_fitted_suspension_flags_nothing(tmp_path, case, seed):  # the others: -m long (CI time)
    """Two speeds, or the measurement date at another suspension than the reference date: no hidden effect, the
    suspension identified and fitted under D, nothing named and at most 2 % of the cells flagged (with one μ_B
    for both speeds 27-39 % were; with the likelihood's w_opt 1-9 %; another suspension flagged 15-25 %). 24
    segments per date (the acceptance grid has 40, and its two-speed nulls) to keep CI's time."""
    c = HE.CASES[case]
    path = HE.prepare(tmp_path / f"{case}-{seed}", c.hidden, seed=seed, speeds_kmh=c.speeds, w_ref=c.w_ref,
                      n_segments=24, n_reference=32)
    d = suspid.diagnose(path).diagnosis
    assert d["named_effects"] == [], d["reason"]
    assert d["gap_before"]["share_flagged"] <= 0.02
    fit = d["gap_before"]["suspension_fit"]
    assert fit["status"] == "fitted" and fit["D"] < fit["D_start"]
    errors = HE.parameter_errors(d, path.parent / "measurement" / "truth.json",
                                 path.parent / "runs" / "config" / "before" / "result.json")
    assert max(abs(e) for e in errors["gap_before_interval"].values()) < 6.0, errors
    if case == "two-speeds":
        coverage = d["statistics"]["noise_mean_by_speed"]
        assert [(c["mean"], c["reference_segments"]) for c in coverage] == [("speed_group", 32)] * 2


@pytest.mark.slow
@pytest.mark.acceptance
@pytest.mark.parametrize("seed", SEEDS)
def test_independent_bending_and_tilt_named_in_two_steps(tmp_path, seed):
    d, _ = run_case(tmp_path, "bending+tilt", seed)
    assert sorted(d["named_effects"]) == ["carbody-bending", "sensor-tilt"], [s["reason"] for s in d["steps"]]
    assert len([s for s in d["steps"] if s["named"]]) == 2
    assert d["gap_after"]["share_flagged"] < 0.03


def test_coupling_test_reads_the_tilt_from_the_cross_spectrum():
    from types import SimpleNamespace

    from suspid.workflows.diagnose.coupling import coupling_test

    rng = np.random.default_rng(0)
    channels = ["bogie_front_vertical", "bogie_front_lateral", "bogie_rear_vertical"]

    def records(angle_deg):
        a = math.radians(angle_deg)
        out = []
        for _ in range(24):
            s = np.convolve(rng.standard_normal(820), np.ones(5) / 5, "same")
            v, z = s[:800], s[20:]                                 # z: the vertical further on (the instrument)
            lat = 0.5 * rng.standard_normal(800)                  # lateral above vertical: power hardly changes
            x = math.cos(a) * lat + math.sin(a) * v
            out.append(SimpleNamespace(accelerations=np.array([v, x, z]), fs=100.0))
        return out

    tilted = coupling_test(records(6.0), channels, (0.4, 40.0))[0]
    assert tilted["significant"] and tilted["angle_deg"] == pytest.approx(6.0, rel=0.15)
    null = coupling_test(records(0.0), channels, (0.4, 40.0))[0]
    assert not null["significant"]


def test_coupling_against_the_twin_sensor_removes_the_vehicles_own_coupling():
    """Both bogies couple lateral and vertical by the same amount on a set of segments (0.03, the order of the
    independent train's, which shifts both bogies together); the front sensor is tilted by 6°; each bogie's
    vertical is the other's instrument. The raw β of the front channel is off by the own coupling, its
    difference with the model's coupling (given as 0.03) and with the rear (its twin) is not; nothing is found
    on the untilted twin, and without the tilt nothing at all."""
    from types import SimpleNamespace

    from suspid.workflows.diagnose.coupling import coupling_test, twin

    channels = ["bogie_front_vertical", "bogie_front_lateral", "bogie_rear_vertical", "bogie_rear_lateral"]
    assert twin("bogie_front_lateral", channels) == "bogie_rear_lateral" and twin("carbody_middle_x", channels) is None

    def records(angle_deg, seed=1, own=0.03):
        rng = np.random.default_rng(seed)
        a = math.radians(angle_deg)
        out = []
        for _ in range(24):
            s = np.convolve(rng.standard_normal(840), np.ones(5) / 5, "same")   # the track: the rear 0.2 s later
            rows = []
            for tilt, v in ((a, s[20:820]), (0.0, s[:800])):
                lat = 0.5 * rng.standard_normal(800) + own * v
                rows += [v, math.cos(tilt) * lat + math.sin(tilt) * v]
            out.append(SimpleNamespace(accelerations=np.array(rows), fs=100.0))
        return out

    rows = {r["channel"]: r for r in coupling_test(records(6.0), channels, (0.4, math.inf),
                                                   model_coupling={c: 0.03 for c in channels})}
    front, rear = rows["bogie_front_lateral"], rows["bogie_rear_lateral"]
    assert front["significant"] and not rear["significant"] and front["twin"] == "bogie_rear_lateral"
    assert front["angle_deg"] == pytest.approx(6.0, rel=0.1)
    assert math.degrees(math.asin(front["beta_raw"])) == pytest.approx(6.0 + math.degrees(0.03), rel=0.1)
    # against a model without the vehicle's coupling (0) the untilted rear differs from it, but not from its twin
    # beyond the tilt: the pair says the front is the tilted one
    rows0 = {r["channel"]: r for r in coupling_test(records(6.0), channels, (0.4, math.inf))}
    assert rows0["bogie_front_lateral"]["significant"] and not rows0["bogie_rear_lateral"]["significant"]
    assert not any(r["significant"] for r in coupling_test(records(0.0, seed=2), channels, (0.4, math.inf),
                                                            model_coupling={c: 0.03 for c in channels}))


@pytest.mark.slow
@pytest.mark.acceptance
@pytest.mark.parametrize("seed", SEEDS)
def test_independent_shared_tilt_under_sensor_noise_is_named(tmp_path, seed):
    """4° on both bogies' lateral sensors (twins: their difference cancels it) and on the mid-car one, 0.005 m/s²
    of white sensor noise: named from the coupling (instrumental variables against the model's coupling, the
    lateral motion of the untilted carbody ends removed) on the three channels, the angle within 10 % (what is
    left is the channels' calibration-gain ratios, 0.89-1.05 on seeds 3-5)."""
    d, _ = run_case(tmp_path, "shared-tilt", seed)
    assert "sensor-tilt" in d["named_effects"], d["reason"]
    tilt = next(e for e in d["effects"] if e["name"] == "sensor-tilt")["parameters"]
    assert set(tilt["channels"]) == {"bogie_front_lateral", "bogie_rear_lateral", "carbody_middle_lateral"}, tilt
    assert abs(tilt["angle_deg"] - 4.0) <= 0.4, tilt


@pytest.mark.slow
@pytest.mark.acceptance
@pytest.mark.parametrize("seed", SEEDS)
def test_independent_lateral_bracket_is_never_named(tmp_path, seed):
    """A bracket resonance (14 Hz) on one carbody lateral sensor: nothing named (no tilt on it or its untouched
    twin), the resonance reported unexplained on its channel."""
    d, _ = run_case(tmp_path, "bracket-lateral", seed)
    assert d["named_effects"] == [], d["reason"]
    hits = [u for u in d["unexplained"] if u["channel"] == "carbody_front_lateral"
            and u["f_low_hz"] <= 14.0 <= u["f_high_hz"]]
    assert hits and "no catalogue effect fits" in hits[0]["text"], d["unexplained"]


@pytest.mark.slow
@pytest.mark.acceptance
@pytest.mark.parametrize("seed", SEEDS)
def test_independent_one_wheelset_polygon_is_named_with_its_order(tmp_path, seed):
    d, _ = run_case(tmp_path, "polygon-one", seed)
    assert "wheel-polygon" in d["named_effects"], d["reason"]
    assert _main(d, "wheel-polygon") == 1, d["effects"]


@pytest.mark.slow
@pytest.mark.acceptance
@pytest.mark.parametrize("seed", SEEDS)
def test_independent_channel_gain_is_reported(tmp_path, seed):
    """+8 % on one channel (0.67 dB, below min_db in every cell): reported as a channel-level gain there."""
    d, _ = run_case(tmp_path, "gain-8", seed)
    gains = {g["channel"]: g for g in d["channel_gains"] if g["significant"]}
    assert "bogie_rear_vertical" in gains, d["channel_gains"]
    assert gains["bogie_rear_vertical"]["gain"] == pytest.approx(1.08, abs=0.03)
    assert any(u.get("kind") == "channel-level gain" and u["channel"] == "bogie_rear_vertical"
               for u in d["unexplained"])
