"""Writing runs into the monitoring database: ``suspid run`` / ``suspid monitor`` with a ``fleet:`` section,
and ``suspid fleet import`` of the run folders that exist.

A run's element values come from its ``result.json``; its verdicts from the
acceptable domains (``monitor.acceptable``) by the monitor's status rule
(:func:`suspid.workflows.monitor.status_of`): ``ok`` -> ok, ``warning`` ->
warning, ``out-of-domain`` -> alarm, and ``not-identifiable``,
``not-trustworthy`` or ``unmonitored`` -> not assessable. Trust is the run's
(yes / no / not assessed). Recording a run already in the database (same run
folder and config hash) changes nothing, so an import can be repeated and an
interrupted recording completed without doubling anything. Each run (each
monitor, all its dates) is written in one transaction together with the
replay of its vehicle's alarms (:func:`suspid.fleet.alarms.update_alarms`);
on PostgreSQL a transaction-scoped advisory lock per vehicle serialises
writers of the same vehicle, SQLite serialises all writers.
"""

from __future__ import annotations

import datetime as dt
import json
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

from sqlalchemy import select, text
from sqlalchemy.orm import Session

from suspid.errors import DataError
from suspid.fleet.alarms import update_alarms
from suspid.fleet.db import Database
from suspid.fleet.schema import ElementValue, Indicator, Run
from suspid.indicators.standard import IndicatorValue
from suspid.workflows.monitor import status_of
from suspid.workflows.report import trust_word

VERDICT_OF_STATUS = {"ok": "ok", "warning": "warning", "out-of-domain": "alarm", "not-identifiable": "not assessable",
                     "not-trustworthy": "not assessable", "unmonitored": "not assessable"}
Log = Callable[[str], None]


@dataclass(frozen=True)
class VehicleKey:
    """Which vehicle a run measured: fleet, trainset, vehicle."""

    fleet: str
    trainset: str
    vehicle: str


@dataclass
class RecordedRun:
    """A run in the database: its row id, whether this call wrote it, its element values and indicators."""

    run_id: int
    created: bool
    n_values: int
    n_indicators: int
    date: dt.date
    run_dir: Path


@dataclass
class ImportResult:
    """What :func:`import_folders` recorded (``created`` False: the run was already there)."""

    runs: list[RecordedRun] = field(default_factory=list)

    @property
    def n_created(self) -> int:
        return sum(r.created for r in self.runs)


def element_kind(group: str) -> str:
    """``c_yaw[bogie1]`` -> ``c_yaw``; a kind-level name is its own kind."""
    return group.split("[", 1)[0]


def _reasons(result: Mapping[str, Any], key: str, name: str) -> str:
    """``result[key][name]`` (a reason or a list of reasons) as one text, "" when there is none."""
    found = (result.get(key) or {}).get(name) or ""
    return "; ".join(map(str, found)) if isinstance(found, (list, tuple)) else str(found)


def not_assessable_reason(result: Mapping[str, Any], name: str, status: str) -> str | None:
    """Why an element's verdict is ``not assessable`` (None for the other verdicts), from the run's own reasons."""
    if status == "not-identifiable":
        return "not identifiable: " + (_reasons(result, "non_identifiable_reasons", name) or
                                       "the measurements do not determine it")
    if status == "not-trustworthy":
        return "not trustworthy under model error: " + (_reasons(result, "untrustworthy_reasons", name) or
                                                        "a model-error check flags it")
    if status == "unmonitored":
        return "no acceptable domain given for it (monitor.acceptable, or fleet.acceptable of a suspid run)"
    return None


def element_rows(result: Mapping[str, Any], acceptable: Mapping[str, Sequence[float | None]]) -> list[dict[str, Any]]:
    """The element values of one ``result.json`` with their verdicts, trust, nominal values, plain-language
    labels and the reasons behind a ``not assessable`` verdict and a ``not assessed`` trust (module docstring)."""
    rows = []
    trust = result.get("trustworthy") or {}
    labels = {r.get("name"): r.get("label") for r in (result.get("verdict") or {}).get("rows", [])}
    for n in result["parameters"]:
        domain = acceptable.get(n)
        status = status_of(result["interval"][n], domain, bool(result["identifiable"][n]), trust.get(n))
        nominal = (result.get("nominal") or {}).get(n)
        rows.append({"element_group": n, "kind": element_kind(n), "unit": result.get("units", {}).get(n, ""),
                     "value": float(result["w_opt"][n]), "interval_low": float(result["interval"][n][0]),
                     "interval_high": float(result["interval"][n][1]),
                     "acceptable_low": None if domain is None else domain[0],
                     "acceptable_high": None if domain is None else domain[1],
                     "identifiable": bool(result["identifiable"][n]), "trust": trust_word(trust.get(n)),
                     "verdict": VERDICT_OF_STATUS[status],
                     "w_ref": (result.get("w_ref") or {}).get(n),
                     "nominal": None if nominal is None else float(nominal), "label": labels.get(n),
                     "reason": not_assessable_reason(result, n, status),
                     "trust_reason": (_reasons(result, "not_assessed_reasons", n) or None)
                     if trust_word(trust.get(n)) == "not assessed" else None})
    return rows


def _lock_vehicle(session: Session, key: VehicleKey) -> None:
    if session.get_bind().dialect.name == "postgresql":
        lock = zlib.crc32(f"{key.fleet}/{key.trainset}/{key.vehicle}".encode()) - 2**31
        session.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": lock})


def _figure(run_dir: Path, name: str) -> str | None:
    return str(run_dir / name) if (run_dir / name).is_file() else None


@dataclass
class RunRecord:
    """One identification to record (the arguments of :func:`record_result`)."""

    key: VehicleKey
    date: dt.date
    result: Mapping[str, Any]
    run_dir: Path
    mileage_km: float | None = None
    kind: str = "run"
    acceptable: Mapping[str, Sequence[float | None]] | None = None
    indicators: Sequence[IndicatorValue] = ()


def _add(session: Session, rec: RunRecord) -> RecordedRun:
    """Add one run (unless its run folder and run id are there already) and replay its vehicle's alarms."""
    run_dir, key = Path(rec.run_dir).resolve(), rec.key
    config_hash = str(rec.result.get("run_id") or "")
    found = session.scalar(select(Run).where(Run.run_dir == str(run_dir), Run.config_hash == config_hash))
    if found is not None:
        if (found.fleet, found.trainset, found.vehicle) != (key.fleet, key.trainset, key.vehicle):
            raise DataError(f"{run_dir}: run {config_hash} is recorded already for {found.fleet}/{found.trainset}/"
                            f"{found.vehicle} (database run {found.id}), not for {key.fleet}/{key.trainset}/"
                            f"{key.vehicle}; nothing was recorded")
        return RecordedRun(found.id, False, len(found.values), len(found.indicators), found.date, run_dir)
    rows = element_rows(rec.result, rec.acceptable or {})
    run = Run(fleet=key.fleet, trainset=key.trainset, vehicle=key.vehicle, date=rec.date,
              mileage_km=rec.mileage_km, kind=rec.kind, name=str(rec.result.get("name", run_dir.name)),
              config_hash=config_hash, run_dir=str(run_dir), report_path=_figure(run_dir, "report.md"),
              figure1_path=_figure(run_dir, "figure1_spectra.png"),
              figure2_path=_figure(run_dir, "figure2_parameters.png"),
              recorded_at=dt.datetime.now(dt.timezone.utc).replace(tzinfo=None))
    run.values = [ElementValue(**r) for r in rows]
    run.indicators = [Indicator(name=i.name, segment=i.segment, channel=i.channel, value=float(i.value),
                                limit=i.limit, unit=i.unit, verdict=i.verdict, detail=json.dumps(i.detail))
                      for i in rec.indicators]
    session.add(run)
    session.flush()
    update_alarms(session, key.fleet, key.trainset, key.vehicle)
    return RecordedRun(run.id, True, len(rows), len(rec.indicators), rec.date, run_dir)


def record_results(db: Database, records: Sequence[RunRecord]) -> list[RecordedRun]:
    """Record several runs (a monitor's dates) in one transaction: all of them or, after a fault, none.

    Each run is keyed by its run folder and run id (``result.json``'s ``run_id``,
    the digest of its config): recording it again changes nothing, so a
    recording interrupted by any fault is completed by doing it again, and
    never doubled (:meth:`suspid.fleet.db.Database.write` retries passing faults).
    """
    def work(session: Session) -> list[RecordedRun]:
        for key in sorted({r.key for r in records}, key=lambda k: (k.fleet, k.trainset, k.vehicle)):
            _lock_vehicle(session, key)      # in one order: two writers of the same vehicles cannot deadlock
        return [_add(session, r) for r in records]

    return db.write(work)


def record_result(db: Database, key: VehicleKey, date: dt.date, result: Mapping[str, Any], run_dir: Path, *,
                  mileage_km: float | None = None, kind: str = "run",
                  acceptable: Mapping[str, Sequence[float | None]] | None = None,
                  indicators: Sequence[IndicatorValue] = ()) -> RecordedRun:
    """Record one identification (its ``result.json`` dict) and its indicators, then replay the alarms.

    :param run_dir: the run's folder (``report.md``, ``figure1_spectra.png``, ``figure2_parameters.png``).
    :param kind: ``run`` (``suspid run``) or ``monitor-date``.
    :param acceptable: acceptable domain per element group (SI units); without one: not assessable.
    :raises DataError: the run folder is recorded for another vehicle, or a fault of the database.
    """
    return record_results(db, [RunRecord(key, date, result, Path(run_dir), mileage_km, kind, acceptable,
                                         indicators)])[0]


def is_recorded(db: Database, run_dir: Path, config_hash: str) -> bool:
    """Whether the run of ``run_dir`` with ``config_hash`` is in the database (its indicators need no computing)."""
    return db.query(lambda session: session.scalar(
        select(Run.id).where(Run.run_dir == str(Path(run_dir).resolve()), Run.config_hash == str(config_hash)))
        is not None)


def _read_json(path: Path) -> dict[str, Any]:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(f"{path}: not found") from None
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: not valid JSON ({exc.msg}, line {exc.lineno})") from None


def mileage_at(date: dt.date, first: dt.date, mileage_km: float | None, km_per_day: float | None) -> float | None:
    """Mileage at ``date``: ``mileage_km`` at ``first`` plus ``km_per_day`` per day since (None if unknown)."""
    if mileage_km is None:
        return None
    return mileage_km + (km_per_day or 0.0) * (date - first).days


def import_folders(db: Database, folders: Sequence[Path], key: VehicleKey, *, date: dt.date | None = None,
                   mileage_km: float | None = None, km_per_day: float | None = None,
                   indicators: Callable[[Path], Sequence[IndicatorValue]] | None = None,
                   log: Log = lambda s: None) -> ImportResult:
    """Record existing run folders: a monitor folder (``monitor.json`` and ``dates/<date>/``) or a run folder.

    A monitor folder brings its dates, acceptable domains and (with ``mileage_km``, ``km_per_day``) the mileage
    of every date. A run folder needs ``date`` (default: the day its ``result.json`` was written).

    :param indicators: run folder -> its indicators (e.g. from the run's ``config.yaml``); None: none stored.
    :raises DataError: a folder with neither ``monitor.json`` nor ``result.json``.
    """
    out = ImportResult()
    for folder in map(Path, folders):
        if (folder / "monitor.json").is_file():
            summary = _read_json(folder / "monitor.json")
            dates = [dt.date.fromisoformat(d) for d in summary["dates"]]
            for d in dates:
                run_dir = folder / "dates" / d.isoformat()
                log(f"{key.trainset}: {run_dir}")
                result = _read_json(run_dir / "result.json")
                new = indicators and not is_recorded(db, run_dir, str(result.get("run_id") or ""))
                out.runs.append(record_result(
                    db, key, d, result, run_dir, kind="monitor-date",
                    mileage_km=mileage_at(d, dates[0], mileage_km, km_per_day),
                    acceptable=summary.get("acceptable") or {}, indicators=indicators(run_dir) if new else ()))
        elif (folder / "result.json").is_file():
            result_path = folder / "result.json"
            d = date or dt.date.fromtimestamp(result_path.stat().st_mtime)
            log(f"{key.trainset}: {folder}")
            result = _read_json(result_path)
            new = indicators and not is_recorded(db, folder, str(result.get("run_id") or ""))
            out.runs.append(record_result(db, key, d, result, folder, kind="run", mileage_km=mileage_km,
                                          indicators=indicators(folder) if new else ()))
        else:
            raise DataError(f"{folder}: neither a monitor folder (monitor.json) nor a run folder (result.json)")
    return out
