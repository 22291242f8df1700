"""Curves and cant as inputs of the exudyn-train model (plugins/simulators/exudyn_train/curving.py):
steady curving against its closed forms, transitions against a direct time integration of the same
linear equations, superposition on the track's response."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lsim

from suspid.data.track import curve_geometry, synthetic_segments
from suspid.errors import ConfigError, SimulatorError
from suspid.interfaces import TrackSegment
from suspid.plugins.simulators.exudyn_train import ExudynTrain
from suspid.plugins.simulators.exudyn_train import parameters as P
from suspid.plugins.simulators.exudyn_train.curving import (CurveModel, DesignTrack, curve_forces, curve_response,
                                                            frame_outputs, static_coordinates)
from suspid.plugins.simulators.exudyn_train.modes import state_matrix
from suspid.plugins.simulators.exudyn_train.solvers import FrequencyResponse

G = 9.81
X = np.arange(0.0, 800.0, 0.25)


def curve(v, radius, cant, irregularities=None, name="curve"):
    irr = np.zeros((4, X.size)) if irregularities is None else irregularities
    return TrackSegment(name, X, irr, v, curvature=np.full(X.size, 1.0 / radius), cant=np.full(X.size, cant))


def steady_state(sim, w, seg):
    """Static equilibrium of the model at parameters ``w`` in the steady curve ``seg``: (body, motion) -> value."""
    values = sim.values(w)
    v = float(seg.speed)
    lin = sim.linear_system(w, v)
    cm = CurveModel.of(values, sim.opts.layout, sim.sensors(values), sim.opts.gravity_roll)
    F = curve_forces(cm, lin, DesignTrack(seg), np.array([400.0]), np.array([v]))
    q = {k: float(val[0]) for k, val in static_coordinates(lin, F).items()}
    return values, lin, cm, q


def offsets(lin, q, radius):
    """Each wheelset's lateral offset from its rails' centre line (the versine x_j^2 / 2R off the car centre's
    tangent), m."""
    return np.array([q[(f"wheelset_{j + 1}", "lateral")] - x ** 2 / (2 * radius)
                     for j, x in enumerate(lin.wheelset_x)])


def test_wheelsets_take_the_conicity_offset_of_pure_rolling():
    """Balanced cant, R = 4000 m. Wheelsets free to steer (primary longitudinal stiffness 3 kN/m): each rolls
    without longitudinal creep at y0 = -r0 l0 / (lambda R) (outwards), within 1 % (the gravitational stiffness
    takes 0.2 %). Rigid bogie (1e11 N/m): the mean offset of the four is the rigid bogie's
    y0 (1 + f22 a^2 / (f11 l0^2)) (a the half wheelbase), within 2 %."""
    sim = ExudynTrain()
    radius, cant = 4000.0, 0.15
    seg = curve(np.sqrt(G * cant / 1.5 * radius), radius, cant)
    values, lin, cm, q = steady_state(sim, {"k_prim_x": 3e3}, seg)
    y0 = -values["r0"] * values["l0"] / (values["conicity"] * radius)
    np.testing.assert_allclose(offsets(lin, q, radius), y0, rtol=0.01)
    values, lin, cm, q = steady_state(sim, {"k_prim_x": 1e11}, seg)
    f11, f22 = cm.creep[0]
    rigid = y0 * (1 + f22 * values["a_ws"] ** 2 / (f11 * values["l0"] ** 2))
    assert np.mean(offsets(lin, q, radius)) == pytest.approx(rigid, rel=0.02)
    # nominal primary stiffness: between the two limits, leading wheelsets further out than trailing ones
    values, lin, cm, q = steady_state(sim, {}, seg)
    y = offsets(lin, q, radius)
    assert np.all(y < 0.9 * y0) and np.all(y > 1.1 * rigid) and y[0] < y[1] and y[2] < y[3]


def roll_closed_form(p, a_q, wheel_load):
    """Carbody, bogie and wheelset roll (rad) of a conventional car under the cant deficiency a_q (m/s^2):
    three roll equilibria. Carbody on the secondary suspension of both bogies (vertical springs and anti-roll
    bars, K_s = 2 (2 k_sec_z b_sec^2 + k_arb)), loaded by m_c a_q at h_car - h_sec above the springs and
    destabilised by its weight on them (m_c g (h_car - h_sec)); each bogie on its primary springs
    (K_p = 4 k_prim_z b_prim^2) under the lateral loads at h_sec and r0 and the tilting preloads; each wheelset
    on the Hertzian springs in series with the track (K_w = 2 l0^2 k_H k_track / (k_H + k_track))."""
    g = 9.81
    mc, mb = p["m_car"], p["m_bogie"]
    dc, hb, hs, r0 = p["h_car"] - p["h_sec"], p["h_bogie"], p["h_sec"], p["r0"]
    Ks = 2 * (2 * p["k_sec_z"] * p["b_sec"] ** 2 + p["k_arb"])
    Kp = 4 * p["k_prim_z"] * p["b_prim"] ** 2
    kh = P.hertz_stiffness(p, wheel_load)
    Kw = 2 * p["l0"] ** 2 * kh * p["k_track"] / (kh + p["k_track"])
    A = np.array([[Ks - mc * g * dc, -Ks, 0.0],
                  [Ks / 2, -(Ks / 2 + Kp - mc * g / 2 * (hs - hb) - (mc / 2 + mb) * g * (hb - r0)), Kp],
                  [0.0, Kp / 2, -(Kp / 2 + Kw)]])
    rhs = np.array([mc * a_q * dc, -((hs - hb) * mc * a_q / 2 + (hb - r0) * (mc / 2 + mb) * a_q), 0.0])
    return np.linalg.solve(A, rhs)


def test_steady_curving_carbody_reads_the_cant_deficiency():
    """Frequency solver in a constant curve (no irregularities): the carbody lateral sensors read
    a = v^2 / R - g cant / (2 l0) + g theta_c, theta_c the carbody's roll in its suspension from the
    three-stage closed form (:func:`roll_closed_form`, 1.72e-2 rad at a_q = 1.08 m/s^2); balanced
    cant gives zero on the carbody and no roll; the reading depends on v, R and cant only through the cant
    deficiency."""
    sim = ExudynTrain(fs_hz=100.0)
    lateral = [i for i, c in enumerate(sim.channels()) if c.startswith("carbody") and c.endswith("lateral")]
    radius, cant = 4000.0, 0.10
    v = 300 / 3.6
    (r,) = sim.simulate({}, [curve(v, radius, cant)])
    values, lin, cm, q = steady_state(sim, {}, curve(v, radius, cant))
    a_q = v ** 2 / radius - G * cant / (2 * values["l0"])
    theta = roll_closed_form(values, a_q, sim.opts.layout.wheel_load(values, 0))[0]
    assert theta > 0.005                                       # rolls outwards (left side up in a left curve)
    assert q[("carbody", "roll")] == pytest.approx(theta, rel=1e-4)
    mid = r.accelerations[:, r.accelerations.shape[1] // 2]
    np.testing.assert_allclose(mid[lateral], a_q + G * theta, atol=1e-4)
    # balanced cant: nothing to read, no roll
    vb = np.sqrt(G * cant / (2 * values["l0"]) * radius)
    (rb,) = sim.simulate({}, [curve(vb, radius, cant)])
    assert np.max(np.abs(rb.accelerations[lateral])) < 1e-4    # (the bogies carry the steering's creep forces)
    assert abs(steady_state(sim, {}, curve(vb, radius, cant))[3][("carbody", "roll")]) < 1e-7
    # the same cant deficiency on a flatter curve without cant: the same reading
    v2 = np.sqrt(a_q * 2 * radius)
    (r2,) = sim.simulate({}, [curve(v2, 2 * radius, 0.0)])
    mid2 = r2.accelerations[:, r2.accelerations.shape[1] // 2]
    np.testing.assert_allclose(mid2[lateral], mid[lateral], rtol=1e-3)


def test_transitions_match_a_direct_integration_of_the_linear_model():
    """Straight, 150 m clothoid, arc (R 2500 m, cant 0.12 m), clothoid, straight at 250 km/h: the frequency
    solver's curve response (static part + FFT of the force increments) equals a time integration of
    M q'' + D q' + K q = F(t) (scipy lsim, first-order hold) plus the frame's terms, on every lateral channel
    (within 1.5 % of the largest value; 0.7 % measured)."""
    sim = ExudynTrain(fs_hz=100.0)
    v = 250 / 3.6
    kappa, cant = curve_geometry(X, {"radius_m": 2500.0, "cant_m": 0.12, "start_m": 100.0,
                                     "transition_m": 150.0, "arc_m": 250.0})
    seg = TrackSegment("clothoids", X, np.zeros((4, X.size)), v, curvature=kappa, cant=cant)
    (r,) = sim.simulate({}, [seg])
    values = sim.values({})
    lin = sim.linear_system({}, v)
    response = FrequencyResponse(lin)
    cm = CurveModel.of(values, sim.opts.layout, sim.sensors(values), True)
    n_t = r.accelerations.shape[1]
    # direct integration from rest in the straight before the curve
    t = np.arange(n_t) / 100.0
    F = curve_forces(cm, lin, DesignTrack(seg), X[0] + v * t, np.full(n_t, v))
    A = state_matrix(lin, positions=response.acting)
    n, p = lin.M.shape[0], response.acting.size
    B = np.vstack([np.zeros((p, n)), response.Minv])
    Cacc = lin.C @ (A[p:, :])                                    # sensors: C q'' + C_disp q
    Cdisp = np.hstack([lin.C_disp[:, response.acting], np.zeros((lin.C.shape[0], n))])
    _, y, _ = lsim((A, B, Cacc + Cdisp, lin.C @ B[p:]), F.T, t, interp=True)
    y = y.T + frame_outputs(cm, DesignTrack(seg), X[0] + v * t, np.full(n_t, v))
    scale = np.max(np.abs(y), axis=1, keepdims=True)
    lateral = [i for i, c in enumerate(r.channels) if c.endswith("lateral")]
    assert np.max(scale[lateral]) > 0.3                            # a real signal: the arc's a_q is 0.36 m/s^2
    np.testing.assert_allclose(r.accelerations[lateral], y[lateral], rtol=0, atol=0.015 * np.max(scale))
    direct = curve_response(response, cm, seg, 100.0, n_t, 8.0, lambda tt: X[0] + v * tt,
                            lambda tt: np.full_like(tt, v))
    np.testing.assert_allclose(direct, r.accelerations, atol=1e-12)


def test_curve_superposes_on_the_track_response():
    """Irregular track in a curve: the record is the straight-track record plus the curve's response (the model
    is linear), constant in a constant curve: the spectra above 0 Hz are those of straight track."""
    sim = ExudynTrain(fs_hz=100.0)
    rough = synthetic_segments({"n_segments": 1, "length_m": 799.75, "speed_kmh": 300.0, "seed": 5})[0]
    v = rough.speed
    (straight,) = sim.simulate({}, [TrackSegment("s", X, rough.irregularities, v)])
    (curved,) = sim.simulate({}, [curve(v, 4000.0, 0.1, rough.irregularities)])
    (smooth,) = sim.simulate({}, [curve(v, 4000.0, 0.1)])
    np.testing.assert_allclose(curved.accelerations, straight.accelerations + smooth.accelerations, atol=1e-9)
    steady = smooth.accelerations[:, 200:-200]
    assert np.max(np.ptp(steady, axis=1)) < 1e-6 * max(1.0, np.max(np.abs(steady)))


def test_time_solver_integrates_the_curve_forces():
    """Irregular track through two clothoids and an arc (R 2000 m, cant 0.12 m) at 250 km/h: the time solver
    (curve forces from time tables, the static curving state at the start) agrees with the frequency solver
    within 4 % of each channel's largest value (the nonlinear kinematics of the time solver about the
    curving offsets, e.g. 50 mm carbody displacement, add up to 2 %); a straight segment after a curved one
    starts straight again."""
    x = np.arange(0.0, 500.0, 0.25)
    rough = synthetic_segments({"n_segments": 1, "length_m": 499.75, "speed_kmh": 250.0, "seed": 6})[0]
    kappa, cant = curve_geometry(x, {"radius_m": 2000.0, "cant_m": 0.12, "start_m": 50.0, "transition_m": 100.0,
                                     "arc_m": 200.0})
    v = 250 / 3.6
    seg = TrackSegment("clothoids", x, rough.irregularities, v, curvature=kappa, cant=cant)
    straight = TrackSegment("straight", x, rough.irregularities, v)
    freq = ExudynTrain(fs_hz=100.0).simulate({}, [seg, straight])
    timed = ExudynTrain(solver="time", fs_hz=100.0).simulate({}, [seg, straight])
    for f, t in zip(freq, timed):
        scale = np.max(np.abs(f.accelerations), axis=1, keepdims=True)
        assert np.all(np.abs(f.accelerations - t.accelerations) <= 0.04 * scale), f.segment
    lateral = [i for i, c in enumerate(freq[0].channels) if c.startswith("carbody") and c.endswith("lateral")]
    assert np.mean(timed[0].accelerations[lateral, 300:450]) > 0.4    # in the arc: a_q 0.62 m/s^2 + roll


def test_curve_inputs_checked():
    bad = TrackSegment("bad", X, np.zeros((4, X.size)), 80.0, curvature=np.full(X.size - 1, 1e-4))
    with pytest.raises(SimulatorError, match="curvature of shape"):
        ExudynTrain().simulate({}, [bad])
    with pytest.raises(ConfigError, match="cant_m"):
        synthetic_segments({"n_segments": 1, "length_m": 100.0, "curve": {"radius_m": 1000.0, "cant_m": 0.5}})


def test_speed_record_through_a_curve_in_both_solvers():
    """Speed rising 45 -> 55 m/s over 400 m through a clothoid into an arc (R 1500 m, cant 0.1 m): the frequency
    solver (speed blocks, curve forces with v(t)) and the time solver agree within 4 % of each channel's
    largest value (3 % measured)."""
    seg = synthetic_segments({"n_segments": 1, "length_m": 400.0, "speed_kmh": 180.0, "seed": 2,
                              "curve": {"radius_m": 1500, "cant_m": 0.1, "start_m": 30, "transition_m": 100}})[0]
    v = 50.0 * (0.9 + 0.2 * seg.distance / seg.distance[-1])
    ramp = TrackSegment("ramp", seg.distance, seg.irregularities, v, curvature=seg.curvature, cant=seg.cant)
    (rf,) = ExudynTrain(fs_hz=100.0).simulate({}, [ramp])
    (rt,) = ExudynTrain(solver="time", fs_hz=100.0).simulate({}, [ramp])
    scale = np.max(np.abs(rt.accelerations), axis=1, keepdims=True)
    assert np.all(np.abs(rf.accelerations - rt.accelerations) <= 0.04 * scale)


@pytest.mark.parametrize("suffix", [".csv", ".h5"])
def test_track_files_keep_curvature_and_cant(tmp_path, suffix):
    from suspid.data.files import read_track, write_track, write_track_csv
    from suspid.errors import DataError

    seg = synthetic_segments({"n_segments": 1, "length_m": 200.0, "seed": 1,
                              "curve": {"radius_m": 1200.0, "cant_m": 0.1, "start_m": 20.0, "transition_m": 60.0,
                                        "direction": "right"}})[0]
    path = tmp_path / f"track{suffix}"
    write_track_csv(seg, path) if suffix == ".csv" else write_track([seg], path)
    (back,) = read_track(path)
    np.testing.assert_array_equal(back.curvature, seg.curvature)
    np.testing.assert_array_equal(back.cant, seg.cant)
    assert back.curvature.min() == pytest.approx(-1 / 1200.0)          # a right-hand curve
    straight = TrackSegment("s", seg.distance, seg.irregularities, seg.speed)
    write_track_csv(straight, tmp_path / "s.csv")
    assert read_track(tmp_path / "s.csv")[0].curvature is None
    bad = TrackSegment("b", seg.distance, seg.irregularities, seg.speed, cant=seg.cant[:-1])
    with pytest.raises(DataError, match="cant must be one finite value per distance sample"):
        write_track_csv(bad, tmp_path / "b.csv")


def test_segments_digest_tells_a_curve_from_straight_track():
    """Run caches key on the segments' digest: a curve must not reuse straight track's results (straight track
    keeps the digest it had without the curve fields)."""
    from suspid.workflows.problem import array_digest, segments_digest
    from suspid.workflows.problem import stable_hash

    x = np.arange(10.0)
    irr = np.zeros((4, 10))
    straight = TrackSegment("a", x, irr, 50.0)
    assert segments_digest([straight]) == stable_hash([array_digest(x, irr, np.atleast_1d(50.0))])
    digests = {segments_digest([TrackSegment("a", x, irr, 50.0, **kw)])
               for kw in ({}, {"curvature": np.full(10, 1e-3)}, {"cant": np.full(10, 1e-3)})}
    assert len(digests) == 3


def test_jacobian_on_curves_and_speed_records():
    """simulate_jacobian on a curved segment with a speed record: central differences of simulate (the
    analytic derivatives hold for straight constant-speed segments only); for a curve at constant speed
    they equal the analytic derivatives of the straight-track record plus the curve record's own (linear
    superposition), within 1e-3 of the largest derivative."""
    sim = ExudynTrain(fs_hz=100.0)
    rough = synthetic_segments({"n_segments": 1, "length_m": 300.0, "speed_kmh": 250.0, "seed": 4})[0]
    x, v = rough.distance, rough.speed
    kappa, cant = curve_geometry(x, {"radius_m": 2000.0, "cant_m": 0.1, "start_m": 30.0, "transition_m": 100.0})
    curved = TrackSegment("curved", x, rough.irregularities, v, curvature=kappa, cant=cant)
    smooth = TrackSegment("smooth", x, np.zeros_like(rough.irregularities), v, curvature=kappa, cant=cant)
    straight = TrackSegment("straight", x, rough.irregularities, v)
    names = ["k_sec_y", "c_yaw"]
    (r, g), (rs, gs) = sim.simulate_jacobian({}, [curved, straight], names)
    ((_, g0),) = sim.simulate_jacobian({}, [smooth], names)
    np.testing.assert_allclose(r.accelerations, sim.simulate({}, [curved])[0].accelerations, atol=1e-12)
    np.testing.assert_allclose(g, gs + g0, rtol=0, atol=1e-3 * np.max(np.abs(g)))
    assert np.max(np.abs(g0)) > 0.01 * np.max(np.abs(gs))          # the curve's part is not negligible
    ramp = TrackSegment("ramp", x, rough.irregularities, v * (0.95 + 0.1 * x / x[-1]))
    ((rr, gr),) = sim.simulate_jacobian({}, [ramp], names)
    assert gr.shape == (2,) + rr.accelerations.shape and np.all(np.isfinite(gr)) and np.any(gr != 0)
