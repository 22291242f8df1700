"""The frequency solver with a speed record (short-time constant speed with overlap-add,
plugins/simulators/exudyn_train/variable_speed.py) against its parts and against the time solver."""

from __future__ import annotations

import time

import numpy as np

from suspid.data.track import synthetic_segments
from suspid.interfaces import TrackSegment
from suspid.method.spectra import record_spectrum
from suspid.plugins.simulators.exudyn_train import ExudynTrain
from suspid.plugins.simulators.exudyn_train.solvers import FrequencyResponse
from suspid.plugins.simulators.exudyn_train.variable_speed import SpeedFamily, wheelset_responses


def ramp_segment(length_m=400.0, v0=50.0, spread=0.1, seed=3):
    seg = synthetic_segments({"spectrum": "german-low", "n_segments": 1, "length_m": length_m,
                              "speed_kmh": 3.6 * v0, "seed": seed})[0]
    x = seg.distance
    v = v0 * (1.0 - spread + 2 * spread * (x - x[0]) / (x[-1] - x[0]))      # -10 % to +10 %, linear in distance
    return TrackSegment("ramp", x, seg.irregularities, v)


def test_speed_family_is_the_linear_model_at_another_speed():
    """The low-rank update of the creep damping about v0 gives the per-wheelset response of a model
    linearised at v directly (Woodbury identity: exact up to rounding)."""
    sim = ExudynTrain()
    a, b = sim.linear_system({}, 50.0), sim.linear_system({}, 100.0)
    d_creep = (a.D - b.D) * 100.0
    freqs = np.linspace(0.0, 30.0, 61)
    family = SpeedFamily(FrequencyResponse(sim.linear_system({}, 80.0)), d_creep, freqs)
    for v in (72.0, 88.0):
        direct = wheelset_responses(FrequencyResponse(sim.linear_system({}, v)), freqs)   # (n_w, 3, n_out, n_f)
        U = np.zeros((12, freqs.size), dtype=complex)
        U[4] = 1.0                                   # lateral alignment under wheelset 2 alone
        np.testing.assert_allclose(family.apply(v, U), direct[1, 1], rtol=1e-6,
                                   atol=1e-9 * np.max(np.abs(direct[1, 1])))
    # and the shift matters: the responses at 72 and 88 m/s differ by more than 1 %
    d72 = wheelset_responses(FrequencyResponse(sim.linear_system({}, 72.0)), freqs)[1, 1]
    d88 = wheelset_responses(FrequencyResponse(sim.linear_system({}, 88.0)), freqs)[1, 1]
    assert np.max(np.abs(d72 - d88)) > 0.01 * np.max(np.abs(d88))


def test_variable_speed_frequency_solver_matches_the_time_solver():
    """Speed +-10 % over a 400 m segment (50 m/s mean): median |dY| <= 0.5 dB against the time solver,
    and the frequency solver is faster. The constant-speed path is untouched (same records as before)."""
    ramp = ramp_segment()
    fsim = ExudynTrain(solver="frequency", fs_hz=100.0)
    tsim = ExudynTrain(solver="time", fs_hz=100.0, step_s=0.002)
    (rf,) = fsim.simulate({}, [ramp])
    (rt,) = tsim.simulate({}, [ramp])
    assert rf.accelerations.shape == rt.accelerations.shape
    grid = {"f_min_hz": 0.5, "f_max_hz": 30.0, "n_freqs": 60}          # an 8 s record: cells of 4 lines
    d = np.abs(record_spectrum(rf.accelerations, 100.0, grid) - record_spectrum(rt.accelerations, 100.0, grid))
    assert np.median(d) <= 0.5, np.median(d)
    w = {"c_yaw": 5.2e5}
    t0 = time.perf_counter()
    fsim.simulate(w, [ramp])
    t_f = time.perf_counter() - t0
    t0 = time.perf_counter()
    tsim.simulate(w, [ramp])
    t_t = time.perf_counter() - t0
    assert t_f < t_t, (t_f, t_t)


def test_constant_speed_segments_keep_the_constant_speed_path():
    """A segment of constant speed beside a variable one gives the record it gives alone (bit-identical)."""
    ramp = ramp_segment(300.0)
    const = TrackSegment("const", ramp.distance, ramp.irregularities, 50.0)
    sim = ExudynTrain(solver="frequency", fs_hz=100.0)
    (alone,) = ExudynTrain(solver="frequency", fs_hz=100.0).simulate({}, [const])
    both = sim.simulate({}, [ramp, const])
    assert np.array_equal(both[1].accelerations, alone.accelerations)
    assert both[0].accelerations.shape[1] == int(round(ramp.duration() * 100.0))
