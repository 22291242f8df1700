"""Reading the monitoring database: the fleet overview, a vehicle's history and trends, alarms, exports.

Every function takes an open :class:`~suspid.fleet.db.Database` and returns
plain typed rows (dicts with JSON-able values), what the dashboard shows and
what ``/export.csv`` and ``/export.json`` hand to a maintenance information system.
"""

from __future__ import annotations

import datetime as dt
from typing import Any

from sqlalchemy import select

from suspid.fleet.db import Database
from suspid.fleet.schema import Acknowledgement, Alarm, AuditEntry, ElementValue, Indicator, Run
from suspid.fleet.trends import Trend, dates_from_mileage, fit_trend


def overview(db: Database, *, fleet: str | None = None, trainset: str | None = None,
             verdict: str | None = None, group: str | None = None) -> list[dict[str, Any]]:
    """The latest verdict of every (trainset, vehicle, element group), with its trust, date and alarm state.

    Filters keep the rows of one fleet, trainset, element group (or its kind) or latest verdict.
    """
    with db.read() as s:
        q = select(Run, ElementValue).join(ElementValue).order_by(Run.date, Run.id)
        if fleet:
            q = q.where(Run.fleet == fleet)
        if trainset:
            q = q.where(Run.trainset == trainset)
        latest: dict[tuple, dict[str, Any]] = {}
        for run, v in s.execute(q):
            latest[(run.fleet, run.trainset, run.vehicle, v.element_group)] = {
                "fleet": run.fleet, "trainset": run.trainset, "vehicle": run.vehicle,
                "element_group": v.element_group, "kind": v.kind, "verdict": v.verdict, "trust": v.trust,
                "value": v.value, "unit": v.unit, "interval_low": v.interval_low, "interval_high": v.interval_high,
                "date": run.date.isoformat(), "mileage_km": run.mileage_km, "run_id": run.id}
        alarms = {(a.fleet, a.trainset, a.vehicle, a.source): a for a in s.scalars(select(Alarm))}
    rows = []
    for k, row in sorted(latest.items()):
        a = alarms.get(k)
        row["alarm"] = None if a is None or a.state != "raised" else a.level
        row["acknowledged"] = bool(a is not None and a.acked_by)
        if group and group not in (row["element_group"], row["kind"]):
            continue
        if verdict and row["verdict"] != verdict:
            continue
        rows.append(row)
    return rows


def trainsets(db: Database) -> list[str]:
    with db.read() as s:
        return sorted(set(s.scalars(select(Run.trainset))))


def history(db: Database, trainset: str | None, *, fleet: str | None = None) -> list[dict[str, Any]]:
    """Every element value of a trainset (of every trainset: None), in date order (one row per run and element
    group)."""
    with db.read() as s:
        q = select(Run, ElementValue).join(ElementValue)
        if trainset is not None:
            q = q.where(Run.trainset == trainset)
        if fleet:
            q = q.where(Run.fleet == fleet)
        return [{"run_id": r.id, "fleet": r.fleet, "trainset": r.trainset, "vehicle": r.vehicle,
                 "date": r.date.isoformat(), "mileage_km": r.mileage_km, "element_group": v.element_group,
                 "value": v.value, "interval_low": v.interval_low, "interval_high": v.interval_high,
                 "acceptable_low": v.acceptable_low, "acceptable_high": v.acceptable_high, "unit": v.unit,
                 "identifiable": v.identifiable, "trust": v.trust, "verdict": v.verdict, "w_ref": v.w_ref,
                 "kind": v.kind, "nominal": v.nominal, "label": v.label, "reason": v.reason,
                 "trust_reason": v.trust_reason}
                for r, v in s.execute(q.order_by(Run.date, Run.id, ElementValue.element_group))]


def indicators(db: Database, trainset: str | None = None, run_id: int | None = None,
               per_run: bool = True) -> list[dict[str, Any]]:
    """Indicator values (the run's own when ``per_run``, else every segment's too), in date order."""
    with db.read() as s:
        q = select(Run, Indicator).join(Indicator)
        if trainset:
            q = q.where(Run.trainset == trainset)
        if run_id is not None:
            q = q.where(Run.id == run_id)
        if per_run:
            q = q.where(Indicator.segment.is_(None))
        return [{"run_id": r.id, "fleet": r.fleet, "trainset": r.trainset, "vehicle": r.vehicle,
                 "date": r.date.isoformat(), "mileage_km": r.mileage_km,
                 "name": i.name, "segment": i.segment, "channel": i.channel, "value": i.value, "limit": i.limit,
                 "unit": i.unit, "verdict": i.verdict}
                for r, i in s.execute(q.order_by(Run.date, Run.id, Indicator.name, Indicator.id))]


def trends(db: Database, trainset: str, *, fleet: str | None = None) -> list[tuple[dict[str, Any], Trend]]:
    """The trend of every (vehicle, element group) of a trainset, with its points (:mod:`suspid.fleet.trends`).

    The abscissa is the mileage when every point has one, else the days since the first date. Each info dict
    has the vehicle, the element group, the points (:func:`history` rows), their abscissae ``x`` and the
    vehicle's ``calendar`` (:class:`~suspid.fleet.trends.Calendar`, abscissa <-> date).
    """
    return trends_of(history(db, trainset, fleet=fleet))


def trends_of(rows: list[dict[str, Any]]) -> list[tuple[dict[str, Any], Trend]]:
    """:func:`trends` of :func:`history` rows (of one trainset or several), by (fleet, trainset, vehicle, group)."""
    groups: dict[tuple[str, str, str, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r["fleet"], r["trainset"], r["vehicle"], r["element_group"]), []).append(r)
    out = []
    for (fleet, trainset, vehicle, group), pts in sorted(groups.items()):
        dates = [dt.date.fromisoformat(p["date"]) for p in pts]
        use_km = all(p["mileage_km"] is not None for p in pts)
        x = [p["mileage_km"] if use_km else (d - min(dates)).days for p, d in zip(pts, dates)]
        t = fit_trend(group, x, [p["value"] for p in pts],
                      [(p["interval_high"] - p["interval_low"]) / 2 for p in pts],
                      [p["identifiable"] and p["trust"] != "no" for p in pts],
                      acceptable_low=pts[-1]["acceptable_low"], acceptable_high=pts[-1]["acceptable_high"],
                      abscissa="mileage_km" if use_km else "days")
        calendar = dates_from_mileage(t, dates, [p["mileage_km"] for p in pts])
        out.append(({"fleet": fleet, "trainset": trainset, "vehicle": vehicle, "element_group": group,
                     "points": pts, "x": x, "calendar": calendar}, t))
    return out


def alarms(db: Database, *, state: str | None = None, trainset: str | None = None) -> list[dict[str, Any]]:
    """Alarms (``raised`` or ``cleared`` with ``state``), newest first."""
    with db.read() as s:
        q = select(Alarm)
        if state:
            q = q.where(Alarm.state == state)
        if trainset:
            q = q.where(Alarm.trainset == trainset)
        return [{"id": a.id, "fleet": a.fleet, "trainset": a.trainset, "vehicle": a.vehicle, "source": a.source,
                 "state": a.state, "level": a.level, "raised_on": _iso(a.raised_on), "cleared_on": _iso(a.cleared_on),
                 "last_date": _iso(a.last_date), "acked_by": a.acked_by, "acked_at": _iso(a.acked_at),
                 "ack_comment": a.ack_comment}
                for a in s.scalars(q.order_by(Alarm.raised_on.desc(), Alarm.id))]


def acknowledgements(db: Database, alarm_id: int | None = None) -> list[dict[str, Any]]:
    """Every acknowledgement (of one alarm with ``alarm_id``), oldest first: who, when (UTC), comment, the
    episode (``raised_on``) and level acknowledged."""
    with db.read() as s:
        q = select(Acknowledgement)
        if alarm_id is not None:
            q = q.where(Acknowledgement.alarm_id == alarm_id)
        return [{"id": a.id, "alarm_id": a.alarm_id, "user": a.user_name, "at": _iso(a.at), "comment": a.comment,
                 "raised_on": _iso(a.raised_on), "level": a.level}
                for a in s.scalars(q.order_by(Acknowledgement.at, Acknowledgement.id))]


def audit(db: Database, limit: int = 200) -> list[dict[str, Any]]:
    """The newest audit entries."""
    with db.read() as s:
        return [{"id": e.id, "at": _iso(e.at), "actor": e.actor, "action": e.action,
                 "alarm_id": e.alarm_id, "detail": e.detail}
                for e in s.scalars(select(AuditEntry).order_by(AuditEntry.id.desc()).limit(limit))]


def run_info(db: Database, run_id: int) -> dict[str, Any] | None:
    """One run: its keys, paths and element values (None when there is no such run)."""
    with db.read() as s:
        r = s.get(Run, run_id)
        if r is None:
            return None
        return {"id": r.id, "fleet": r.fleet, "trainset": r.trainset, "vehicle": r.vehicle, "date": r.date.isoformat(),
                "mileage_km": r.mileage_km, "kind": r.kind, "name": r.name, "config_hash": r.config_hash,
                "run_dir": r.run_dir, "report_path": r.report_path, "figure1_path": r.figure1_path,
                "figure2_path": r.figure2_path,
                "values": [{"element_group": v.element_group, "value": v.value, "interval_low": v.interval_low,
                            "interval_high": v.interval_high, "unit": v.unit, "identifiable": v.identifiable,
                            "trust": v.trust, "verdict": v.verdict, "nominal": v.nominal, "label": v.label,
                            "kind": v.kind, "reason": v.reason, "trust_reason": v.trust_reason,
                            "acceptable_low": v.acceptable_low, "acceptable_high": v.acceptable_high}
                           for v in r.values]}


def count_runs(db: Database) -> int:
    with db.read() as s:
        return len(s.scalars(select(Run.id)).all())


def _iso(v: dt.date | dt.datetime | None) -> str | None:
    """A date as ``YYYY-MM-DD``; a time (UTC) as ``YYYY-MM-DD HH:MM:SS``, without microseconds."""
    if v is None:
        return None
    if isinstance(v, dt.datetime):
        return v.isoformat(sep=" ", timespec="seconds")
    return v.isoformat()
