"""The depot's overview (rows, states, counts, next crossings), the numbers as the dashboard writes them, forecasts
that mean something, the trend figure and Figure 2, and the database migration that added users and
acknowledgements. Known answers from the recorded fleet of ``dashboard_fixtures`` (SQLite) and from lines whose
crossings are computed by hand."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest

from dashboard_fixtures import TODAY, build_fleet
from suspid.dashboard import present
from suspid.fleet import board, queries
from suspid.fleet.db import open_database
from suspid.fleet.trends import Calendar, dates_from_mileage, fit_trend


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    root = tmp_path_factory.mktemp("board")
    url = f"sqlite:///{root / 'fleet.sqlite'}"
    ids = build_fleet(url, root)
    db = open_database(url)
    yield {"db": db, "root": root, **ids}
    db.dispose()


def test_overview_rows_are_sorted_by_urgency_and_counted(fleet):
    b = board.board(fleet["db"], today=TODAY)
    order = [(r["trainset"], r["source"], r["state"]) for r in b["rows"]]
    assert order == [("TS01", "c_yaw[bogie1]", "alarm"), ("TS01", "en14363-instability", "warning"),
                     ("TS02", "k_sec_z", "not assessable"), ("TS01", "c_sec_z", "ok"),
                     ("TS01", "en12299-comfort", "ok"), ("TS02", "c_yaw[bogie1]", "ok")]
    assert b["counts"] == {"alarm": 1, "warning": 1, "not assessable": 1, "ok": 3}
    assert [r["source"] for r in board.board(fleet["db"], today=TODAY, state="ok", trainset="TS01")["rows"]] == \
        ["c_sec_z", "en12299-comfort"]
    assert [r["source"] for r in board.board(fleet["db"], today=TODAY, group="c_yaw")["rows"]] == \
        ["c_yaw[bogie1]", "c_yaw[bogie1]"]                                  # by kind


def test_an_element_row_says_value_nominal_date_mileage_age_crossing_and_alarm(fleet):
    row = next(r for r in board.board(fleet["db"], today=TODAY)["rows"] if r["source"] == "c_yaw[bogie1]")
    assert row["label"] == "bogie 1: yaw damper rate per damper" and row["location"] == "bogie 1"
    assert row["percent"] == pytest.approx(200 / 3) and row["percent_low"] == pytest.approx(190 / 3)
    assert (row["date"], row["mileage_km"], row["age_days"]) == ("2026-05-01", 208_000.0, 214)
    assert row["next"]["kind"] == "crossed" and row["next"]["text"] == "alarm level crossed on 2026-05-01"
    assert row["alarm"]["state"] == "raised" and row["alarm"]["level"] == "alarm"
    assert row["alarm"]["raised_on"] == "2026-04-01"
    v = present.row_value(row)
    assert v == {"head": "66.7 % of nominal", "interval": "[63.3 %, 70.0 %]",
                 "detail": "200 kN s/m [190, 210] kN s/m"}
    assert row["trust"] == "not assessed" and row["trust_reason"] == "reference-date self-check not run"


def test_flat_trend_has_no_forecast_and_every_not_assessable_has_its_reason(fleet):
    rows = {(r["trainset"], r["source"]): r for r in board.board(fleet["db"], today=TODAY)["rows"]}
    flat = rows[("TS01", "c_sec_z")]
    assert flat["next"]["kind"] == "no trend" and flat["next"]["date"] is None
    assert flat["next"]["text"].startswith("no trend")
    lost = rows[("TS02", "k_sec_z")]
    assert lost["reason"] == "not identifiable: flat direction: the interval spans 100 % of the admissible one"
    assert all(r["reason"] for r in rows.values() if r["verdict"] == "not assessable")
    instability = rows[("TS01", "en14363-instability")]
    assert present.row_value(instability) == {"head": "84 % of the limit", "interval": "",
                                              "detail": "4.75 m/s², limit 5.65 m/s²"}
    assert instability["alarm"]["level"] == "warning" and instability["alarm"]["raised_on"] == "2026-04-01"
    cleared = rows[("TS02", "c_yaw[bogie1]")]
    assert cleared["state"] == "ok" and cleared["alarm"]["state"] == "cleared"


def test_comfort_alarm_uses_the_en12299_levels():
    from suspid.fleet.alarms import COMFORT_LEVELS, indicator_levels, indicator_margin, replay

    days = [dt.date(2026, 1, 1) + dt.timedelta(days=i) for i in range(4)]
    margins = [indicator_margin(v, None, "en12299-comfort") for v in (1.5, 2.3, 4.2, 1.7)]
    assert indicator_levels("en12299-comfort") is COMFORT_LEVELS
    states = [replay(list(zip(days[:k + 1], range(k + 1), margins[:k + 1])), COMFORT_LEVELS) for k in range(4)]
    assert [None if s is None else (s.state, s.level) for s in states] == \
        [None, ("raised", "warning"), ("raised", "alarm"), ("cleared", "alarm")]


# -- forecasts with meaning -----------------------------------------------------------------------------
def _line(slope: float, noise: float = 0.0, n: int = 6, seed: int = 0):
    rng = np.random.default_rng(seed)
    x = 100_000.0 + 27_000.0 * np.arange(n)
    y = 300e3 + slope * (x - x[0]) + rng.normal(0, noise, n)
    return x, y


def test_no_crossing_is_forecast_when_the_slope_interval_contains_zero():
    """The faulty-sensor case of issue 47: scatter without a trend once gave crossings in 2028 ... 2134."""
    x, y = _line(0.0, noise=25e3, seed=3)
    t = fit_trend("k_sec_z", x, y, np.full(x.size, 30e3), np.ones(x.size, bool), acceptable_low=262.5e3,
                  acceptable_high=437.5e3)
    assert t.slope_low <= 0 <= t.slope_high and not t.significant
    assert t.forecasts and all(f.x is None and f.x_low is None and f.x_high is None for f in t.forecasts)
    nxt = board.next_crossing(t, Calendar.of("mileage_km", [dt.date(2026, 1, 1)], [1.0]), TODAY)
    assert nxt["kind"] == "no trend" and nxt["date"] is None


def test_a_forecast_in_the_past_is_labelled_so_and_a_future_one_has_its_interval():
    x, y = _line(-1.0)                                           # -1 N s/m per km: warning (233 kN s/m) at +67 000 km
    dates = [dt.date(2026, 1, 1) + dt.timedelta(days=30 * i) for i in range(x.size)]
    t = fit_trend("c_yaw", x, y, np.full(x.size, 8e3), np.ones(x.size, bool), acceptable_low=225e3,
                  acceptable_high=375e3)
    calendar = dates_from_mileage(t, dates, list(x))
    assert calendar.rate == pytest.approx(900.0) and t.significant
    warning = t.forecasts[0]
    assert warning.crossed and warning.crossed_on == dates[3]   # 300e3 - 81 000 < 233e3 first at the 4th date
    alarm = t.forecasts[1]                                      # 217e3: 83 000 km after the first date
    assert alarm.x == pytest.approx(183_000.0) and alarm.crossed and alarm.crossed_on == dates[4]
    t2 = fit_trend("c_yaw", x[:3], y[:3], np.full(3, 8e3), np.ones(3, bool), acceptable_low=225e3,
                   acceptable_high=375e3)
    dates_from_mileage(t2, dates[:3], list(x[:3]))
    early = board.next_crossing(t2, calendar, dt.date(2026, 2, 1))
    assert early["kind"] == "forecast" and early["level"] == "warning"
    assert early["date"] == (dt.date(2026, 1, 1) + dt.timedelta(days=67_000 / 900)).isoformat()
    assert early["text"].startswith(f"warning level about {early['date']} (90 %: ")
    late = board.next_crossing(t2, calendar, dt.date(2026, 12, 1))
    assert late["kind"] == "past forecast" and "before today; not measured since" in late["text"]


# -- numbers as people read them -----------------------------------------------------------------------------
@pytest.mark.parametrize("value,unit,text", [
    (118_500.0, "N s/m", "118.5 kN s/m"), (1_185_000.0, "N/m", "1.185 MN/m"), (350e3, "N/m", "350 kN/m"),
    (4.7519, "m/s^2", "4.752 m/s²"), (1.3487, "-", "1.349"), (0.000123, "m", "0.000123 m"), (0.0, "N/m", "0 N/m"),
])
def test_engineering_units_without_scientific_notation(value, unit, text):
    assert present.quantity(value, unit) == text
    assert "e+" not in present.quantity(value, unit) and "e-" not in present.quantity(value, unit)


def test_mileage_age_and_slope_words():
    assert present.mileage(1_134_737.4) == "1\u202f134\u202f737 km" and present.mileage(None) == "mileage not recorded"
    assert (present.age(0), present.age(1), present.age(170)) == ("today", "1 day ago", "170 days ago")
    x, y = _line(-1.3)
    t = fit_trend("c_yaw", x, y, np.full(x.size, 8e3), np.ones(x.size, bool), acceptable_low=225e3,
                  acceptable_high=375e3)
    assert present.slope(t, "N s/m").startswith("-1.3 kN s/m per 1 000 km (90 % interval -1.3 to -1.3)")


# -- the figures ----------------------------------------------------------------------------------------------
def _figure_of(png: bytes):
    import matplotlib.image as mpimg
    import io

    return mpimg.imread(io.BytesIO(png))


def test_trend_figure_names_every_line_bounds_its_axes_and_marks_today(fleet, monkeypatch):
    from matplotlib.figure import Figure

    from suspid.dashboard import figures

    made: list[Figure] = []
    real = figures.Figure
    monkeypatch.setattr(figures, "Figure", lambda *a, **k: made.append(real(*a, **k)) or made[-1])
    info, trend = next((i, t) for i, t in queries.trends(fleet["db"], "TS01") if i["element_group"] == "c_sec_z")
    png = figures.trend_figure(info, trend, today=dt.date(2026, 4, 15), label="secondary vertical damper")
    pixels = _figure_of(png)
    assert pixels.shape[1] >= 1100 and pixels.shape[0] >= 480              # large enough to read
    ax = made[0].axes[0]
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "acceptable domain (edges)" in legend and "today (2026-04-15)" in legend
    assert any(t.startswith("fitted line (Theil-Sen): no trend") for t in legend)
    assert "warning level (16 kN s/m)" in legend and "alarm level (14 kN s/m)" in legend
    drawn = [ln for ln in ax.get_lines() if len(ln.get_xdata())]
    assert len(ax.get_legend().legend_handles) >= len({ln.get_linestyle() + str(ln.get_color()) for ln in drawn})
    lo, hi = ax.get_xlim()
    assert lo >= 100_000 - 0.05 * 108_000 and hi <= 208_000 + 0.05 * 108_000  # the data, no far forecast
    assert ax.get_ylabel() == "secondary vertical damper (kN s/m)"
    info, trend = next((i, t) for i, t in queries.trends(fleet["db"], "TS01") if i["element_group"] != "c_sec_z")
    figures.trend_figure(info, trend, today=TODAY)
    legend = [t.get_text() for t in made[1].axes[0].get_legend().get_texts()]
    assert "alarm level crossed (measured on 2026-05-01)" in legend
    assert any(t.startswith("today (2026-12-01, about ") and t.endswith("right of the plot") for t in legend)


@pytest.mark.parametrize("n", [1, 2, 3, 6])
def test_figure_2_title_is_not_clipped(tmp_path, monkeypatch, n):
    from suspid.infra import files
    from suspid.workflows import report
    from suspid.workflows.verdict import VerdictRow

    made = {}
    real = files.save_figure
    monkeypatch.setattr(report, "save_figure", lambda fig, path, **k: made.setdefault("fig", fig) and real(fig, path))
    rows = [VerdictRow(name=f"p{i}", label="a parameter", unit="N/m", nominal=1e5, value=9e4, interval=(8e4, 1e5),
                       change_percent=-10.0, interval_percent=(-20.0, 0.0), identifiable=True, trust="yes",
                       warning=None, alarm=None, verdict="ok", rule="") for i in range(n)]
    report.figure_verdict(tmp_path / "f2.png", rows)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = made["fig"]
    canvas = FigureCanvasAgg(fig)                              # the figure as saved (closed, so a canvas anew)
    canvas.draw()
    box = fig.axes[0].title.get_window_extent(canvas.get_renderer())
    width = fig.get_figwidth() * fig.dpi
    assert box.x0 >= 0 and box.x1 <= width, (box.x0, box.x1, width)


# -- the migration ---------------------------------------------------------------------------------------------
def test_migration_0002_keeps_an_old_acknowledgement_as_the_first_row(tmp_path):
    """A database of revision 0001 with an alarm acknowledged the old way (on the alarm itself) is upgraded:
    the acknowledgement becomes a row of ``acknowledgements``, the element values gain their new columns."""
    from sqlalchemy import create_engine, text

    from suspid.fleet.db import migrate

    path = tmp_path / "old.sqlite"
    engine = create_engine(f"sqlite:///{path}")
    migrate(engine, "0001")
    with engine.begin() as c:
        c.execute(text("INSERT INTO alarms (id, fleet, trainset, vehicle, source, state, level, raised_on, "
                       "acked_by, acked_at, ack_comment) VALUES (1, 'demo', 'TS01', 'car1', 'c_yaw', 'raised', "
                       "'alarm', '2026-03-01', 'old.user', '2026-03-02 10:00:00.123456', 'seen')"))
    engine.dispose()
    db = open_database(path)
    try:
        (ack,) = queries.acknowledgements(db)
        assert (ack["user"], ack["comment"], ack["raised_on"], ack["level"]) == ("old.user", "seen", "2026-03-01",
                                                                              "alarm")
        assert ack["at"] == "2026-03-02 10:00:00"                           # shown without microseconds
        assert queries.history(db, "TS01") == []
    finally:
        db.dispose()
