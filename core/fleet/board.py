"""The depot's overview (the dashboard's first page): one row per trainset, vehicle and element group or
standard indicator, with what a maintenance engineer asks first.

Each row has the latest value with its interval (in % of the nominal value for an element, of the limit for
the EN 14363 instability), the date, mileage and age of that measurement, the verdict and the trust with the
reason behind a "not assessable", the alarm (raised or cleared, level, acknowledged by whom) and the next
level crossing of the trend (:mod:`suspid.fleet.trends`): "alarm level crossed on ...", the forecast date
with its interval, "no trend" when the slope's interval contains 0. The row's **state** is the more urgent of
its latest verdict and its raised alarm's level (an alarm stays raised under hysteresis while a value hovers);
rows are sorted by state (alarm, warning, not assessable, ok), then by the soonest crossing. Every value is a
plain JSON-able type, so ``/export.json?what=board`` hands the same rows to a maintenance system.
"""

from __future__ import annotations

import datetime as dt
import re
from collections import Counter
from typing import Any

from suspid.fleet import queries
from suspid.fleet.db import Database
from suspid.fleet.trends import Trend
from suspid.indicators.standard import COMFORT, COMFORT_ALARM, COMFORT_WARNING, INSTABILITY

STATES = ("alarm", "warning", "not assessable", "ok")
"""A row's state, most urgent first."""
_RANK = {s: i for i, s in enumerate(STATES)}
INDICATOR_LABELS = {INSTABILITY: "EN 14363 bogie lateral instability (sliding rms)",
                    COMFORT: "EN 12299 mean ride comfort N_MV"}


def location(name: str) -> str:
    """Where the element group sits, in words: ``c_yaw[bogie1,left]`` -> ``bogie 1, left``; a kind-level name
    is every element of its kind."""
    if "[" not in name:
        return "all bogies and sides"
    inner = name.split("[", 1)[1].rstrip("]")
    return ", ".join(re.sub(r"(?<=[A-Za-z])(?=\d)", " ", part.strip()) for part in inner.split(","))


def state_of(verdict: str, alarm: dict[str, Any] | None) -> str:
    """The more urgent of the latest verdict and the raised alarm's level."""
    states = [verdict if verdict in _RANK else "not assessable"]
    if alarm is not None and alarm["state"] == "raised":
        states.append(alarm["level"])
    return min(states, key=_RANK.__getitem__)


def element_reason(p: dict[str, Any]) -> str | None:
    """Why a history point's verdict is "not assessable": the recorded reason, else what its fields say."""
    if p["verdict"] != "not assessable":
        return None
    if p.get("reason"):
        return p["reason"]
    if not p["identifiable"]:
        return "not identifiable (the run recorded no reason)"
    if p["trust"] == "no":
        return "not trustworthy under model error (the run recorded no reason)"
    if p["acceptable_low"] is None and p["acceptable_high"] is None:
        return "no acceptable domain given for it (monitor.acceptable)"
    return "not assessable (the run recorded no reason)"


def next_crossing(trend: Trend, calendar: Any, today: dt.date) -> dict[str, Any]:
    """The next level crossing of a trend, as a row shows it: ``kind`` (crossed, forecast, past forecast,
    beyond horizon, no trend, none), ``level``, ``date`` (ISO), its interval and a ``text`` in words."""
    out: dict[str, Any] = {"kind": "none", "level": None, "date": None, "date_low": None, "date_high": None,
                           "x": None, "text": ""}
    if trend.slope is None:
        return out | {"text": f"no trend yet ({trend.n_points} usable points, 3 needed)"}
    crossed = [f for f in trend.forecasts if f.crossed]
    if crossed:
        f = crossed[-1]                                   # the alarm level when both are past
        on = f.crossed_on.isoformat() if f.crossed_on else None
        return out | {"kind": "crossed", "level": f.level, "date": on, "x": f.crossed_x,
                      "text": f"{f.level} level crossed on {on}" if on else f"{f.level} level crossed"}
    if not trend.significant:
        return out | {"kind": "no trend", "text": "no trend (the slope's 90 % interval contains 0): no forecast"}
    ahead = [f for f in trend.forecasts if not f.crossed]
    if not ahead:
        return out | {"text": trend.note or "no acceptable domain: no forecast"}
    f = ahead[0]
    horizon = trend.horizon
    base = out | {"level": f.level, "x": f.x, "date": _iso(f.date), "date_low": _iso(f.date_low),
                  "date_high": _iso(f.date_high)}
    if f.x is None or (horizon is not None and f.x > horizon):
        after = calendar.to_date(horizon) if calendar is not None and horizon is not None else None
        return base | {"kind": "beyond horizon", "date": None,
                       "text": f"{f.level} level: no crossing within the horizon" +
                               (f" (until {after.isoformat()})" if after else "")}
    interval = (f"90 %: {_iso(f.date_low) or '?'} to "
                f"{_iso(f.date_high) or 'beyond the horizon'}") if f.date else ""
    if f.date is None:
        unit = "km" if trend.abscissa == "mileage_km" else "days"
        return base | {"kind": "forecast", "text": f"{f.level} level at about {f.x:,.0f} {unit}".replace(",", " ")}
    if f.date < today:
        return base | {"kind": "past forecast",
                       "text": f"{f.level} level: forecast to have been crossed on {f.date.isoformat()}, before "
                               f"today; not measured since ({interval})"}
    return base | {"kind": "forecast", "text": f"{f.level} level about {f.date.isoformat()} ({interval})"}


def _iso(d: dt.date | None) -> str | None:
    return None if d is None else d.isoformat()


def _alarm(a: dict[str, Any] | None) -> dict[str, Any] | None:
    if a is None:
        return None
    return {"id": a["id"], "state": a["state"], "level": a["level"], "raised_on": a["raised_on"],
            "cleared_on": a["cleared_on"], "acknowledged_by": a["acked_by"], "acknowledged_at": a["acked_at"]}


def _age(date: str, today: dt.date) -> int:
    return (today - dt.date.fromisoformat(date)).days


def board(db: Database, *, today: dt.date | None = None, fleet: str | None = None, trainset: str | None = None,
          group: str | None = None, state: str | None = None) -> dict[str, Any]:
    """The overview's rows (module docstring) and their counts by state.

    :param today: the date ages and past forecasts are judged against (default: today).
    :param group: keep an element group, its kind (``c_yaw`` keeps ``c_yaw[bogie1]``) or an indicator name.
    :param state: keep the rows in this state (one of :data:`STATES`).
    :returns: ``{"rows": [...], "counts": {state: n}, "today": ISO date}`` (counts of the kept rows).
    """
    today = today or dt.date.today()
    alarms = {(a["fleet"], a["trainset"], a["vehicle"], a["source"]): a for a in queries.alarms(db)}
    rows = []
    for info, trend in queries.trends_of(queries.history(db, trainset, fleet=fleet)):
        p = info["points"][-1]
        key = (info["fleet"], info["trainset"], info["vehicle"], info["element_group"])
        alarm = alarms.get(key)
        nominal = p.get("nominal")
        pc = (lambda v: None if not nominal else 100.0 * v / nominal)  # noqa: E731
        rows.append({
            "what": "element", "fleet": key[0], "trainset": key[1], "vehicle": key[2], "source": key[3],
            "kind": p.get("kind") or key[3].split("[", 1)[0], "label": p.get("label") or key[3].split("[", 1)[0],
            "location": location(key[3]), "value": p["value"], "unit": p["unit"], "nominal": nominal,
            "interval_low": p["interval_low"], "interval_high": p["interval_high"], "limit": None,
            "percent": pc(p["value"]), "percent_low": pc(p["interval_low"]), "percent_high": pc(p["interval_high"]),
            "percent_of": "nominal" if nominal else None,
            "verdict": p["verdict"], "trust": p["trust"], "trust_reason": p.get("trust_reason"),
            "reason": element_reason(p), "date": p["date"], "mileage_km": p["mileage_km"],
            "age_days": _age(p["date"], today), "run_id": p["run_id"], "alarm": _alarm(alarm),
            "state": state_of(p["verdict"], alarm),
            "next": next_crossing(trend, info["calendar"], today)})
    latest: dict[tuple[str, str, str, str], dict[str, Any]] = {}
    for i in queries.indicators(db, trainset, per_run=True):
        if fleet is None or i["fleet"] == fleet:
            latest[(i["fleet"], i["trainset"], i["vehicle"], i["name"])] = i
    for key, i in sorted(latest.items()):
        alarm = alarms.get(key)
        limit = i["limit"]
        rows.append({
            "what": "indicator", "fleet": key[0], "trainset": key[1], "vehicle": key[2], "source": key[3],
            "kind": key[3], "label": INDICATOR_LABELS.get(key[3], key[3]), "location": i["channel"],
            "value": i["value"], "unit": "" if i["unit"] == "-" else i["unit"], "nominal": None,
            "interval_low": None, "interval_high": None, "limit": limit,
            "levels": {"warning": COMFORT_WARNING, "alarm": COMFORT_ALARM} if key[3] == COMFORT else None,
            "percent": None if not limit else 100.0 * i["value"] / limit, "percent_low": None, "percent_high": None,
            "percent_of": "limit" if limit else None,
            "verdict": i["verdict"], "trust": "not applicable", "trust_reason": None,
            "reason": ("no bogie mass given, so no EN 14363 limit" if i["verdict"] == "not assessable" else None),
            "date": i["date"], "mileage_km": i["mileage_km"], "age_days": _age(i["date"], today),
            "run_id": i["run_id"], "alarm": _alarm(alarm), "state": state_of(i["verdict"], alarm),
            "next": {"kind": "none", "level": None, "date": None, "date_low": None, "date_high": None, "x": None,
                     "text": "not forecast (an indicator)"}})
    if group:
        rows = [r for r in rows if group in (r["source"], r["kind"])]
    if state:
        rows = [r for r in rows if r["state"] == state]
    rows.sort(key=lambda r: (_RANK[r["state"]], r["next"]["date"] or "9999", r["trainset"], r["vehicle"],
                             r["what"], r["source"]))
    counts = Counter(r["state"] for r in rows)
    return {"rows": rows, "counts": {s: counts.get(s, 0) for s in STATES}, "today": today.isoformat()}
