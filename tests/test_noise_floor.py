"""The sensor-noise floor of the noise model: a known gain and floor come back; the floor holds still.

Data: P_mes_i = g P_sim_i + N (two-sided PSD) with Y = 5 log10 P, the excitation
level of every segment drawn anew (that is what makes g and N separable), plus
Gaussian scatter in dB.
"""

import json

import numpy as np
import pytest

from suspid.errors import ConfigError
from suspid.method.floor import estimate_floor
from suspid.method.noise import NoiseModel, fit_noise_model, modelled_spectra
from suspid.method.objective import ObjectiveFunction
from suspid.plugins.objectives.likelihood import LikelihoodObjective as Likelihood

V0, F = 40, 120
FREQS = np.linspace(0.5, 40.0, F)
CHANNELS = ("carbody_vertical", "bogie_lateral", "clean")
GAIN_DB = np.array([1.0, -0.5, 0.3])                 # m per channel, dB of Y
FLOOR_DB = np.array([-36.0, -45.0, None])            # 5 log10 N per channel; the last has no floor


def data(seed: int = 1, scatter_db: float = 0.4):
    """y_mes, y_sim ``(V0, 3, F)`` dB with the known gain and floor above."""
    rng = np.random.default_rng(seed)
    base = -20.0 - 15.0 * np.log10(FREQS)[None, None, :] * np.array([1.0, 1.5, 2.0])[None, :, None]
    y_sim = base + rng.normal(0, 2.0, (V0, 1, 1)) + rng.normal(0, 1.0, (V0, 3, 1))
    power = np.array([0.0 if d is None else 10 ** (d / 5) for d in FLOOR_DB])[:, None]
    y_mes = 5 * np.log10(10 ** ((y_sim + GAIN_DB[:, None]) / 5) + power) + rng.normal(0, scatter_db, y_sim.shape)
    return y_mes, y_sim


def test_known_gain_and_floor_are_recovered():
    y_mes, y_sim = data()
    floor = estimate_floor(y_mes, y_sim, FREQS)
    for k in (0, 1):
        on = floor.power[k] > 0
        assert on.mean() > 0.8                      # identified over most of the band
        assert np.median(5 * np.log10(floor.power[k, on])) == pytest.approx(FLOOR_DB[k], abs=0.5)
        signal = (y_sim.mean(axis=0)[k] + GAIN_DB[k]) > FLOOR_DB[k] + 5     # where the gain is identifiable
        assert np.median(np.abs(floor.gain_db[k, signal] - GAIN_DB[k])) < 0.15
    assert np.all(floor.power[2] == 0)               # no floor in the data: none found (N = 0 fallback)
    np.testing.assert_allclose(floor.gain_db[2], (y_mes - y_sim).mean(axis=0)[2])


def test_no_floor_where_the_excitation_never_changes():
    """With the same P_sim on every segment g and N cannot be told apart: N = 0 there."""
    y_mes, y_sim = data()
    flat = np.repeat(y_sim[:1], V0, axis=0)
    y_flat = y_mes - y_sim + flat                     # same scatter, no excitation change
    assert np.all(estimate_floor(y_flat, flat, FREQS).power == 0)


def test_modelled_spectrum_holds_still_in_a_noise_dominated_cell():
    y_mes, y_sim = data()
    model = fit_noise_model(y_mes, y_sim, {"floor": "auto"}, freqs=FREQS, channels=CHANNELS)
    b = model.sample(V0, seed=3)
    now, lower = modelled_spectra(y_sim, b, model.floor_), modelled_spectra(y_sim - 10.0, b, model.floor_)
    level = y_sim.mean(axis=0)[1] + GAIN_DB[1]
    noisy = level < FLOOR_DB[1] - 5                     # the floor dominates by 5 dB (a factor 10 in power)
    assert noisy.sum() > 10
    # 10 dB less simulated: at most 5 log10(1.1 / 1.01) = 0.19 dB less modelled (with the exact gain and floor)
    assert np.median(np.abs(now[:, 1, noisy] - lower[:, 1, noisy])) < 0.25
    loud = level > FLOOR_DB[1] + 15
    np.testing.assert_allclose((now - lower)[:, 1, loud], 10.0, atol=0.2)  # where the signal dominates it follows
    np.testing.assert_array_equal(modelled_spectra(y_sim, b, None), y_sim + b)  # no floor: eq. 4 exactly
    # without a floor (today's model) the same cell moves by the whole 10 dB
    plain = fit_noise_model(y_mes, y_sim, {}, freqs=FREQS, channels=CHANNELS)
    assert plain.floor_ is None
    np.testing.assert_allclose(plain.effective(y_sim) - plain.effective(y_sim - 10.0), 10.0, rtol=1e-12)


def test_objective_sees_the_floor():
    """J at the true floor model is the same whether y_sim drops 10 dB in noise-dominated cells or not."""
    y_mes, y_sim = data()
    noisy = (y_sim.mean(axis=0) + GAIN_DB[:, None]) < np.array([-46.0, -55.0, -1e9])[:, None]
    model = fit_noise_model(y_mes, y_sim, {"floor": "auto"}, freqs=FREQS, channels=CHANNELS)
    fn = ObjectiveFunction.from_noise_model(Likelihood(), y_mes, FREQS, model, seed=5, channels=CHANNELS)
    assert fn.floor is model.floor_
    j_now = fn.evaluate(y_sim)[0]
    j_lower = fn.evaluate(np.where(noisy[None], y_sim - 10.0, y_sim))[0]
    assert j_lower == pytest.approx(j_now, abs=0.02 * abs(j_now))
    plain = ObjectiveFunction.from_noise_model(Likelihood(), y_mes, FREQS,
                                               fit_noise_model(y_mes, y_sim, {}, freqs=FREQS, channels=CHANNELS),
                                               seed=5, channels=CHANNELS)
    assert plain.evaluate(np.where(noisy[None], y_sim - 10.0, y_sim))[0] < plain.evaluate(y_sim)[0] - 0.2 * abs(j_now)


def test_floor_from_a_sensor_specification():
    y_mes, y_sim = data()
    density = {c: 2 * 10 ** (d / 5) if d is not None else 1e-30 for c, d in zip(CHANNELS, FLOOR_DB)}
    model = fit_noise_model(y_mes, y_sim, {"floor": "spec", "sensor_noise_density": density},
                            freqs=FREQS, channels=CHANNELS)
    np.testing.assert_allclose(model.floor_.power[0], 10 ** (FLOOR_DB[0] / 5))     # one-sided / 2
    signal = (y_sim.mean(axis=0)[1] + GAIN_DB[1]) > FLOOR_DB[1] + 5
    assert np.median(np.abs(model.floor_.gain_db[1, signal] - GAIN_DB[1])) < 0.15
    one = fit_noise_model(y_mes, y_sim, {"floor": "spec", "sensor_noise_density": 2e-7}, channels=CHANNELS)
    np.testing.assert_allclose(one.floor_.power, 1e-7)


@pytest.mark.parametrize("options, match", [
    ({"floor": "spec"}, r"key 'noise': floor: spec needs sensor_noise_density"),
    ({"floor": "loud"}, r"noise\.floor"),
    ({"floor": "spec", "sensor_noise_density": -1.0}, r"noise\.sensor_noise_density"),
    ({"floor": "spec", "sensor_noise_density": {"carbody_vertical": 1e-6}}, r"missing: bogie_lateral, clean"),
    ({"floor": "spec", "sensor_noise_density": {**{c: 1e-6 for c in CHANNELS}, "roof": 1e-6}}, r"unknown: roof"),
])
def test_bad_floor_options_are_one_line_errors(options, match):
    y_mes, y_sim = data()
    with pytest.raises(ConfigError, match=match) as err:
        fit_noise_model(y_mes, y_sim, options, freqs=FREQS, channels=CHANNELS)
    assert "\n" not in str(err.value)


def test_floor_is_saved_and_old_files_load_without_one(tmp_path):
    y_mes, y_sim = data()
    model = fit_noise_model(y_mes, y_sim, {"floor": "auto"}, freqs=FREQS, channels=CHANNELS)
    again = NoiseModel.load(model.save(tmp_path / "floor.npz"))
    np.testing.assert_array_equal(again.floor_.power, model.floor_.power)
    np.testing.assert_array_equal(again.floor_.gain_db, model.floor_.gain_db)
    # a file as written before the floor existed: format version 1, three options, no floor arrays
    plain = fit_noise_model(y_mes, y_sim, {}, freqs=FREQS, channels=CHANNELS)
    old = tmp_path / "old.npz"
    meta = {"format": "suspid-noise-model", "format_version": 1, "shrinkage": 0.0, "n_samples": V0,
            "options": {"n_components": None, "variance_fraction": 0.99, "shrinkage": 0.0},
            "channels": list(CHANNELS)}
    np.savez(old, meta=np.array(json.dumps(meta)), freqs=FREQS,
             **{n: getattr(plain, n + "_") for n in NoiseModel._ARRAYS})
    loaded = NoiseModel.load(old)
    assert loaded.floor_ is None
    np.testing.assert_array_equal(loaded.effective(y_sim), y_sim)
    # and a model without a floor is still written as version 1, readable by suspid before the floor
    with np.load(plain.save(tmp_path / "plain.npz")) as content:
        assert json.loads(str(content["meta"]))["format_version"] == 1 and "floor_power" not in content.files


def test_diagnosis_sees_no_discrepancy_where_the_floor_dominates():
    """Measurement date: the simulated response drops by 10 dB where the floor dominates (a parameter or
    speed change), the measured levels barely move. Through the floor nothing is flagged there; with
    today's model (additive in dB) those cells are flagged."""
    from suspid.workflows.diagnose import calibrate_null, locate, make_cells

    y_mes0, y_sim0 = data(seed=1)
    y_mes1, y_sim1 = data(seed=2, scatter_db=0.0)
    level = y_sim0.mean(axis=0) + GAIN_DB[:, None]
    noisy = np.zeros(level.shape, bool)
    noisy[:2] = level[:2] < np.array(FLOOR_DB[:2], dtype=float)[:, None] - 5
    y_sim1 = np.where(noisy[None], y_sim1 - 10.0, y_sim1)
    power = np.array([0.0 if d is None else 10 ** (d / 5) for d in FLOOR_DB])[:, None]
    rng = np.random.default_rng(7)
    y_mes1 = 5 * np.log10(10 ** ((y_sim1 + GAIN_DB[:, None]) / 5) + power) + rng.normal(0, 0.4, y_sim1.shape)
    flagged = {}
    for mode in ("auto", "none"):
        model = fit_noise_model(y_mes0, y_sim0, {"floor": mode}, freqs=FREQS, channels=CHANNELS)
        grid = make_cells(list(CHANNELS), FREQS, [80.0] * V0)
        null = calibrate_null(grid, model, 100, np.random.default_rng(4))
        dmap = locate(grid, null, y_mes1, model.effective(y_sim1), model.mean_)
        in_noise = (grid.cell_means(noisy[None].astype(float).repeat(V0, axis=0)) > 0.5)
        worst = max(abs(r["magnitude_db"]) for r, n in zip(dmap.rows(), in_noise) if n)
        flagged[mode] = int((dmap.flagged & in_noise).sum()), int(in_noise.sum()), worst
    assert flagged["none"][0] >= 0.8 * flagged["none"][1] > 3      # additive in dB: the floor cells move
    assert flagged["none"][2] > 5.0                                # by several dB
    # with the floor the residual there is what the floor's estimate leaves (about 0.1-0.3 dB with v0 = 40)
    assert flagged["auto"][2] < 0.4 and flagged["auto"][0] <= 0.25 * flagged["auto"][1]


def test_run_with_a_specified_floor_reports_and_saves_it(tmp_path):
    """A whole (small) identification with the sensors' density given: the floor reaches the run's noise
    model file, result.json and report.md, and w_ref is still recovered."""
    from test_pipeline import _write

    from suspid.config import load_config
    from suspid.workflows.identify import run

    cfg = _write(tmp_path)
    # 24 segments: with the 16 of the pipeline test the statistical error of k_sec_z reaches 10 %
    cfg.write_text(cfg.read_text().replace("n_segments: 16", "n_segments: 24"))
    # the experiment's reference sensors: 0.005 m/s² rms white at 100 Hz, one-sided 2 σ² / fs
    cfg.write_text(cfg.read_text().replace("noise: {floor: auto}", "noise: {floor: spec, sensor_noise_density: 5.0e-7}"))
    out = run(load_config(cfg), progress=False, log=lambda s: None)
    r = out.result
    assert max(r["errors_percent"].values()) < 8.0, r["errors_percent"]
    assert r["noise_floor"]["mode"] == "spec"
    assert all(row["share"] == 1.0 and row["median_db"] == pytest.approx(5 * np.log10(2.5e-7))
               for row in r["noise_floor"]["channels"].values())
    assert json.loads((out.run_dir / "result.json").read_text())["noise_floor"] == r["noise_floor"]
    assert "## Sensor-noise floor" in (out.run_dir / "report.md").read_text()
    np.testing.assert_allclose(NoiseModel.load(out.run_dir / "noise_model.npz").floor_.power, 2.5e-7)


def test_model_error_keeps_a_given_systematic_gain():
    """Two dates of one vehicle through apply_model_error share its fixed gains when they are passed on;
    without them the first draws of rng are those gains (the smooth one, then one flat gain per channel)."""
    from suspid.data.experiment import (ReferenceOptions, apply_model_error, fixed_gains_db, measurement_process,
                                        smooth_gain_db, systematic_grid)
    from suspid.interfaces import Response

    fs = 100.0
    a = np.random.default_rng(0).standard_normal((2, 2000))
    r = [Response(["x", "y"], fs, a, "s1")]
    opt = ReferenceOptions(model_error_db=1.5, model_error_scatter_db=0.0, sensor_noise_rms=0.0, segment_gain_db=0.0)
    drawn = apply_model_error(r, opt, np.random.default_rng(3))[0].accelerations
    rng = np.random.default_rng(3)
    sys_db = smooth_gain_db(rng, systematic_grid(fs), 2, 1.5, opt.correlation_octaves)
    sys_db = sys_db + opt.channel_gain_db * rng.standard_normal(2)[:, None]
    np.testing.assert_allclose(fixed_gains_db(np.random.default_rng(3), fs, 2, opt), sys_db)
    given = apply_model_error(r, opt, np.random.default_rng(99), sys_db)[0].accelerations
    np.testing.assert_allclose(given, drawn, atol=1e-12)
    assert not np.allclose(drawn, a)
    # measurement_process draws them from its fixed seed: every date passing that seed shares them
    np.testing.assert_allclose(measurement_process(r, opt, np.random.default_rng(5), fixed_seed=3)[0].accelerations,
                               drawn, atol=1e-12)


def test_measurement_process_gains_per_channel_and_per_segment():
    """A flat fixed gain per channel (the same on both dates) and a flat gain per segment, in Y = 10 log10|A|:
    the log-amplitude ratio of a measured to a simulated record is the gain in dB, exactly (no noise)."""
    from suspid.data.experiment import ReferenceOptions, fixed_gains_db, measurement_process
    from suspid.interfaces import Response

    fs, n_t = 100.0, 4000
    base = np.random.default_rng(0).standard_normal((3, n_t))
    segs = [Response(["x", "y", "z"], fs, base, f"s{i}") for i in range(30)]
    opt = ReferenceOptions(model_error_db=0.0, model_error_scatter_db=0.0, sensor_noise_rms=0.0,
                           channel_gain_db=1.0, segment_gain_db=0.5)

    def gains(out):   # (segments, channels) dB: 10 log10 of the rms ratio, the gain being flat in frequency
        return np.array([10 * np.log10(np.std(o.accelerations, axis=1) / np.std(base, axis=1)) for o in out])

    ref = gains(measurement_process(segs, opt, np.random.default_rng(1), fixed_seed=0))
    mes = gains(measurement_process(segs, opt, np.random.default_rng(2), fixed_seed=0))
    fixed = fixed_gains_db(np.random.default_rng(0), fs, 3, opt)   # (3, 512), flat: one value per channel
    assert np.ptp(fixed, axis=1).max() < 1e-12 and np.ptp(fixed[:, 0]) > 1.0   # the channels' gains differ
    # both dates hold the same fixed gains, up to the mean of 30 segment gains (0.5 dB rms: 4 sigma = 0.37 dB)
    np.testing.assert_allclose(ref.mean(axis=0), fixed[:, 0], atol=4 * 0.5 / np.sqrt(30))
    np.testing.assert_allclose(mes.mean(axis=0), fixed[:, 0], atol=4 * 0.5 / np.sqrt(30))
    assert 0.3 < ref.std(axis=0, ddof=1).mean() < 0.7      # per-segment gains of 0.5 dB rms
    assert not np.allclose(ref, mes)                        # drawn anew on each date
