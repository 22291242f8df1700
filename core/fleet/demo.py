"""The demo fleet (``suspid fleet demo configs/fleet-demo.yaml``): a small fleet monitored end to end.

A fleet plan names a database, a base monitor config shared by every trainset
(a degradation ``scenario`` on the frequency solver) and the trainsets, each
with its own overrides (which element degrades and how much, a faulty sensor,
its seed)::

    name: fleet-demo
    database: runs/fleet-demo/fleet.sqlite   # relative to the plan file, or a URL
    fleet: demo
    base: {...}                              # a suspid config with monitor: and fleet: (mileage)
    trainsets:
      - {trainset: TS01, set: {monitor.scenario.parameter: c_yaw, monitor.scenario.loss: 0.6}}

Every trainset's monitor records its dates into the database (its run
folders in ``runs/<name>/<trainset>/``). Then, for each trainset whose
scenario loses at least 20 %, the plan is checked against what the database
says: the first date with a ``warning`` and with an ``alarm`` verdict against
the first date whose *true* value (the scenario's) is past the warning and
alarm levels, and each forecast interval (the trend as of the last date)
against the date the true value crosses that level. ``fleet-demo.json`` and
``fleet-demo.md`` in ``runs/<name>/`` say what held.
"""

from __future__ import annotations

import copy
import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import yaml

from suspid.config import build_simulator, load_config, override_arguments
from suspid.errors import ConfigError
from suspid.fleet import queries
from suspid.fleet.db import database_url, open_database
from suspid.infra.files import write_json, write_text
from suspid.workflows.monitor import scenario_dates

Log = Callable[[str], None]
DEGRADING = 0.2


@dataclass
class DemoCheck:
    """One degrading element of the demo: verdict dates and forecasts against the simulated degradation."""

    trainset: str
    element_group: str
    loss: float
    first_warning: str | None
    first_alarm: str | None
    true_warning: str | None
    true_alarm: str | None
    forecasts: dict[str, dict[str, Any]] = field(default_factory=dict)
    dates: list[str] = field(default_factory=list)

    def on_time(self, level: str) -> bool:
        """The first ``level`` verdict within one measurement date of the first date at or after the true
        crossing (a date's verdict judges the identified value, whose interval straddles the truth)."""
        first, true = getattr(self, f"first_{level}"), getattr(self, f"true_{level}")
        if first is None or true is None:
            return False
        expected = next((i for i, d in enumerate(self.dates) if d >= true), len(self.dates))
        return abs(self.dates.index(first) - expected) <= 1

    @property
    def holds(self) -> bool:
        """Warning then alarm on the right dates, and both forecast intervals contain the true crossings."""
        covered = len(self.forecasts) == 2 and all(v.get("contains_true") for v in self.forecasts.values())
        return bool(covered and self.on_time("warning") and self.on_time("alarm")
                    and self.first_warning <= self.first_alarm)


@dataclass
class DemoResult:
    """The demo's database URL, its output folder and the checks of its degrading elements."""

    database: str
    out_dir: Path
    checks: list[DemoCheck]


def read_plan(path: Path) -> dict[str, Any]:
    try:
        plan = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: not found") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{path}: not valid YAML ({exc})") from None
    for key in ("base", "trainsets", "database"):
        if not isinstance(plan, dict) or key not in plan:
            raise ConfigError(f"{path}: key '{key}' is missing (a fleet plan has name, database, fleet, base, "
                              f"trainsets)")
    for i, t in enumerate(plan["trainsets"]):
        if not isinstance(t, dict) or "trainset" not in t:
            raise ConfigError(f"{path}, key 'trainsets.{i}': give {{trainset: NAME, set: {{key.path: value}}}}")
    return plan


def _true_crossing(dates: list[dt.date], nominal: float, loss: float, level: float) -> dt.date | None:
    """Date the scenario's true value nominal * (1 - loss * t) reaches ``level`` (t linear over the dates)."""
    need = (1.0 - level / nominal) / loss
    if not 0.0 <= need:
        return dates[0]
    span = (dates[-1] - dates[0]).days
    return dates[0] + dt.timedelta(days=need * span)


def trainset_configs(plan_file: Path, plan: Mapping[str, Any], url: str) -> list[tuple[str, Any]]:
    """Each trainset's validated monitor config (base + the trainset's overrides + where it records)."""
    base_dir = plan_file.parent
    name = plan.get("name", "fleet-demo")
    out = []
    for i, t in enumerate(plan["trainsets"]):
        trainset = t["trainset"]
        mapping = copy.deepcopy(plan["base"])
        mapping["name"] = f"{name}-{trainset}"
        overrides = dict(t.get("set") or {}) | {
            "output.dir": str((base_dir / "runs" / name / trainset).resolve()),
            "fleet.database": url, "fleet.trainset": trainset, "fleet.fleet": plan.get("fleet", "fleet")}
        try:
            cfg = load_config(mapping, override_arguments(overrides), base_dir=base_dir)
        except ConfigError as exc:
            raise ConfigError(f"{plan_file}, trainsets.{i} ({trainset}): {exc}") from None
        out.append((trainset, (mapping, overrides, cfg)))
    return out


def run_demo(plan_file: str | Path, *, log: Log = lambda s: None, progress: bool = False) -> DemoResult:
    """Monitor every trainset of the plan into its database, then check the degrading elements (module docstring)."""
    from suspid import api

    plan_file = Path(plan_file).resolve()
    plan = read_plan(plan_file)
    where = str(plan["database"])
    url = database_url(where if "://" in where else plan_file.parent / where)
    if url.startswith("sqlite:///"):
        Path(url.removeprefix("sqlite:///")).parent.mkdir(parents=True, exist_ok=True)
    configs = trainset_configs(plan_file, plan, url)          # every trainset checked before any simulation
    for trainset, (mapping, overrides, _) in configs:
        log(f"trainset {trainset}: monitoring")
        api.monitor(mapping, overrides, progress=progress, log=log)
    out_dir = plan_file.parent / "runs" / plan.get("name", "fleet-demo")
    db = open_database(url)
    checks = []
    try:
        for trainset, (_, _, cfg) in configs:
            s = cfg.monitor.scenario
            if s is None or s.loss < DEGRADING:
                continue
            dates = scenario_dates(s)
            nominal = next(p.nominal for p in build_simulator(cfg).parameters() if p.name == s.parameter)
            hist = [h for h in queries.history(db, trainset) if h["element_group"] == s.parameter]
            first = {"warning": next((h["date"] for h in hist if h["verdict"] in ("warning", "alarm")), None),
                     "alarm": next((h["date"] for h in hist if h["verdict"] == "alarm"), None)}
            trend = next(t for info, t in queries.trends(db, trainset) if info["element_group"] == s.parameter)
            check = DemoCheck(trainset, s.parameter, s.loss, first["warning"], first["alarm"], None, None,
                              dates=[d.isoformat() for d in dates])
            for f in trend.forecasts:
                true = _true_crossing(dates, nominal, s.loss, f.value)
                check.forecasts[f.level] = {
                    "level": f.value, "date": _iso(f.date), "date_low": _iso(f.date_low),
                    "date_high": _iso(f.date_high), "true_date": _iso(true),
                    "contains_true": bool(f.date_low and true and f.date_low <= true and
                                          (f.date_high is None or true <= f.date_high))}
                setattr(check, f"true_{f.level}", _iso(true))
            checks.append(check)
    finally:
        db.dispose()
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "fleet-demo.json", {"database": url, "checks": [c.__dict__ | {"holds": c.holds}
                                                                          for c in checks]})
    lines = ["# Demo fleet", "", f"Database: `{url}`; `suspid dashboard --db {url}` shows it.", "",
             "| trainset | element | loss | first warning | true warning | first alarm | true alarm | "
             "warning forecast [interval] | alarm forecast [interval] | holds |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for c in checks:
        fc = {k: f"{v['date']} [{v['date_low']}, {v['date_high'] or 'beyond'}]" for k, v in c.forecasts.items()}
        lines.append(f"| {c.trainset} | `{c.element_group}` | {100 * c.loss:.0f} % | {c.first_warning} | "
                     f"{c.true_warning} | {c.first_alarm} | {c.true_alarm} | {fc.get('warning', '-')} | "
                     f"{fc.get('alarm', '-')} | {'yes' if c.holds else 'no'} |")
    write_text(out_dir / "fleet-demo.md", "\n".join(lines) + "\n")
    return DemoResult(url, out_dir, checks)


def _iso(d: dt.date | None) -> str | None:
    return None if d is None else d.isoformat()
