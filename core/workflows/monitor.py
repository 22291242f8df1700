"""Maintenance monitoring across measurement dates (``suspid monitor``; paper §1 and §2.3).

The identification is repeated on measurements taken at successive dates;
every suspension parameter is followed over time and flagged as soon as it
leaves its acceptable domain. The noise model B is identified once, at the
reference date, and reused unchanged at every later date (paper §2.3): each
date's run loads it through ``noise.path`` and never identifies its own.

The ``monitor:`` section of a run config (every other section is the base
identification config, shared by all dates)::

    monitor:
      reference:
        noise_model: runs/ref/noise_model.npz   # optional; see "Reference date"
      acceptable:                    # acceptable domain per parameter, SI units;
        c_sec_z: [15.0e3, 25.0e3]    # null for an open side: [null, 25.0e3]
        k_sec_z: [322.5e3, 537.5e3]
      campaigns:                     # measured dates: overrides of the data section
        - {date: 2026-01-15, data: {source: measured, measurements: m/2026-01, track_file: t/2026-01}}
        - {date: 2026-03-15, data: {source: measured, measurements: m/2026-03, track_file: t/2026-03}}
      # or, instead of campaigns, the synthetic degradation scenario:
      scenario:
        parameter: c_sec_z           # the suspension parameter that degrades
        loss: 0.4                    # lost fraction of its nominal value at the last date
        n_dates: 6                   # dates start, start + interval_days, ...
        start: 2026-01-15
        interval_days: 30
        # dates: [2026-01-15, 2026-02-20, ...]   # or explicit dates

Identified parameters without an acceptable domain are reported with status
``unmonitored`` and never flagged.

**Reference date.** The noise model is, in this order, the
``monitor.reference.noise_model`` file (written by a reference-date run,
``<run dir>/noise_model.npz``), the base config's ``noise.path``, or
identified here from the base config as a numerical experiment (paper §2.3
and :mod:`suspid.data.experiment`: the model at w0 made into measurements on the
reference-date track) in ``<monitor dir>/reference/`` with its own ledger.
Measured campaigns therefore need one of the first two.

**Dates.** Each date is the base config with overrides (``monitor`` removed,
``noise.path`` set to the reference model, ``output.dir`` set to
``<monitor dir>/dates/<date>/``), run by :func:`suspid.workflows.identify.run` in its
own directory with its own ledger: an interrupted monitor resumes where it
stopped when run again. A campaign's ``data`` mapping is applied key by key
(``data: {track: {seed: 3}}`` changes only the seed). For a numerical
experiment, every date has its own track realisations: ``data.track.seed``
defaults to ``seed_for(seed, "monitor-<date>")``.

**Scenario.** A numerical experiment (paper §3.3) per date:
``data.w_ref`` is the simulator's nominal value of every identified
parameter except ``parameter``, whose value is ``nominal × (1 - loss × t)``
with t going linearly in time from 0 at the first date to 1 at the last (six
dates and 40 %: 0, 8, 16, 24, 32, 40 % lost).

**Status** of a parameter at a date, from its uncertainty interval [a, b]
(``result.json``) and its acceptable domain [lo, hi]:

- ``ok``: lo <= a and b <= hi;
- ``out-of-domain``: b < lo or a > hi, the whole interval outside;
- ``warning``: otherwise, the interval overlaps an edge of the domain;
- ``not-identifiable``: the run flags the parameter as not identifiable; it
  has no value to judge, so it is never flagged;
- ``not-trustworthy``: identifiable, but a model-error check of the run says
  its value is not a finding (``trustworthy: false``); never flagged either.
  A value whose trust is *not assessed* (the checks that would judge it did
  not run) keeps its status from the interval, and its row says so
  (``trustworthy``: yes, no or not assessed);
- ``unmonitored``: no acceptable domain given.

The **alert date** of a parameter is its first ``out-of-domain`` date.
Outputs in the monitor's run directory: ``monitor.csv`` (one row per date and
parameter), ``monitor.json`` (``alerts: {parameter: date}``,
``first_warnings``, every row), ``monitor.md`` and ``monitor_<parameter>.png``
(the time evolution with the acceptable domain shaded and the intervals drawn).
"""

from __future__ import annotations

import csv
import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from suspid import registry
from suspid.config import Config, build_simulator, identified_bounds, loaded
from suspid.errors import ConfigError
from suspid.infra.files import atomic_open, pyplot, save_figure, write_json, write_text
from suspid.infra.lock import open_run_dir
from suspid.infra.seeds import seed_for
from suspid.sections import W_REF_MEASURED, MonitorOptions, Scenario
from suspid.workflows.identify import IdentificationResult, run
from suspid.workflows.records import Record, key
from suspid.workflows.problem import build_problem
from suspid.workflows.report import markdown_table, trust_word

ConfigSource = str | Path | Mapping[str, Any]

STATUSES = ("ok", "warning", "out-of-domain", "not-identifiable", "not-trustworthy", "unmonitored")


# -- the monitor: section ----------------------------------------------------------------
@dataclass
class DatePlan:
    """One measurement date: its config (ready for :func:`suspid.workflows.identify.run`) and, for the scenario, its loss."""

    date: dt.date
    config: Config
    loss: float | None = None


@dataclass(kw_only=True)
class MonitorRow(Record):
    """One (date, parameter) of a monitor: the value, its interval and acceptable domain (SI), its trust and
    status (module docstring), and the truth of a numerical experiment (else None)."""

    date: str
    parameter: str
    unit: str
    value: float
    interval_low: float
    interval_high: float
    acceptable_low: float | None
    acceptable_high: float | None
    identifiable: bool
    trustworthy: str
    status: str
    w_ref: float | None


@dataclass(kw_only=True)
class MonitorScenario(Record):
    """The synthetic degradation of a monitor: the parameter, its loss at the last date, the loss per date."""

    parameter: str
    loss: float
    losses: dict[str, float]


@dataclass(kw_only=True)
class MonitorResult(Record):
    """A finished monitor: what ``monitor.json`` holds (its serialisation, versioned), its folder and each
    date's identification.

    :ivar date_labels: the dates (ISO), in order (``monitor.json``'s ``dates``).
    :ivar alerts: parameter -> the first date it left its acceptable domain.
    :ivar first_warnings: parameter -> the first date its interval overlapped an edge of the domain (or left it).
    :ivar rows: one :class:`MonitorRow` per date and parameter, in date order.
    :ivar dates: date (ISO) -> :class:`~suspid.workflows.identify.IdentificationResult` (not in the file).
    """

    SCHEMA_VERSION = 1

    name: str
    date_labels: list[str] = key("dates")
    parameters: list[str]
    reference_noise_model: str
    acceptable: dict[str, list[float | None]]
    alerts: dict[str, str]
    first_warnings: dict[str, str]
    scenario: MonitorScenario | None = key(record=MonitorScenario)
    rows: list[MonitorRow] = key(items=MonitorRow)
    monitor_dir: Path = field(default=Path("."), metadata={"json": False})
    dates: dict[str, IdentificationResult] = field(default_factory=dict, metadata={"json": False})

    @property
    def summary(self) -> dict[str, Any]:
        """The content of ``monitor.json`` (:meth:`to_json`)."""
        return self.to_json()

    @classmethod
    def load(cls, monitor_dir: str | Path) -> "MonitorResult":
        """Read a finished monitor's ``monitor.json`` and its dates' ``result.json``."""
        monitor_dir = Path(monitor_dir)
        out = cls.load_file(monitor_dir / "monitor.json", monitor_dir=monitor_dir)
        out.dates = {d: IdentificationResult.load(monitor_dir / "dates" / d) for d in out.date_labels
                     if (monitor_dir / "dates" / d / "result.json").is_file()}
        return out


def monitor_options(config: Config) -> MonitorOptions:
    """Check the (typed) ``config.monitor`` against the identified parameters and the data.

    :raises ConfigError: naming the file and the key path (``monitor.campaigns.2.date``).
    """
    where = config
    opts = config.monitor
    if opts is None:
        raise where.error("this config has no 'monitor:' section (campaigns or scenario, acceptable domains)",
                          "monitor")
    simulator = build_simulator(config)
    bounds = identified_bounds(config, simulator)
    known = {p.name: p for p in simulator.parameters()}

    if opts.reference.noise_model is not None and not opts.reference.noise_model.is_file():
        raise where.error(f"file not found: {opts.reference.noise_model}", "monitor.reference.noise_model")
    for name, (lo, hi) in opts.acceptable.items():
        key = f"monitor.acceptable.{name}"
        if name not in bounds:
            raise where.error(f"'{name}' is not an identified parameter; identified: {', '.join(bounds)}", key)
        if lo is None and hi is None:
            raise where.error("give at least one finite side: [lower, upper], null for an open side", key)
        if lo is not None and hi is not None and not lo < hi:
            raise where.error(f"lower {lo:g} must be below upper {hi:g} ({known[name].unit})", key)

    if bool(opts.campaigns) == (opts.scenario is not None):
        raise where.error("give either 'campaigns' (measurement dates) or 'scenario' (synthetic degradation)",
                         "monitor")
    if opts.campaigns:
        _check_increasing([c.date for c in opts.campaigns], where, "monitor.campaigns.{}.date")
        for i, c in enumerate(opts.campaigns):
            if "w_ref" in c.data and c.data.get("source", config.data.source) == "measured":
                raise where.error(W_REF_MEASURED,
                                 f"monitor.campaigns.{i}.data.w_ref")
    else:
        s = opts.scenario
        if config.data.source != "experiment":
            raise where.error("the scenario is a numerical experiment: the base config needs data.source: "
                             "experiment", "monitor.scenario")
        if s.parameter not in bounds:
            raise where.error(f"'{s.parameter}' is not an identified parameter; identified: {', '.join(bounds)}",
                             "monitor.scenario.parameter")
        if (s.dates is None) == (s.n_dates is None):
            raise where.error("give either 'dates' or 'n_dates' with 'start'", "monitor.scenario")
        if s.n_dates is not None and s.start is None:
            raise where.error("'n_dates' needs a 'start' date", "monitor.scenario.start")
        if s.dates is not None:
            if len(s.dates) < 2:
                raise where.error("the scenario needs at least two dates", "monitor.scenario.dates")
            _check_increasing(s.dates, where, "monitor.scenario.dates.{}")
        lo, hi = bounds[s.parameter]
        last = known[s.parameter].nominal * (1.0 - s.loss)
        if not lo <= last <= hi:
            raise where.error(f"a {100 * s.loss:g} % loss takes {s.parameter} to {last:g} {known[s.parameter].unit}, "
                             f"outside its identification bounds [{lo:g}, {hi:g}] (parameters.{s.parameter})",
                             "monitor.scenario.loss")
    measured = [c.data.get("source", config.data.source) == "measured" for c in opts.campaigns]
    if opts.reference.noise_model is None and config.noise.path is None and \
            (config.data.source != "experiment" or any(measured)):
        raise where.error("measured data need the noise model of their reference date: a noise_model.npz written "
                         "by a reference-date run", "monitor.reference.noise_model")
    return opts


def _check_increasing(dates: Sequence[dt.date], where: Config, key: str) -> None:
    for i in range(1, len(dates)):
        if not dates[i] > dates[i - 1]:
            raise where.error(f"dates must increase: {dates[i]} follows {dates[i - 1]}", key.format(i))


def scenario_dates(s: Scenario) -> list[dt.date]:
    """The scenario's dates: explicit, or ``n_dates`` from ``start`` every ``interval_days``."""
    if s.dates is not None:
        return list(s.dates)
    return [s.start + dt.timedelta(days=s.interval_days * i) for i in range(s.n_dates)]


def scenario_losses(dates: Sequence[dt.date], loss: float) -> list[float]:
    """Lost fraction at each date, linear in time from 0 at the first date to ``loss`` at the last."""
    days = np.array([(d - dates[0]).days for d in dates], dtype=float)
    return [round(float(loss * t), 12) for t in days / days[-1]]


def _flatten(mapping: Mapping[str, Any], prefix: str) -> dict[str, Any]:
    """``{track: {seed: 3}}`` -> ``{prefix.track.seed: 3}`` (so that overrides merge key by key)."""
    out: dict[str, Any] = {}
    for key, value in mapping.items():
        if isinstance(value, Mapping) and value and key != "w_ref":
            out |= _flatten(value, f"{prefix}.{key}")
        else:
            out[f"{prefix}.{key}"] = value
    return out


# -- the plan: one config per date ---------------------------------------------------------------
def reference_noise_path(config: Config, opts: MonitorOptions) -> tuple[Path, bool]:
    """Where the reference date's noise model is, and whether it is to be identified here (module docstring)."""

    if opts.reference.noise_model is not None:
        return opts.reference.noise_model, False
    if config.noise.path is not None:
        return config.noise.path, False
    return config.run_dir() / "reference" / "noise_model.npz", True


def identify_reference(source: ConfigSource, overrides: Sequence[str], config: Config, *, fresh: bool = False,
                       log: Callable[[str], None] = lambda s: None) -> Path:
    """Identify the noise model B at the reference date, once for every date (paper §2.3).

    The base config as a numerical experiment at w0 (:func:`suspid.workflows.problem.build_problem`), with its
    own ledger in ``<monitor dir>/reference/``, simulated on the config's executor; returns the
    ``noise_model.npz`` written there.
    """
    ref_dir = config.run_dir() / "reference"
    ref_cfg = loaded(source, overrides, config).with_({"monitor": None, "output.dir": str(ref_dir),
                                                       "name": f"{config.name}-reference"})
    with registry.get("executor", ref_cfg.executor.plugin)(**ref_cfg.executor.options) as executor, \
            open_run_dir(ref_dir, config_name=ref_cfg.name, config_file=ref_cfg.source_file, fresh=fresh,
                         log=log) as ledger:
        log("reference date: identifying the noise model B once for every date (paper §2.3)")
        problem = build_problem(ref_cfg, ledger, log, executor)
        return problem.noise_model.save(ref_dir / "noise_model.npz")


def monitor_dates(source: ConfigSource, overrides: Sequence[str], config: Config, opts: MonitorOptions,
                  noise_model: Path) -> list[DatePlan]:
    """The validated config of every date, in date order, all reusing ``noise_model``."""
    where = config
    simulator = build_simulator(config)
    nominal = {p.name: p.nominal for p in simulator.parameters()}
    names = list(identified_bounds(config, simulator))
    if opts.scenario is not None:
        dates = scenario_dates(opts.scenario)
        losses = scenario_losses(dates, opts.scenario.loss)
        per_date = []
        for d, loss in zip(dates, losses):
            w_ref = {n: nominal[n] for n in names}
            w_ref[opts.scenario.parameter] = nominal[opts.scenario.parameter] * (1.0 - loss)
            per_date.append((d, {"data.w_ref": w_ref}, loss, "monitor.scenario"))
    else:
        per_date = [(c.date, _flatten(c.data, "data"), None, f"monitor.campaigns.{i}.data")
                    for i, c in enumerate(opts.campaigns)]
    base_dir = config.run_dir()
    base = loaded(source, overrides, config)
    plans = []
    for d, data, loss, key in per_date:
        label = d.isoformat()
        extra = {"monitor": None, "noise.path": str(noise_model), "output.dir": str(base_dir / "dates" / label),
                 "name": f"{config.name}-{label}"}
        if data.get("data.source", config.data.source) == "experiment":
            extra["data.track.seed"] = seed_for(config.seed, f"monitor-{label}")  # own track realisations
        try:
            cfg = base.with_(extra, data)
        except ConfigError as exc:
            if exc.key and exc.key.startswith("data.") and key.startswith("monitor.campaigns"):
                raise where.error(f"{exc.detail} (date {label})", f"{key}{exc.key[len('data'):]}") from None
            raise where.error(f"{exc.detail} (date {label}, key '{exc.key}')", key) from None
        plans.append(DatePlan(d, cfg, loss))
    return plans


# -- status and alerts ---------------------------------------------------------------------------
def status_of(interval: Sequence[float], domain: Sequence[float | None] | None, identifiable: bool,
              trustworthy: bool | None = None) -> str:
    """``ok``, ``warning``, ``out-of-domain``, ``not-identifiable``, ``not-trustworthy`` or ``unmonitored``
    (module docstring).

    :param interval: ``(a, b)`` the uncertainty interval, SI units.
    :param domain: ``(lo, hi)`` the acceptable domain, ``None`` for an open side; ``None`` for no domain.
    :param trustworthy: the run's trust under model error (None: not assessed, judged by the interval).
    """
    if not identifiable:
        return "not-identifiable"
    if trustworthy is False:
        return "not-trustworthy"
    if domain is None:
        return "unmonitored"
    lo = -np.inf if domain[0] is None else domain[0]
    hi = np.inf if domain[1] is None else domain[1]
    a, b = interval
    if b < lo or a > hi:
        return "out-of-domain"
    if lo <= a and b <= hi:
        return "ok"
    return "warning"


def monitor_rows(dated: Sequence[tuple[dt.date, dict[str, Any]]],
                 acceptable: Mapping[str, Sequence[float | None]]) -> list[dict[str, Any]]:
    """One row per (date, parameter) from the dates' ``result.json`` dicts, in date order."""
    rows = []
    for d, r in dated:
        for n in r["parameters"]:
            domain = acceptable.get(n)
            rows.append({
                "date": d.isoformat(), "parameter": n, "unit": r["units"].get(n, ""),
                "value": r.get("w_corrected", r["w_opt"])[n],
                "interval_low": r["interval"][n][0], "interval_high": r["interval"][n][1],
                "acceptable_low": domain[0] if domain else None, "acceptable_high": domain[1] if domain else None,
                "identifiable": bool(r["identifiable"][n]),
                "trustworthy": trust_word(r.get("trustworthy", {}).get(n)),
                "status": status_of(r["interval"][n], domain, bool(r["identifiable"][n]),
                                    r.get("trustworthy", {}).get(n)),
                "w_ref": r["w_ref"][n] if "w_ref" in r else None,
            })
    return rows


def first_dates(rows: Sequence[Mapping[str, Any]], statuses: Sequence[str]) -> dict[str, str]:
    """Parameter -> the first date whose status is one of ``statuses`` (rows in date order)."""
    out: dict[str, str] = {}
    for row in rows:
        if row["status"] in statuses and row["parameter"] not in out:
            out[row["parameter"]] = row["date"]
    return out


# -- the run -------------------------------------------------------------------------------------
def monitor_plan(source: ConfigSource, overrides: Sequence[str], config: Config
                 ) -> tuple[MonitorOptions, Path, bool, list[DatePlan]]:
    """Every check of a monitor before any simulation: its options, and the config of every date.

    :returns: the options, the reference noise model's path, whether it is to be identified here, the dates.
    """
    opts = monitor_options(config)
    noise_model, identify = reference_noise_path(config, opts)
    return opts, noise_model, identify, monitor_dates(source, overrides, config, opts, noise_model)


def run_monitor(source: ConfigSource, overrides: Sequence[str], config: Config, *, fresh: bool = False,
                progress: bool = False, log: Callable[[str], None] = lambda s: None) -> MonitorResult:
    """Identify at every date (resuming each from its ledger), then write the monitor outputs.

    :param config: the monitor's config, loaded from ``source`` with ``overrides``.
    """
    opts, noise_model, identify, plans = monitor_plan(source, overrides, config)  # every date checked first
    if identify:
        identify_reference(source, overrides, config, fresh=fresh, log=log)
    dated, results = [], {}
    for plan in plans:
        loss = f" ({100 * plan.loss:.0f} % loss of {opts.scenario.parameter})" if plan.loss is not None else ""
        log(f"date {plan.date.isoformat()}{loss}")
        out = run(plan.config, fresh=fresh, progress=progress, log=log)
        dated.append((plan.date, out.to_dict()))
        results[plan.date.isoformat()] = out
    monitor_dir = config.run_dir()
    monitor_dir.mkdir(parents=True, exist_ok=True)
    summary = write_monitor(monitor_dir, config.name, dated, opts, noise_model,
                            {p.date.isoformat(): p.loss for p in plans if p.loss is not None})
    return MonitorResult.from_json(summary, monitor_dir=monitor_dir, dates=results)


def write_monitor(monitor_dir: Path, name: str, dated: Sequence[tuple[dt.date, dict[str, Any]]],
                  opts: MonitorOptions, noise_model: Path, losses: Mapping[str, float] | None = None) -> dict:
    """monitor.csv, monitor.json, monitor.md and one monitor_<parameter>.png per parameter.

    :returns: the monitor.json summary (:meth:`MonitorResult.to_json`).
    """
    acceptable = {n: list(v) for n, v in opts.acceptable.items()}
    rows = monitor_rows(dated, acceptable)
    names = dated[0][1]["parameters"]
    units = dated[0][1]["units"]
    alerts = first_dates(rows, ("out-of-domain",))
    warnings = first_dates(rows, ("warning", "out-of-domain"))
    with atomic_open(monitor_dir / "monitor.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows({k: "" if v is None else v for k, v in row.items()} for row in rows)
    summary = MonitorResult(
        name=name, date_labels=[d.isoformat() for d, _ in dated], parameters=names,
        reference_noise_model=str(noise_model), acceptable=acceptable, alerts=alerts, first_warnings=warnings,
        scenario=None if opts.scenario is None else MonitorScenario(
            parameter=opts.scenario.parameter, loss=opts.scenario.loss, losses=dict(losses or {})),
        rows=[MonitorRow(**r) for r in rows]).to_json()
    write_json(monitor_dir / "monitor.json", summary)

    figures = [figure_monitor(monitor_dir / f"monitor_{n}.png", n, units.get(n, ""),
                              [r for r in rows if r["parameter"] == n], alerts.get(n)) for n in names]

    def domain_text(n: str) -> str:
        if n not in acceptable:
            return "none (unmonitored)"
        lo, hi = acceptable[n]
        return f"[{'-∞' if lo is None else f'{lo:.4g}'}, {'+∞' if hi is None else f'{hi:.4g}'}] {units.get(n, '')}"

    lines = [f"# Monitor `{name}`", "",
             f"{len(dated)} dates from {dated[0][0]} to {dated[-1][0]}; the noise model of the reference date, "
             f"`{noise_model}`, is reused at every date (paper §2.3).", ""]
    if opts.scenario is not None:
        lines += [f"Synthetic degradation scenario: `{opts.scenario.parameter}` loses "
                  f"{100 * opts.scenario.loss:g} % of its nominal value linearly in time, the other parameters "
                  f"stay nominal; every date has its own track realisations.", ""]
    lines += ["## Alerts", ""]
    if alerts:
        for n, d in alerts.items():
            row = next(r for r in rows if r["parameter"] == n and r["date"] == d)
            lines.append(f"- **`{n}` out of its acceptable domain {domain_text(n)} on {d}**: interval "
                         f"[{row['interval_low']:.4g}, {row['interval_high']:.4g}]; first warning on {warnings[n]}. "
                         f"Maintenance is due.")
    else:
        lines.append("- none: no identified parameter has left its acceptable domain.")
    pending = [n for n in warnings if n not in alerts]
    for n in pending:
        lines.append(f"- `{n}`: warning since {warnings[n]} (its interval overlaps an edge of {domain_text(n)}).")
    lines += ["", "## Acceptable domains", "",
              markdown_table(["parameter", "acceptable domain"], [[f"`{n}`", domain_text(n)] for n in names]),
              "", "## Per date", "",
              "Each cell: identified value, uncertainty interval and status. `not-identifiable` and "
              "`not-trustworthy` values are not findings and are never flagged.", "", trust_summary(rows), ""]
    header = ["date"] + (["loss"] if losses else []) + [f"{n} ({units.get(n, '')})" for n in names]
    table = []
    for d, r in dated:
        cells = [d.isoformat()] + ([f"{100 * losses[d.isoformat()]:.0f} %"] if losses else [])
        for n in names:
            row = next(x for x in rows if x["parameter"] == n and x["date"] == d.isoformat())
            status = row["status"] if row["status"] in ("ok", "unmonitored") else f"**{row['status']}**"
            cells.append(f"{row['value']:.4g} [{row['interval_low']:.4g}, {row['interval_high']:.4g}] {status}")
        table.append(cells)
    lines += [markdown_table(header, table), "", "## Time evolution", ""]
    lines += [f"![{n}]({f.name})" for n, f in zip(names, figures)]
    write_text(monitor_dir / "monitor.md", "\n".join(lines) + "\n")
    return summary


def trust_summary(rows: Sequence[Mapping[str, Any]]) -> str:
    """One sentence: how many (date, parameter) values are trustworthy under model error, not, or not assessed."""
    counts = {w: sum(r["trustworthy"] == w for r in rows) for w in ("yes", "no", "not assessed")}
    text = (f"Trust under model error (the dates' model-error checks): yes for {counts['yes']}, no for "
            f"{counts['no']}, not assessed for {counts['not assessed']} of the {len(rows)} values")
    if counts["not assessed"]:
        text += (" (the checks that would judge them did not run, e.g. on the reference date's noise model "
                 "without its data: each date's report.md says which ran)")
    return text + "."


_COLOURS = {"ok": "tab:green", "warning": "tab:orange", "out-of-domain": "tab:red",
            "not-identifiable": "0.55", "not-trustworthy": "0.55", "unmonitored": "tab:blue"}


def figure_monitor(path: Path, name: str, unit: str, rows: Sequence[Mapping[str, Any]],
                   alert: str | None = None) -> Path:
    """Time evolution of one parameter: value and interval per date, acceptable domain shaded.

    :param rows: this parameter's rows of :func:`monitor_rows`, in date order.
    :param alert: the alert date (ISO), drawn as a vertical line.
    """
    plt = pyplot()
    dates = [dt.date.fromisoformat(r["date"]) for r in rows]
    value = np.array([r["value"] for r in rows])
    lo_i = np.array([r["interval_low"] for r in rows])
    hi_i = np.array([r["interval_high"] for r in rows])
    fig, ax = plt.subplots(figsize=(8, 4))
    lo, hi = rows[0]["acceptable_low"], rows[0]["acceptable_high"]
    if lo is not None or hi is not None:
        span = [v for v in (*lo_i, *hi_i, *(x for x in (lo, hi) if x is not None)) if np.isfinite(v)]
        pad = 0.15 * (max(span) - min(span) or abs(max(span)) or 1.0)
        ax.set_ylim(min(span) - pad, max(span) + pad)
        bottom, top = ax.get_ylim()
        ax.axhspan(bottom if lo is None else lo, top if hi is None else hi, color="tab:green", alpha=0.12,
                   lw=0, label="acceptable domain")
        for edge in (lo, hi):
            if edge is not None:
                ax.axhline(edge, color="tab:green", lw=1, ls="--")
    if any(r["w_ref"] is not None for r in rows):
        ax.plot(dates, [np.nan if r["w_ref"] is None else r["w_ref"] for r in rows], "s--", color="black",
                ms=5, mfc="none", lw=0.8, zorder=2, label="w_ref (true value)")
    for status in STATUSES:
        idx = [i for i, r in enumerate(rows) if r["status"] == status]
        if not idx:
            continue
        hollow = status in ("not-identifiable", "not-trustworthy")
        yerr = np.maximum([value[idx] - lo_i[idx], hi_i[idx] - value[idx]], 0.0)
        ax.errorbar([dates[i] for i in idx], value[idx], yerr=yerr,
                    fmt="o", ms=7, capsize=4, color=_COLOURS[status], mfc="white" if hollow else _COLOURS[status],
                    label=f"w_opt and interval: {status}", zorder=3)
    if alert is not None:
        ax.axvline(dt.date.fromisoformat(alert), color="tab:red", ls=":", lw=1.5, label=f"alert {alert}")
    ax.set_title(f"{name}: identified value per date")
    ax.set_ylabel(f"{name} ({unit})" if unit else name)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.autofmt_xdate()
    fig.tight_layout()
    return save_figure(fig, path)
