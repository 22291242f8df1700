"""The diagnosis's evidence rules, third round: a coupling estimator consistent under sensor noise, vetoes in
the units of the null, channel-level gains, one trust rule for the diagnosis's suspensions.

Fast tests: synthetic records and spectra with known answers, and the independent train's records
(``tests/independent``, no suspid code) for the coupling; the whole diagnoses are acceptance cases in
``test_diagnose_independent.py``.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from independent import effects as HE
from independent import train as TR

KMH = 1 / 3.6
CHANNELS = ["bogie_front_vertical", "bogie_front_lateral", "bogie_rear_vertical"]


def _tilted_records(rng, angle_deg: float, noise: float, n_records: int = 24, n_t: int = 1024):
    """A vertical motion s seen by the point's vertical v (with white sensor noise ``noise`` m/s²) and, delayed
    and filtered, by another vertical z (the instrument, its own noise); the tilted lateral x = cos α lat +
    sin α s + its noise."""
    a = math.radians(angle_deg)
    out = []
    for _ in range(n_records):
        s = np.convolve(rng.standard_normal(n_t + 20), np.ones(8) / 8, "same")      # low-pass vertical motion
        lat = 0.5 * np.convolve(rng.standard_normal(n_t), np.ones(3) / 3, "same")
        v = s[:n_t] + noise * rng.standard_normal(n_t)
        z = 0.8 * s[20:n_t + 20] + noise * rng.standard_normal(n_t)                 # 0.2 s further on the track
        x = math.cos(a) * lat + math.sin(a) * s[:n_t] + noise * rng.standard_normal(n_t)
        out.append(SimpleNamespace(accelerations=np.array([v, x, z]), fs=100.0))
    return out


def _ols(records) -> float:
    """The regression of x on v (what the coupling test used before): biased toward 0 by v's noise."""
    from scipy.signal import csd, welch

    num = den = 0.0
    for r in records:
        v, x = r.accelerations[0], r.accelerations[1]
        f, s_vx = csd(v, x, fs=r.fs, nperseg=256)
        _, s_vv = welch(v, fs=r.fs, nperseg=256)
        _, s_xx = welch(x, fs=r.fs, nperseg=256)
        num += float(np.sum(np.real(s_vx)[1:] / s_xx[1:]))
        den += float(np.sum(s_vv[1:] / s_xx[1:]))
    return num / den


def test_coupling_estimator_is_consistent_under_sensor_noise():
    """Known answer: sin 4° = 0.0698 under white sensor noise on every channel. The regression of x on v is
    biased toward zero (errors in variables); the instrumental-variable estimator is within 10 % in the mean
    over replicates, and its jackknife se is about the spread of the replicates."""
    from suspid.workflows.diagnose.coupling import coupling_test

    truth = math.sin(math.radians(4.0))
    rng = np.random.default_rng(11)
    est, se, ols = [], [], []
    for _ in range(12):
        recs = _tilted_records(rng, 4.0, noise=0.15)
        row = coupling_test(recs, CHANNELS, (0.4, math.inf))[0]
        est.append(row["beta"])
        se.append(row["se"])
        ols.append(_ols(recs))
    assert abs(np.mean(est) - truth) < 0.10 * truth, est
    assert np.mean(ols) < 0.6 * truth, ols                               # what the noise did to the old estimator
    assert 0.4 < np.std(est, ddof=1) / np.mean(se) < 2.5, (est, se)   # 20 replicates: 0.85
    null = coupling_test(_tilted_records(rng, 0.0, noise=0.15), CHANNELS, (0.4, math.inf))[0]
    assert not null["significant"] and abs(null["beta"]) < 3 * null["se"]


def _independent_records(case: str, seed: int, n_segments: int = 24):
    c = HE.CASES[case]
    return HE.simulate(None, c.hidden, seed=seed, n_segments=n_segments, speed_mps=c.speeds[0] * KMH,
                       instrument=TR.Instrument(noise_asd=c.noise_asd or TR.Instrument().noise_asd))


def test_shared_tilt_is_found_against_the_models_coupling_on_the_independent_train():
    """4° on both bogies' lateral sensors and on the mid-car one, 0.005 m/s² of sensor noise (the independent
    train): the twins' difference sees nothing, their couplings against the model's (0) do; the untilted
    carbody ends not taken. Estimated with the carbody ends' lateral motion removed (controls), each channel is
    within 4 % of its truth in its own calibration (sin 4° times the generator's calibration-gain ratio of its
    lateral and vertical channels) and at least 3 times more precise than without; the pooled angle within
    5 % of 4°."""
    from suspid.workflows.diagnose.coupling import coupling_test, pooled_tilt

    rows = {r["channel"]: r for r in coupling_test(_independent_records("shared-tilt", 3), TR.CHANNELS,
                                                   (0.4, math.inf))}
    gain = dict(zip(TR.CHANNELS, TR.Instrument().calibration(0)))                  # simulate's instrument_seed
    tilted = ("bogie_front_lateral", "bogie_rear_lateral", "carbody_middle_lateral")
    for c in tilted:
        r = rows[c]
        truth = math.sin(math.radians(4.0)) * gain[c] / gain[r["vertical"]]
        assert r["significant"] and r["controls"] == ["carbody_front_lateral", "carbody_rear_lateral"], r
        assert abs(r["beta"] - truth) < 0.04 * truth and r["se"] < r["se_raw"] / 3, (c, r["beta"], truth, r["se"])
    assert abs(rows["bogie_front_lateral"]["t_pair"]) < 2.0            # the shared tilt cancels in the pair
    assert not rows["carbody_front_lateral"]["significant"] and not rows["carbody_rear_lateral"]["significant"]
    pooled = pooled_tilt([rows[c] for c in tilted])
    assert abs(pooled["angle_deg"] - 4.0) < 0.2 and 0 < pooled["se_deg"] < 0.3, pooled
    assert sum(pooled["weights"].values()) == pytest.approx(1.0) and min(pooled["weights"].values()) >= 0


def _body_records(rng, angle_deg: float, noise: float, n_records: int = 24, n_t: int = 1024):
    """A rigid body's lateral motion (sway y and yaw ψ) seen by lateral sensors at its front, middle and rear
    (y + ψ, y, y - ψ), the middle one tilted by ``angle_deg`` into its vertical; the verticals see one track
    motion at three delays; white sensor noise ``noise`` on every channel. Rows in the order of BODY."""
    a = math.radians(angle_deg)
    out = []
    for _ in range(n_records):
        s = np.convolve(rng.standard_normal(n_t + 40), np.ones(8) / 8, "same")
        y, psi = (np.convolve(rng.standard_normal(n_t), np.ones(6) / 6, "same") for _ in range(2))
        vert = [s[40:], s[20:n_t + 20], s[:n_t]]
        lat = [y + psi, math.cos(a) * y + math.sin(a) * vert[1], y - psi]
        rows = [x for pair in zip(vert, lat) for x in pair]
        out.append(SimpleNamespace(accelerations=np.array(rows) + noise * rng.standard_normal((6, n_t)), fs=100.0))
    return out


BODY = ["carbody_front_vertical", "carbody_front_lateral", "carbody_middle_vertical", "carbody_middle_lateral",
        "carbody_rear_vertical", "carbody_rear_lateral"]


def test_untilted_lateral_channels_as_controls_remove_the_shared_lateral_motion():
    """Known answer: the mid sensor of a rigid body tilted by 4°, its lateral motion the mean of the untilted
    ends'. With the ends' lateral motion removed the estimate is within 3 % of sin 4° in the mean over
    replicates, its spread at least 3 times smaller than without the controls, its jackknife se about that
    spread."""
    from suspid.workflows.diagnose.coupling import coupling_test

    truth = math.sin(math.radians(4.0))
    rng = np.random.default_rng(3)
    est, raw, se = [], [], []
    for _ in range(10):
        rows = {r["channel"]: r for r in coupling_test(_body_records(rng, 4.0, noise=0.05), BODY, (0.4, math.inf))}
        mid = rows["carbody_middle_lateral"]
        assert mid["significant"] and mid["controls"] == ["carbody_front_lateral", "carbody_rear_lateral"], mid
        est.append(mid["beta"])
        raw.append(mid["beta_raw"])
        se.append(mid["se"])
    assert abs(np.mean(est) - truth) < 0.03 * truth, est
    assert np.std(est, ddof=1) < np.std(raw, ddof=1) / 3, (est, raw)                 # 3.6 here
    assert 0.4 < np.std(est, ddof=1) / np.mean(se) < 2.5, (est, se)


def test_pooled_tilt_counts_channels_that_err_together_about_once():
    """Known answers of the random-effects mean: channels that agree within their errors give their GLS mean
    (τ = 0); a twin pair whose errors are 0.98 correlated counts about once beside an independent channel;
    channels scattered far beyond their errors are weighted about equally (τ about their spread), and no
    weight is negative."""
    from suspid.workflows.diagnose.coupling import pooled_tilt

    def rows(betas, cov):
        names = [f"c{i}" for i in range(len(betas))]
        return [{"channel": n, "beta": b, "se": math.sqrt(cov[i][i]),
                 "covariance": {m: cov[i][j] for j, m in enumerate(names)}}
                for i, (n, b) in enumerate(zip(names, betas))]

    sd = 0.002
    same = pooled_tilt(rows([0.0698, 0.0698, 0.0698], np.diag([sd ** 2] * 3)))
    assert same["tau"] == 0.0 and same["angle_deg"] == pytest.approx(4.0, abs=0.01)
    assert same["se_deg"] == pytest.approx(math.degrees(sd / math.sqrt(3)), rel=0.01)
    pair = np.array([[1, 0.98, 0], [0.98, 1, 0], [0, 0, 1]]) * sd ** 2
    w = pooled_tilt(rows([0.070, 0.0701, 0.0699], pair))["weights"]
    assert w["c2"] == pytest.approx(0.5, abs=0.02) and w["c0"] + w["c1"] == pytest.approx(0.5, abs=0.02)
    uneven = np.array([[1, 0.98 * 2, 0], [0.98 * 2, 4, 0], [0, 0, 1]]) * sd ** 2     # the GLS would go negative
    w = pooled_tilt(rows([0.070, 0.071, 0.070], uneven))["weights"]
    assert min(w.values()) >= 0 and sum(w.values()) == pytest.approx(1.0)
    spread = pooled_tilt(rows([0.060, 0.070, 0.080], np.diag([1e-4, 1e-3, 1e-3]) * sd ** 2))
    assert spread["tau"] == pytest.approx(0.01, rel=0.3) and max(spread["weights"].values()) < 0.4
    assert spread["angle_deg"] == pytest.approx(4.0, abs=0.05)


def test_lateral_bracket_resonance_is_no_tilt_on_either_channel_of_the_pair():
    """A bracket resonance (14 Hz) on one carbody lateral sensor: neither that channel nor its untouched twin is
    taken for a tilted sensor."""
    from suspid.workflows.diagnose.coupling import coupling_test

    rows = coupling_test(_independent_records("bracket-lateral", 3), TR.CHANNELS, (0.4, math.inf))
    assert not any(r["significant"] for r in rows), [(r["channel"], r["t"], r["note"]) for r in rows]


def test_constancy_rejects_a_coupling_that_changes_with_frequency():
    """A coupling of 0.1 below 10 Hz and -0.1 above (a resonance, not a tilt): not constant, never a tilt."""
    from scipy.signal import butter, sosfiltfilt

    from suspid.workflows.diagnose.coupling import coupling_test

    rng = np.random.default_rng(5)
    lo, hi = butter(4, 10.0, fs=100.0, output="sos"), butter(4, 10.0, "high", fs=100.0, output="sos")
    recs = []
    for _ in range(24):
        s = rng.standard_normal(1044)
        v, z = s[:1024] + 0.05 * rng.standard_normal(1024), s[20:] + 0.05 * rng.standard_normal(1024)
        x = 0.3 * rng.standard_normal(1024) + 0.1 * sosfiltfilt(lo, s[:1024]) - 0.1 * sosfiltfilt(hi, s[:1024])
        recs.append(SimpleNamespace(accelerations=np.array([v, x, z]), fs=100.0))
    row = coupling_test(recs, CHANNELS, (0.4, math.inf))[0]
    assert not row["constant"] and not row["significant"], row


# ------------------------------------------------------------------------------------------ vetoes
def _candidate(by_channel, null_sd):
    from suspid.workflows.diagnose.fit import Candidate

    c = Candidate("wheel-polygon", "fitted", 4, {}, score=1000.0)
    c.evidence = {"explained_own": 0.9, "channels_changed": list(by_channel), "delta_D_by_channel": by_channel,
                  "null_sd_D_by_channel": null_sd}
    return c


def test_a_small_side_effect_within_the_null_does_not_veto_a_large_improvement():
    """The polygon of the issue: D down by 1019 on the bogie channel, up by 23 on a carbody channel whose D has a
    null sd of 30: no veto (the absolute margin of 10 vetoed it); up by 200 on it: vetoed."""
    from suspid.sections import DiagnoseOptions
    from suspid.workflows.diagnose.name import _rejection

    opts = DiagnoseOptions()
    sd = {"bogie_front_vertical": 40.0, "carbody_front_vertical": 30.0}
    ok = _rejection(_candidate({"bogie_front_vertical": 1019.0, "carbody_front_vertical": -23.0}, sd), None, None,
                    10, opts)
    assert ok is None
    bad = _rejection(_candidate({"bogie_front_vertical": 1019.0, "carbody_front_vertical": -200.0}, sd), None,
                     None, 10, opts)
    assert bad is not None and "null sd" in bad


def test_channel_null_sd_of_D_follows_the_correlation_of_the_bins():
    """Under the noise model, D of a channel (its whitened squared residuals) has sd sqrt(2 tr R²): simulated."""
    from suspid.method.noise import NoiseModel
    from suspid.workflows.diagnose.name import channel_correlation, channel_null_sd

    rng = np.random.default_rng(3)
    f = np.linspace(0.5, 30.0, 60)
    x = np.log2(f)
    L = np.linalg.cholesky(np.exp(-0.5 * ((x[:, None] - x[None]) / 0.5) ** 2) + 0.3 * np.eye(f.size))
    b = np.einsum("fg,vkg->vkf", L, rng.standard_normal((48, 2, f.size)))
    nm = NoiseModel().fit(b, freqs=f, channels=["a", "b"])
    R = channel_correlation(nm, 0)
    e = rng.multivariate_normal(np.zeros(f.size), R, size=4000)
    D = (e ** 2).sum(axis=1)
    assert channel_null_sd(nm, 1)[0] == pytest.approx(D.std(), rel=0.1)
    assert channel_null_sd(nm, 1)[0] > 2 * math.sqrt(2 * f.size)       # far from independent bins


def test_after_map_check_allows_a_cell_coming_and_going_elsewhere():
    """Own cells cleared (4 → 0), total 2 → 3 from one new cell elsewhere: not retracted; own cells kept: is."""
    from suspid.sections import DiagnoseOptions
    from suspid.workflows.diagnose.name import check_after_joint_fit

    def dmap(flags):
        m = np.zeros(12, bool)
        m[list(flags)] = True
        return SimpleNamespace(flagged=m)

    own = np.zeros(12, bool)
    own[:4] = True
    opts = DiagnoseOptions()
    assert check_after_joint_fit(dmap([0, 1]), dmap([8, 9, 10]), own, opts) is None
    assert check_after_joint_fit(dmap([0, 1]), dmap([0, 1, 9]), own, opts) is not None


# ------------------------------------------------------------------------------------------ gains and trust
def test_channel_gain_below_min_db_per_cell_is_found_over_the_channel():
    """+8 % (0.33 dB) on one channel, under a min_db of 0.5 dB per cell: no cell flagged for it, the channel-level
    test finds it with its gain; a resonance on another channel lifts its mean too but is not flat: no gain."""
    from suspid.method.noise import NoiseModel
    from suspid.workflows.diagnose import calibrate_null, locate, make_cells
    from suspid.workflows.diagnose.name import channel_gains

    rng = np.random.default_rng(4)
    f = np.linspace(0.5, 30.0, 60)
    x = np.log2(f)
    L = np.linalg.cholesky(np.exp(-0.5 * ((x[:, None] - x[None]) / 0.5) ** 2) + 0.3 * np.eye(f.size))
    nm = NoiseModel().fit(0.5 * np.einsum("fg,vkg->vkf", L, rng.standard_normal((48, 3, f.size))),
                          freqs=f, channels=["a", "b", "c"])
    grid = make_cells(nm.channels_, f, [80.0] * 40)
    null = calibrate_null(grid, nm, 100, np.random.default_rng(2))
    y_sim = rng.normal(size=(40, 3, f.size))
    y_mes = y_sim + nm.sample(40, np.random.default_rng(7)) + nm.mean_
    y_mes[:, 1] += 10 * math.log10(1.08)              # Y = 5 log10 of the power: 10 log10 of the gain
    y_mes[:, 0] += 4.0 * np.exp(-0.5 * (np.log2(f / 14.0) / 0.2) ** 2)     # a resonance lifts a's mean: no gain
    dmap = locate(grid, null, y_mes, y_sim, nm.mean_, min_db=0.5)
    gains = {g["channel"]: g for g in channel_gains(dmap, nm, 0.05)}
    b = gains["b"]
    assert b["significant"] and abs(b["mean_db"] - 10 * math.log10(1.08)) < 3 * b["sd_db"], b
    assert b["gain"] == pytest.approx(10 ** (b["mean_db"] / 10), abs=1e-3)
    assert not gains["a"]["significant"] and not gains["a"]["flat"] and abs(gains["a"]["z"]) > 3
    assert not gains["c"]["significant"]
    assert not dmap.flagged.reshape(1, 3, -1)[0, 1].any()


def test_suspension_trust_is_not_assessed_without_the_identifications_checks():
    """The diagnosis's suspension: a component the data-group check flags is not trustworthy; the others are
    not assessed (the self-check and adequacy do not run on the diagnosis's models), never yes."""
    from suspid.workflows.diagnose.workflow import suspension_trust

    t = suspension_trust(["k1", "k2"], {"k1": True, "k2": False}, groups_ran=True)
    assert t["trustworthy"] == {"k1": None, "k2": False}
    assert "k1" in t["not_assessed"] and "k2" in t["reasons"]


# ------------------------------------------------------------------------------------------ extension
def test_a_tilt_corrected_in_the_records_extends_to_other_channels_never_twice_on_one():
    """After the coupling route corrected bogie_front_lateral in the records, the model's sensor-tilt may still
    be fitted on the other flagged lateral channel, and no starting point names the corrected one; the
    corrected entry never goes into the model."""
    from suspid.errors import ConfigError
    from suspid.plugins.effects.catalogue import SensorTilt
    from suspid.sections import DiagnoseOptions
    from suspid.workflows.diagnose.fit import EffectFitter
    from suspid.workflows.diagnose.workflow import CORRECTED, _model_effects

    channels = ["bogie_front_vertical", "bogie_front_lateral", "bogie_rear_vertical", "bogie_rear_lateral"]
    f = np.linspace(0.5, 40.0, 50)
    flat = np.zeros((1, 4, f.size))
    disc = SimpleNamespace(spectra=lambda: {"freqs": f, "channels": channels, "measured": flat, "model": flat})
    problem = SimpleNamespace(simulator=object(), segments=[SimpleNamespace(mean_speed=83.3)], channels=channels)
    config = SimpleNamespace(source_file="c.yaml")
    flagged = [("bogie_front_lateral", 10.0, 12.0, 83.3), ("bogie_rear_lateral", 10.0, 12.0, 83.3)]
    tried = []

    def refuse(spec):
        tried.append(list(spec["channels"]))
        raise ConfigError("not simulated here")

    fitter = EffectFitter(config, problem, {}, disc, flagged, DiagnoseOptions(), blocked={"sensor-tilt":
                                                                                        {"bogie_front_lateral"}})
    fitter.simulator_with = refuse
    fitter.fit(SensorTilt)
    assert tried and all(t == ["bogie_rear_lateral"] for t in tried), tried
    only_corrected = EffectFitter(config, problem, {}, disc, flagged[:1], DiagnoseOptions(),
                                  blocked={"sensor-tilt": {"bogie_front_lateral"}}).fit(SensorTilt)
    assert only_corrected.status.startswith("no starting point") and "bogie_front_lateral" in only_corrected.status
    named = [("sensor-tilt", {"angle_deg": 4.0, "channels": ["bogie_front_lateral"], "applied": CORRECTED}, 2),
             ("sensor-tilt", {"angle_deg": 3.0, "channels": ["bogie_rear_lateral"]}, 2)]
    assert _model_effects(named, {}) == [named[1][:2]]


def test_reidentification_without_a_trust_verdict_is_not_assessed():
    """A re-identification whose run judged no component: each is not assessed (None) with a reason, not yes."""
    from suspid.workflows.diagnose.reidentify import Stage

    stage = Stage("after-1", None, SimpleNamespace(), {}, np.zeros(1), {"w_opt": {"k1": 1.0, "k2": 2.0},
                                                                        "trustworthy": {"k2": False}})
    ident = stage.gap()["identified"]
    assert ident["trustworthy"] == {"k1": None, "k2": False} and list(ident["not_assessed"]) == ["k1"]


def test_a_correction_in_the_records_obeys_the_naming_rule_per_channel():
    """The coupling route's rule on each corrected channel: its flagged cells shrink (when it has any), no new
    ones beyond the allowance; a channel with none flagged that stays clean passes (a tilt the power map cannot
    see)."""
    from suspid.workflows.diagnose import make_cells
    from suspid.workflows.diagnose.workflow import correction_evidence

    grid = make_cells(["a_lateral", "b_lateral"], np.linspace(0.5, 30.0, 60), [80.0] * 4)
    B = grid.band_edges.shape[0]
    before, after = np.zeros(grid.n_cells, bool), np.zeros(grid.n_cells, bool)
    before[[0, 1, 2]] = True                                  # three cells of a_lateral flagged
    after[[0, 1, 2]] = True                                   # the correction leaves them: not what made them
    ev, why = correction_evidence(grid, "a_lateral", before, after, 0.1)
    assert ev == {"flagged_before": 3, "flagged_after": 3, "new_flagged": 0} and "does not shrink" in why
    after[:] = False
    after[0] = True
    assert correction_evidence(grid, "a_lateral", before, after, 0.1)[1] is None
    after[[B, B + 1]] = True                                  # two new cells on b_lateral
    assert "new cells" in correction_evidence(grid, "b_lateral", before, after, 0.1)[1]
    assert correction_evidence(grid, "b_lateral", before, np.zeros(grid.n_cells, bool), 0.1)[1] is None


def test_a_level_both_twins_share_is_not_a_channel_gain():
    """-0.6 dB on both bogie verticals (a level the model misses at a compromised suspension): each differs from the model
    but not from its twin, no gain; +8 % on one of them only: a gain there."""
    from suspid.method.noise import NoiseModel
    from suspid.workflows.diagnose import calibrate_null, locate, make_cells
    from suspid.workflows.diagnose.name import channel_gains

    rng = np.random.default_rng(6)
    f = np.linspace(0.5, 30.0, 60)
    x = np.log2(f)
    L = np.linalg.cholesky(np.exp(-0.5 * ((x[:, None] - x[None]) / 0.5) ** 2) + 0.3 * np.eye(f.size))
    names = ["bogie_front_vertical", "bogie_rear_vertical", "carbody_middle_vertical"]
    nm = NoiseModel().fit(0.3 * np.einsum("fg,vkg->vkf", L, rng.standard_normal((48, 3, f.size))),
                          freqs=f, channels=names)
    grid = make_cells(names, f, [80.0] * 40)
    null = calibrate_null(grid, nm, 100, np.random.default_rng(2))
    y_sim = rng.normal(size=(40, 3, f.size))
    y_mes = y_sim + nm.sample(40, np.random.default_rng(7)) + nm.mean_
    both = y_mes.copy()
    both[:, :2] -= 0.6
    gains = {g["channel"]: g for g in channel_gains(locate(grid, null, both, y_sim, nm.mean_), nm, 0.05)}
    assert abs(gains["bogie_front_vertical"]["z"]) > 4 and gains["bogie_front_vertical"]["twin"] == "bogie_rear_vertical"
    assert not any(g["significant"] for g in gains.values()), gains
    one = y_mes.copy()
    one[:, 0] += 10 * math.log10(1.08)
    gains = {g["channel"]: g for g in channel_gains(locate(grid, null, one, y_sim, nm.mean_), nm, 0.05)}
    assert gains["bogie_front_vertical"]["significant"] and not gains["bogie_rear_vertical"]["significant"], gains
