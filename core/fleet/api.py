"""What ``suspid run``/``monitor`` record, ``suspid fleet import`` and ``suspid indicators`` do, as functions.

:func:`record_identification` and :func:`record_monitor` are called by
:func:`suspid.identify` and :func:`suspid.monitor` when the config has a
``fleet.database``; each date of a monitor is one run in the database, with
its mileage (``fleet.mileage_km`` at the first date plus ``fleet.km_per_day``,
or the campaign's own ``mileage_km``) and the indicators of its recordings.
"""

from __future__ import annotations

import contextlib
import datetime as dt
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

from suspid.config import Config, build_simulator, identified_bounds, load_config
from suspid.errors import ConfigError, DataError
from suspid.fleet.db import Database, database_url, open_database
from suspid.fleet.record import (ImportResult, RecordedRun, RunRecord, VehicleKey, import_folders, is_recorded,
                                  mileage_at, record_result, record_results)
from suspid.indicators.recordings import config_indicators
from suspid.indicators.standard import IndicatorValue

Log = Callable[[str], None]


def database_location(config: Config) -> str | None:
    """The config's ``fleet.database`` as a URL (a relative path is taken from the config's folder), or None.

    :raises ConfigError: naming ``fleet.database`` when it is not a usable URL.
    """
    if config.fleet is None or config.fleet.database is None:
        return None
    where = config.fleet.database
    if "://" not in where:
        where = str(config.resolve(where))
    try:
        return database_url(where)
    except ConfigError as exc:
        raise config.error(exc.detail.removeprefix("database: "), "fleet.database") from None


def check_fleet(config: Config) -> None:
    """The ``fleet:`` checks of ``suspid validate``: a usable database URL whose SQLite folder exists."""
    url = database_location(config)
    known = identified_bounds(config, build_simulator(config))
    for name, (lo, hi) in config.fleet.acceptable.items():
        key = f"fleet.acceptable.{name}"
        if name not in known:
            raise config.error(f"'{name}' is not an identified parameter; identified: {', '.join(known)}", key)
        if lo is None and hi is None or lo is not None and hi is not None and not lo < hi:
            raise config.error("give [lower, upper] with lower < upper, null for an open side", key)
    if url is not None and url.startswith("sqlite:///"):
        folder = Path(url.removeprefix("sqlite:///")).parent
        if not folder.is_dir():
            raise config.error(f"folder {folder} of the SQLite database does not exist", "fleet.database")


def _key(config: Config) -> VehicleKey:
    f = config.fleet
    return VehicleKey(f.fleet, f.trainset, f.vehicle)


def _indicators(config: Config, log: Log) -> list[IndicatorValue]:
    if not config.fleet.indicators:
        return []
    log("indicators: EN 14363 instability and EN 12299 comfort of the recordings")
    return config_indicators(config, hunting_hz=config.fleet.hunting_hz)


def _open(config: Config, url: str, log: Log) -> Database:
    return open_database(url, wait_s=config.fleet.wait_s, log=log)


@contextlib.contextmanager
def _keeping(run_dir: Path) -> Iterator[None]:
    """A fault of the database after a run: its line, and that the run's own results are kept for a rerun."""
    try:
        yield
    except DataError as exc:
        raise DataError(f"{exc}; nothing was recorded; the run's results are kept in {run_dir}: the same command "
                        f"records them, once, when the database is usable") from None


def record_identification(config: Config, result: Any, *, log: Log = lambda s: None) -> RecordedRun | None:
    """Record a finished ``suspid run`` (an :class:`~suspid.workflows.identify.IdentificationResult`).

    :raises DataError: a fault of the database (one line; ``result.json`` and the ledger are kept, and the
        same command records the run once).
    """
    url = database_location(config)
    if url is None:
        return None
    with _keeping(result.run_dir):
        db = _open(config, url, log)
        try:
            acceptable = {n: list(v) for n, v in config.fleet.acceptable.items()}
            rec = record_result(db, _key(config), config.fleet.date or dt.date.today(), result.to_dict(),
                                result.run_dir, mileage_km=config.fleet.mileage_km, kind="run",
                                acceptable=acceptable, indicators=_indicators(config, log))
        finally:
            db.dispose()
    log(f"recorded in the monitoring database as run {rec.run_id}" + ("" if rec.created else " (already there)"))
    return rec


def record_monitor(config: Config, plans: Sequence[Any], result: Any, *, log: Log = lambda s: None
                   ) -> list[RecordedRun]:
    """Record every date of a finished monitor (``plans``: its :class:`~suspid.workflows.monitor.DatePlan`),
    all dates in one transaction.

    :raises DataError: as :func:`record_identification`; then no date is recorded.
    """
    url = database_location(config)
    if url is None:
        return []
    acceptable = {n: list(v) for n, v in config.monitor.acceptable.items()}
    campaign_km = {c.date: c.mileage_km for c in config.monitor.campaigns}
    first = plans[0].date
    with _keeping(result.monitor_dir):
        db = _open(config, url, log)
        try:
            records = []
            for plan in plans:
                km = campaign_km.get(plan.date)
                if km is None:
                    km = mileage_at(plan.date, first, config.fleet.mileage_km, config.fleet.km_per_day)
                res = result.dates[plan.date.isoformat()]
                data = res.to_dict()
                new = not is_recorded(db, res.run_dir, str(data.get("run_id") or ""))   # a resumed monitor
                records.append(RunRecord(_key(config), plan.date, data, res.run_dir, km, "monitor-date", acceptable,
                                         _indicators(plan.config, log) if new else ()))
            out = record_results(db, records)
        finally:
            db.dispose()
    n_new = sum(r.created for r in out)
    log(f"recorded {n_new} dates of {config.fleet.trainset} in the monitoring database"
        + (f" ({len(out) - n_new} already there)" if n_new < len(out) else ""))
    return out


def import_runs(database: str | Path, folders: Sequence[str | Path], *, fleet: str, trainset: str,
                vehicle: str = "car1", date: dt.date | None = None, mileage_km: float | None = None,
                km_per_day: float | None = None, indicators: bool = True, log: Log = lambda s: None) -> ImportResult:
    """Record run folders that exist (``suspid fleet import``): monitor folders or ``suspid run`` folders.

    :param indicators: also compute each run's indicators from its ``config.yaml`` (re-simulating a numerical
        experiment's recordings, reading measured ones).
    """
    db = open_database(database, log=log)

    def of(run_dir: Path) -> list[IndicatorValue]:
        cfg_file = Path(run_dir) / "config.yaml"
        return config_indicators(load_config(cfg_file)) if cfg_file.is_file() else []

    try:
        return import_folders(db, [Path(f) for f in folders], VehicleKey(fleet, trainset, vehicle), date=date,
                              mileage_km=mileage_km, km_per_day=km_per_day,
                              indicators=of if indicators else None, log=log)
    finally:
        db.dispose()


def run_indicators(config: Config, *, log: Log = lambda s: None) -> tuple[list[IndicatorValue], RecordedRun | None]:
    """The indicators of a config's recordings (``suspid indicators``); recorded as a ``recording`` run when
    the config has a ``fleet.database``."""
    values = config_indicators(config, hunting_hz=None if config.fleet is None else config.fleet.hunting_hz)
    url = database_location(config)
    if url is None:
        return values, None
    db = _open(config, url, log)
    try:
        result = {"name": config.name, "parameters": [], "run_id": "indicators"}
        rec = record_result(db, _key(config), config.fleet.date or dt.date.today(), result, config.run_dir(),
                            mileage_km=config.fleet.mileage_km, kind="recording", indicators=values)
        return values, rec
    finally:
        db.dispose()
