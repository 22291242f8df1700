"""The monitoring database (SQLite and PostgreSQL alike), alarms with hysteresis, trends and their forecast."""

from __future__ import annotations

import datetime as dt
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fleet_fixtures import db_url, demo_fleet, pg_server  # noqa: F401 - fixtures
from suspid.errors import ConfigError
from suspid.fleet import queries
from suspid.fleet.alarms import ELEMENT_LEVELS, AcknowledgementError, Hysteresis, acknowledge, element_margin, replay
from suspid.fleet.db import database_url, open_database
from suspid.fleet.record import VehicleKey, record_result
from suspid.fleet.trends import fit_trend
from suspid.fleet.users import add_user
from suspid.indicators.standard import IndicatorValue

DOMAIN = {"c_yaw[bogie1]": [225e3, 375e3], "c_sec_z": [15e3, 25e3]}


def result(name: str, c_yaw: float, c_sec_z: float = 20e3, *, hw: float = 10e3, trust=None) -> dict:
    """A result.json with two element groups (one named as an element group, one at kind level)."""
    return {"name": name, "run_id": name, "parameters": ["c_yaw[bogie1]", "c_sec_z"],
            "units": {"c_yaw[bogie1]": "N s/m", "c_sec_z": "N s/m"},
            "w_opt": {"c_yaw[bogie1]": c_yaw, "c_sec_z": c_sec_z},
            "interval": {"c_yaw[bogie1]": [c_yaw - hw, c_yaw + hw], "c_sec_z": [c_sec_z - 1e3, c_sec_z + 1e3]},
            "identifiable": {"c_yaw[bogie1]": True, "c_sec_z": True},
            "trustworthy": {"c_yaw[bogie1]": trust, "c_sec_z": None}}


KEY = VehicleKey("demo", "TS01", "car1")
START = dt.date(2026, 1, 1)


def _record(db, i: int, c_yaw: float, tmp_path: Path, **kwargs):
    d = START + dt.timedelta(days=30 * i)
    return record_result(db, KEY, d, result(f"r{i}", c_yaw, **kwargs), tmp_path / f"run{i}",
                         mileage_km=1000.0 * i, acceptable=DOMAIN, kind="monitor-date",
                         indicators=[IndicatorValue("en14363-instability", 2.0, "m/s^2", "ok", None, "bogie", 5.65)])


# -- the database, both backends ---------------------------------------------------------------------
def test_record_overview_history_and_idempotent_import(db_url, tmp_path):
    db = open_database(db_url)
    try:
        values = [300e3, 290e3, 250e3, 220e3, 200e3]      # c_yaw[bogie1] degrading through its lower edge
        recs = [_record(db, i, v, tmp_path) for i, v in enumerate(values)]
        assert all(r.created for r in recs)
        again = _record(db, 2, 250e3, tmp_path)               # the same run folder and config hash
        assert not again.created and again.run_id == recs[2].run_id
        assert queries.count_runs(db) == 5
        rows = {r["element_group"]: r for r in queries.overview(db)}
        assert rows["c_yaw[bogie1]"]["verdict"] == "alarm" and rows["c_yaw[bogie1]"]["trust"] == "not assessed"
        assert rows["c_sec_z"]["verdict"] == "ok"
        assert [r["element_group"] for r in queries.overview(db, group="c_yaw")] == ["c_yaw[bogie1]"]  # by kind
        assert queries.overview(db, verdict="ok")[0]["element_group"] == "c_sec_z"
        hist = [h for h in queries.history(db, "TS01") if h["element_group"] == "c_yaw[bogie1]"]
        assert [h["verdict"] for h in hist] == ["ok", "ok", "ok", "warning", "alarm"]
        assert [h["mileage_km"] for h in hist] == [0, 1000, 2000, 3000, 4000]
        assert len(queries.indicators(db, "TS01")) == 5
    finally:
        db.dispose()


def test_alarm_raised_escalated_acknowledged_and_audited(db_url, tmp_path):
    db = open_database(db_url)
    try:
        for i, v in enumerate([300e3, 230e3, 210e3]):            # ok, warning, alarm (intervals +- 10e3)
            _record(db, i, v, tmp_path)
        (alarm,) = queries.alarms(db, state="raised")
        assert (alarm["source"], alarm["level"], alarm["raised_on"]) == ("c_yaw[bogie1]", "alarm", "2026-01-31")
        add_user(db, "j.doe", "a long enough password")
        with db.session() as s:
            acknowledge(s, alarm["id"], "j.doe", "damper ordered")
        with pytest.raises(AcknowledgementError, match="no alarm with id"), db.session() as s:
            acknowledge(s, 999, "j.doe")
        (acked,) = queries.alarms(db, state="raised")
        assert acked["acked_by"] == "j.doe" and acked["ack_comment"] == "damper ordered" and acked["acked_at"]
        _record(db, 3, 240e3, tmp_path)       # interval inside again, but not 2 half-widths in: the alarm holds
        assert queries.alarms(db, state="raised")[0]["acked_by"] == "j.doe"
        _record(db, 4, 300e3, tmp_path)       # repaired: well inside, cleared
        (cleared,) = queries.alarms(db)
        assert cleared["state"] == "cleared" and cleared["cleared_on"] == "2026-05-01"
        actions = [(e["action"], e["actor"]) for e in reversed(queries.audit(db))]
        assert actions == [("raised", "suspid"), ("escalated", "suspid"), ("acknowledged", "j.doe"),
                           ("cleared", "suspid")]
    finally:
        db.dispose()


WRITER = """
import datetime as dt, sys
sys.path.insert(0, {tests!r})
from test_fleet import KEY, DOMAIN, result
from suspid.fleet.db import open_database
from suspid.fleet.record import VehicleKey, record_result
w = int(sys.argv[1])
db = open_database({url!r})
for i in range(5):
    record_result(db, VehicleKey("demo", f"TS{{w % 3}}", "car1"), dt.date(2026, 1, 1) + dt.timedelta(days=i + 7 * w),
                  result(f"w{{w}}-{{i}}", 300e3 - 20e3 * i), {tmp!r} + f"/w{{w}}/run{{i}}", acceptable=DOMAIN)
db.dispose()
"""


@pytest.mark.slow   # 8 interpreters importing suspid at once: ~15 s on an idle 2-core machine, a minute when loaded
def test_eight_concurrent_writers_lose_no_record(db_url, tmp_path):
    """8 processes record 5 runs each at once, three of them on the same trainsets: all 40 runs, 80 values."""
    open_database(db_url).dispose()       # the schema first, as a depot's server would have it
    code = WRITER.format(tests=str(Path(__file__).parent), url=db_url, tmp=str(tmp_path))
    procs = [subprocess.Popen([sys.executable, "-c", code, str(w)], stderr=subprocess.PIPE, text=True)
             for w in range(8)]
    errors = [p.communicate(timeout=120)[1] for p in procs]
    assert all(p.returncode == 0 for p in procs), errors
    db = open_database(db_url)
    try:
        assert queries.count_runs(db) == 40
        assert len(queries.history(db, "TS0")) + len(queries.history(db, "TS1")) + \
            len(queries.history(db, "TS2")) == 80
        assert {a["trainset"] for a in queries.alarms(db, state="raised")} == {"TS0", "TS1", "TS2"}
    finally:
        db.dispose()


def test_database_url_errors():
    assert database_url("fleet.sqlite").startswith("sqlite:////")
    assert database_url("postgresql://u@h:5/d").startswith("postgresql+psycopg://")
    with pytest.raises(ConfigError, match="not supported"):
        database_url("mysql://u@h/d")


def test_config_fleet_section_validated(tmp_path):
    import suspid
    from conftest import run_cli

    base = ("name: v\nsimulator: {plugin: exudyn-train, options: {solver: frequency}}\nparameters: {c_sec_z: {}}\n"
            "data: {source: experiment, track: {n_segments: 2, length_m: 800.0}}\n"
            "spectra: {f_min_hz: 0.4, f_max_hz: 20.0, n_freqs: 60}\n")
    path = tmp_path / "c.yaml"
    path.write_text(base + "fleet: {database: 'mysql://x@y/z', trainset: TS1}\n")
    with pytest.raises(ConfigError) as info:
        suspid.validate(path)
    assert info.value.key == "fleet.database" and "not supported" in str(info.value)
    path.write_text(base + "fleet: {database: f.sqlite, acceptable: {c_yaw: [1.0, 2.0]}}\n")
    with pytest.raises(ConfigError) as info:
        suspid.validate(path)
    assert info.value.key == "fleet.acceptable.c_yaw" and "not an identified parameter" in str(info.value)
    path.write_text(base + "fleet: {database: f.sqlite, trainset: 'bad name'}\n")
    res = run_cli("validate", str(path))
    assert res.returncode == 2 and "fleet.trainset" in res.stderr and res.stderr.count("\n") == 1


# -- alarms: hysteresis --------------------------------------------------------------------------------
def test_hysteresis_raises_above_and_clears_only_below_the_lower_level():
    levels = Hysteresis(warning_above=0.8, alarm_above=1.0, clear_below=0.7)
    days = [START + dt.timedelta(days=i) for i in range(8)]
    margins = [0.5, 0.85, 0.75, 1.1, 0.75, None, 0.65, 0.75]
    states = [replay(list(zip(days[:k + 1], range(k + 1), margins[:k + 1])), levels) for k in range(8)]
    seen = [None if s is None else (s.state, s.level) for s in states]
    assert seen == [None, ("raised", "warning"), ("raised", "warning"), ("raised", "alarm"), ("raised", "alarm"),
                    ("raised", "alarm"), ("cleared", "alarm"), ("cleared", "alarm")]   # 0.75 after a clear: none
    assert states[-1].raised_on == days[1] and states[-1].cleared_on == days[6]


def test_element_margin_matches_the_monitor_status():
    """m > 1: the whole interval outside (out-of-domain); -1 < m <= 1: overlapping the edge (warning)."""
    assert element_margin(14e3, 13e3, 15e3, 15e3, 25e3) == pytest.approx(1.0)
    assert element_margin(13.9e3, 12.9e3, 14.9e3, 15e3, 25e3) > ELEMENT_LEVELS.alarm_above
    assert ELEMENT_LEVELS.warning_above < element_margin(15.5e3, 14.5e3, 16.5e3, 15e3, 25e3) < 1
    assert element_margin(20e3, 19e3, 21e3, None, None) is None


# -- trends ---------------------------------------------------------------------------------------------
def test_trend_is_robust_and_its_forecast_intervals_cover_the_true_crossing():
    """A linear loss in mileage with scatter, one gross outlier and one not-trustworthy point, 100 seeds:
    Theil-Sen keeps the slope unbiased; the 90 % forecast intervals of the warning and alarm crossings
    contain the true line's crossings at least 90 % of the time, and stay finite and useful."""
    x = np.arange(8) * 10_000.0
    covered, widths, slopes = 0, [], []
    for seed in range(100):
        rng = np.random.default_rng(seed)
        y = 300e3 - 1.2 * x + rng.normal(0, 4e3, x.size)
        y[3] = 450e3                                         # a bad identification
        usable = np.ones(x.size, bool)
        y[5], usable[5] = 100e3, False                       # not trustworthy: left out
        t = fit_trend("c_yaw", x, y, np.full(x.size, 8e3), usable, acceptable_low=225e3, acceptable_high=375e3)
        assert t.n_points == 7 and t.n_excluded == 1 and t.side == "low"
        slopes.append(t.slope)
        for f in t.forecasts:
            crossing = (300e3 - f.value) / 1.2
            covered += f.x_low < crossing < f.x_high
            widths.append((f.x_high - f.x_low) / crossing)
    assert np.mean(slopes) == pytest.approx(-1.2, rel=0.02)
    assert covered >= 180, covered
    assert np.median(widths) < 1.0                           # narrower than the crossing mileage itself
    levels = {f.level: f.value for f in t.forecasts}
    assert levels == {"warning": 233e3, "alarm": 217e3}     # the edge -+ the median half-width


def test_trend_needs_three_usable_points():
    t = fit_trend("c_yaw", [0, 1, 2], [1, 2, 3], [0.1] * 3, [True, False, True], acceptable_low=0,
                  acceptable_high=10)
    assert t.slope is None and "fewer than 3" in t.note


def test_cli_indicators_recorded_into_the_configured_database(tmp_path):
    """`suspid indicators` on a numerical experiment with a fleet: section: printed, and stored as a recording run
    whose instability limit is the one of the model's 3.5 t bogie."""
    from conftest import run_cli

    path = tmp_path / "c.yaml"
    path.write_text("name: ind\nsimulator: {plugin: exudyn-train, options: {solver: frequency}}\n"
                    "parameters: {c_sec_z: {}}\n"
                    "data: {source: experiment, track: {n_segments: 2, length_m: 800.0}}\n"
                    "spectra: {f_min_hz: 0.4, f_max_hz: 20.0, n_freqs: 60}\n"
                    "fleet: {database: f.sqlite, trainset: TS9, date: 2026-02-01, mileage_km: 5000}\n")
    res = run_cli("indicators", str(path))
    assert res.returncode == 0, res.stderr
    assert "en14363-instability" in res.stdout and "recorded as run 1" in res.stdout
    db = open_database(tmp_path / "f.sqlite")
    try:
        rows = queries.indicators(db, "TS9", per_run=False)
        assert len(rows) == 6 and {r["date"] for r in rows} == {"2026-02-01"}   # 2 segments + the run, x 2
        assert [r["limit"] for r in rows if r["name"] == "en14363-instability"] == [pytest.approx(5.65)] * 3
    finally:
        db.dispose()


@pytest.mark.long   # the demo fleet: 4 trainsets x 6 dates, several minutes on 2 cores
def test_demo_fleet_shows_warning_then_alarm_and_forecasts_contain_the_true_crossings(demo_fleet):
    out = demo_fleet
    assert {c.element_group for c in out.checks} == {"c_yaw", "k_sec_z"}
    assert all(c.holds for c in out.checks), (out.out_dir / "fleet-demo.md").read_text()
