"""Effects: the plugin kind, the built-in catalogue and the exudyn model's implementations.

The exudyn tests run the real model with both solvers: every effect must act
the same in the time solver (exudyn integration) and the frequency solver
(exudyn's linearisation), and do what its physics says.
"""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

from suspid import hookimpl, registry
from suspid.errors import ConfigError, SimulatorError
from suspid.interfaces import Effect, EffectSignature
from suspid.plugins.effects import EFFECTS, beam_mode_shape, klingel_hz
from suspid.plugins.simulators.exudyn_train import ExudynTrain
from suspid.plugins.simulators.exudyn_train.effects import point_jacobian
from suspid.method.spectra import compute_spectra
from suspid.data.track import synthetic_segments

KMH = 1 / 3.6
NAMES = {"carbody-bending", "wheel-polygon", "yaw-damper-series-stiffness", "sensor-tilt", "conicity-change",
         "track-flexibility"}
EXAMPLES = {
    "carbody-bending": {"frequency_hz": 9.5, "damping": 0.02},
    "wheel-polygon": {"order": 1, "amplitude_m": 1e-4},
    "yaw-damper-series-stiffness": {"stiffness_n_per_m": 3e6},
    "sensor-tilt": {"angle_deg": 5.0},
    "conicity-change": {"conicity": 0.3},      # the default car's conicity is 0.15
    "track-flexibility": {"frequency_hz": 60.0},
}


def segments(n=1, length=600.0, speed_kmh=300.0, seed=1):
    return synthetic_segments({"n_segments": n, "length_m": length, "speed_kmh": speed_kmh, "seed": seed})


def spectra(responses, f_max=40.0, n=200):
    return compute_spectra(responses, {"f_min_hz": 0.5, "f_max_hz": f_max, "n_freqs": n})


# ------------------------------------------------------------------------------------------ plugin kind
def test_six_effects_are_registered_through_the_entry_point():
    assert NAMES <= set(registry.names("effect"))
    for cls in EFFECTS:
        assert registry.get("effect", cls.name) is cls
        assert issubclass(cls, Effect)
        assert cls.main_parameter in cls.Options.model_fields
        assert set(cls.fitted) <= set(cls.Options.model_fields)
        for p in cls.fitted:
            lo, hi = cls.bounds(p)
            assert lo < cls.defaults()[p] <= hi or lo <= cls.defaults()[p] < hi
        sig = cls().signature(300 * KMH)
        assert isinstance(sig, EffectSignature) and sig.band_hz[0] < sig.band_hz[1]
        assert sig.speed_dependence in ("none", "proportional", "kinematic")


def test_signatures_follow_the_catalogue():
    v = 300 * KMH
    bend = registry.get("effect", "carbody-bending")().signature(v)
    assert bend.matches_channel("carbody_middle_vertical") and not bend.matches_channel("carbody_middle_lateral")
    assert not bend.matches_channel("bogie_front_vertical") and bend.speed_dependence == "none"
    poly = registry.get("effect", "wheel-polygon")(order=3)
    assert poly.signature(v).band_hz[0] == pytest.approx(v / (math.pi * 0.92))          # 28.8 Hz per order
    assert poly.signature(2 * v).band_hz[0] == pytest.approx(2 * poly.signature(v).band_hz[0])
    assert poly.wavelength() == pytest.approx(math.pi * 0.92 / 3)
    tilt = registry.get("effect", "sensor-tilt")().signature(v)
    assert tilt.matches_channel("bogie_rear_lateral") and not tilt.matches_channel("bogie_rear_vertical")
    assert tilt.matches_channel("channel_7")  # no body or direction word: not ruled out
    assert klingel_hz(v, 0.25) == pytest.approx(v / (2 * math.pi) * math.sqrt(0.25 / (0.46 * 0.75)))


def test_candidates_start_in_the_flagged_cells():
    v = 300 * KMH
    bend = registry.get("effect", "carbody-bending")()
    starts = bend.candidates([v], [("carbody_middle_vertical", 8.9, 11.2, v), ("bogie_front_lateral", 3, 4, v)], [])
    assert starts and all(8.9 <= s["frequency_hz"] <= 11.2 for s in starts)
    poly = registry.get("effect", "wheel-polygon")()
    orders = {s["order"] for s in poly.candidates([v], [("bogie_front_vertical", 27.0, 30.0, v)], [])}
    assert orders == {1}


def test_beam_mode_shape():
    x = np.linspace(-13.0, 13.0, 2601)
    phi = beam_mode_shape(x, 26.0)
    assert beam_mode_shape(0.0, 26.0) == pytest.approx(1.0)
    assert phi[0] == pytest.approx(-1.645, abs=2e-3) and phi[-1] == pytest.approx(phi[0])
    nodes = x[np.nonzero(np.diff(np.sign(phi)))[0]]
    assert nodes == pytest.approx([-0.2759 * 26, 0.2759 * 26], abs=0.02)
    assert abs(np.trapezoid(phi, x)) < 1e-3 * 26     # orthogonal to the rigid bounce


def test_an_effect_a_simulator_does_not_implement_is_a_clear_error(tmp_path):
    class Squeal(Effect):
        name = "squeal"
        main_parameter = "frequency_hz"

        class Options(__import__("pydantic").BaseModel):
            frequency_hz: float = 500.0

        def signature(self, speed_mps):
            return EffectSignature(("bogie",), ("vertical",), (400.0, 600.0))

    plugin = types.SimpleNamespace(suspid_register_effects=hookimpl(lambda register: register(Squeal)))
    registry.add_plugin(plugin, "squeal-plugin")
    cfg = tmp_path / "c.yaml"
    cfg.write_text("simulator: {plugin: exudyn-train, options: {effects: [{name: squeal}]}}\n")
    from suspid.config import load_config

    with pytest.raises(ConfigError, match=r"simulator.options.effects.*'squeal' is not supported by exudyn-train"):
        load_config(cfg)


@pytest.mark.parametrize("effects, key, message", [
    ([{"name": "carbody-bending", "frequency_hz": 30}], "simulator.options.effects.0.frequency_hz", "less than or equal"),
    ([{"name": "carbody-bending", "freq": 9}], "simulator.options.effects.0.freq", "expected one of: name, frequency_hz"),
    ([{"name": "bending"}], "simulator.options.effects", "available effects: carbody-bending"),
    ([{"name": "conicity-change"}, {"name": "conicity-change"}], "simulator.options.effects", "enabled twice"),
    ([{"name": "sensor-tilt", "channels": ["carbody_middle_vertical"]}], "simulator.options", "not a lateral channel"),
    ([{"name": "wheel-polygon", "wheelsets": [5]}], "simulator.options", "wheelset 5 does not exist"),
])
def test_effect_options_errors_name_the_key(tmp_path, effects, key, message):
    import yaml

    from suspid.config import load_config

    cfg = tmp_path / "c.yaml"
    cfg.write_text(yaml.safe_dump({"simulator": {"plugin": "exudyn-train", "options": {"effects": effects}}}))
    with pytest.raises(ConfigError, match=message) as info:
        load_config(cfg)
    assert info.value.key == key


def test_fitted_effect_parameters_are_simulator_parameters():
    sim = ExudynTrain(effects=[{"name": "carbody-bending", "frequency_hz": 9.5}])
    params = {p.name: p for p in sim.parameters()}
    p = params["carbody-bending/frequency_hz"]
    assert (p.nominal, p.lower, p.upper, p.unit) == (9.5, 5.0, 20.0, "Hz")
    assert "carbody-bending/damping" in params and "carbody-bending/length_m" not in params
    assert sim.values({"carbody-bending/frequency_hz": 11.0})["carbody-bending/frequency_hz"] == 11.0
    with pytest.raises(SimulatorError, match="unknown parameter"):
        ExudynTrain().values({"carbody-bending/frequency_hz": 11.0})
    # changing a fitted parameter updates the model in place, without a rebuild
    seg = segments(length=300.0)
    sim.simulate({}, seg)
    model = next(iter(sim._models.values()))
    sim.simulate({"carbody-bending/frequency_hz": 11.0}, seg)
    assert next(iter(sim._models.values())) is model
    modes = sim.modes(speed=300 * KMH, w={"carbody-bending/frequency_hz": 11.0})["modes"]
    bending = [m for m in modes if m["body"] == "carbody-bending"]
    assert len(bending) == 1 and bending[0]["frequency_hz"] == pytest.approx(11.0, rel=0.02)


def test_rigid_point_jacobian_matches_exudyn_kinematics():
    sim = ExudynTrain()
    model = sim._model(sim.values({}), 300 * KMH, __import__(
        "suspid.plugins.simulators.exudyn_train.model", fromlist=["TimeFeatures"]).TimeFeatures())
    for i, s in enumerate(model.sensors):
        assert np.allclose(model.point_jacobians_xyz[i], point_jacobian(s.position), atol=1e-8)


# ------------------------------------------------------------------------------------------ both solvers
@pytest.fixture(scope="module")
def fast_track():
    return segments(length=600.0)


@pytest.mark.parametrize("name", sorted(NAMES))
def test_time_and_frequency_solvers_agree_with_each_effect(name, fast_track):
    fs = 250.0 if name == "track-flexibility" else 100.0
    f_max = 90.0 if name == "track-flexibility" else 40.0
    eff = [{"name": name, **EXAMPLES[name]}]
    (rt,) = ExudynTrain(solver="time", fs_hz=fs, effects=eff).simulate({}, fast_track)
    (rf,) = ExudynTrain(solver="frequency", fs_hz=fs, effects=eff).simulate({}, fast_track)
    (r0,) = ExudynTrain(solver="frequency", fs_hz=fs).simulate({}, fast_track)
    yt, f = spectra([rt], f_max)
    yf, _ = spectra([rf], f_max)
    y0, _ = spectra([r0], f_max)
    effect_db = np.abs(yf[0] - y0[0])
    shows = effect_db > 1.0                                  # where the effect changes the spectra
    assert shows.sum() >= 3, name
    assert np.median(np.abs(yt[0] - yf[0])[shows]) < 0.3, name
    rms = np.sqrt(np.mean(rt.accelerations ** 2, axis=1)) / np.sqrt(np.mean(rf.accelerations ** 2, axis=1))
    assert np.all(np.abs(rms - 1) < 0.05), (name, rms)


def test_bending_shows_mid_car_vertical(fast_track):
    (r0,) = ExudynTrain().simulate({}, fast_track)
    (rb,) = ExudynTrain(effects=[{"name": "carbody-bending", **EXAMPLES["carbody-bending"]}]).simulate({}, fast_track)
    y0, f = spectra([r0])
    yb, _ = spectra([rb])
    ch = ExudynTrain().channels()
    d = yb[0] - y0[0]
    mid = ch.index("carbody_middle_vertical")
    assert f[np.argmax(d[mid])] == pytest.approx(9.5, abs=0.5) and d[mid].max() > 6.0
    assert d[mid].max() > d[ch.index("carbody_front_vertical")].max() + 2.0    # strongest mid-car
    assert np.abs(d[[ch.index(c) for c in ch if "lateral" in c]]).max() < 1e-6   # a vertical mode


def test_polygon_is_a_line_at_k_v_over_pi_d_on_the_bogie(fast_track):
    v = 300 * KMH
    sim = ExudynTrain(effects=[{"name": "wheel-polygon", "order": 1, "amplitude_m": 1e-4, "wheelsets": [3]}])
    (r,) = sim.simulate({}, fast_track)
    (r0,) = ExudynTrain().simulate({}, fast_track)
    ch = sim.channels()
    a = r.accelerations - r0.accelerations
    f = np.fft.rfftfreq(a.shape[1], 1 / r.fs)
    rear = np.abs(np.fft.rfft(a[ch.index("bogie_rear_vertical")]))
    front = np.abs(np.fft.rfft(a[ch.index("bogie_front_vertical")]))
    assert f[np.argmax(rear)] == pytest.approx(v / (math.pi * 0.92), abs=2 / (a.shape[1] / r.fs))
    assert rear.max() > 100 * front.max()                      # wheelset 3 is in the rear bogie


def test_tilt_mixes_the_vertical_into_the_lateral_channel(fast_track):
    alpha = math.radians(5.0)
    base = ExudynTrain(gravity_roll=False)    # the model's own g × roll is switched off here
    tilted = ExudynTrain(gravity_roll=False,
                         effects=[{"name": "sensor-tilt", "angle_deg": 5.0, "gravity_roll": False,
                                   "channels": ["carbody_middle_lateral"]}])
    (r0,) = base.simulate({}, fast_track)
    (r1,) = tilted.simulate({}, fast_track)
    ch = base.channels()
    lat, vert = ch.index("carbody_middle_lateral"), ch.index("carbody_middle_vertical")
    expected = math.cos(alpha) * r0.accelerations[lat] + math.sin(alpha) * r0.accelerations[vert]
    assert np.allclose(r1.accelerations[lat], expected, atol=1e-9)
    others = [i for i in range(len(ch)) if i != lat]
    assert np.allclose(r1.accelerations[others], r0.accelerations[others])
    # with gravity the roll angle of the body enters: a low-frequency addition
    (r2,) = ExudynTrain(gravity_roll=False, effects=[{"name": "sensor-tilt", "angle_deg": 0.0}]).simulate(
        {}, fast_track)
    y0, f = spectra([r0])
    y2, _ = spectra([r2])
    low = f < 1.0
    assert np.mean(y2[0, lat, low] - y0[0, lat, low]) > 0.3


def test_conicity_effect_equals_the_conicity_parameter(fast_track):
    (ra,) = ExudynTrain(effects=[{"name": "conicity-change", "conicity": 0.18}]).simulate({}, fast_track)
    (rb,) = ExudynTrain(vehicle={"conicity": 0.18}).simulate({}, fast_track)
    assert np.allclose(ra.accelerations, rb.accelerations)


def test_series_stiffness_makes_the_yaw_damper_a_spring_at_high_frequency():
    w = 2 * math.pi * 20.0
    stiff = ExudynTrain(effects=[{"name": "yaw-damper-series-stiffness", "stiffness_n_per_m": 100e6}])
    soft = ExudynTrain(effects=[{"name": "yaw-damper-series-stiffness", "stiffness_n_per_m": 3e6}])
    from suspid.plugins.simulators.exudyn_train.solvers import FrequencyResponse

    k = ExudynTrain().channels().index("bogie_front_lateral")
    H = {name: FrequencyResponse(s.linear_system({}, 300 * KMH))(np.array([w / (2 * math.pi)]))[0, k, 1]
         for name, s in (("rigid", ExudynTrain(vehicle={"k_yaw_s": 1e10})), ("stiff", stiff), ("soft", soft))}
    assert abs(H["stiff"] / H["rigid"] - 1) < abs(H["soft"] / H["rigid"] - 1)   # 100 MN/m is nearly rigid
    modes = soft.modes(speed=300 * KMH)
    assert modes["stable"]
    internal = [m for m in modes["modes"] if m["body"] == "yaw-damper-series-stiffness"]
    assert len(internal) >= 4                                   # one internal coordinate per damper


def test_track_flexibility_adds_the_p2_resonance():
    sim = ExudynTrain(effects=[{"name": "track-flexibility", "frequency_hz": 60.0, "damping": 0.3}])
    modes = sim.modes(speed=300 * KMH)["modes"]
    wheelset_bounce = [m for m in modes if m["body"].startswith("wheelset") and m["motion"] == "vertical"
                       and 40 < m["frequency_hz"] < 80]
    assert wheelset_bounce and all(m["frequency_hz"] == pytest.approx(60.0, rel=0.08) for m in wheelset_bounce)
    # the effect replaces the model's own track support (P2 resonance 50-80 Hz)
    own = [m for m in ExudynTrain().modes(speed=300 * KMH)["modes"]
           if m["body"].startswith("wheelset") and m["motion"] == "vertical"]
    assert own and all(50 < m["frequency_hz"] < 80 for m in own)
    assert not any(m["body"] == "track" for m in modes)


def test_static_equilibrium_holds_with_effects():
    """The effects add no static load: the reference configuration stays the equilibrium, the car at rest."""
    from suspid.interfaces import TrackSegment
    from suspid.plugins.simulators.exudyn_train.model import TimeFeatures

    static = sorted(NAMES - {"wheel-polygon"})           # a polygon is an input: it moves the car
    sim = ExudynTrain(solver="time", effects=[{"name": n, **EXAMPLES[n]} for n in static])
    model = sim._model(sim.values({}), 300 * KMH, TimeFeatures())
    assert np.max(np.abs(model.static_residual())) < 1e-9 * 40000 * 9.81
    flat = TrackSegment("flat", np.arange(0.0, 200.0, 0.25), np.zeros((4, 800)), 50.0)
    (rest,) = sim.simulate({}, [flat])
    assert np.max(np.abs(rest.accelerations)) < 1e-6
