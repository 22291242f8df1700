"""The ``suspid`` command line.

User mistakes (a :class:`~suspid.errors.SuspidError`) print one line on stderr
and exit with code 2; ``--debug`` shows the traceback instead. Ctrl-C exits
with code 130 and keeps what is already in the run ledger (``ingest``, which
has none, says that the output folder keeps the previous ingest).
"""

from __future__ import annotations

import dataclasses
import errno
import importlib.util
import json
import sqlite3
import sys
import warnings
from contextlib import contextmanager
from pathlib import Path
from types import ModuleType
from typing import List, Optional

import click
import typer
from rich import box
from rich.console import Console
from rich.measure import Measurement
from rich.table import Table
from rich.text import Text  # cells as Text: element groups (c_yaw[bogie1]) are not markup

import suspid
from suspid import registry
from suspid.errors import ConfigError, SuspidError


def _lazy(name: str) -> ModuleType:
    """The module ``name``, executed on its first attribute access (importlib's ``LazyLoader``).

    The workflows import numpy, scipy, GPy and matplotlib (seconds); a command
    pays for them when it runs, ``suspid --help`` and ``--version`` do not.
    """
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    spec.loader = importlib.util.LazyLoader(spec.loader)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


api = _lazy("suspid.api")
_report = _lazy("suspid.workflows.report")
_simulate = _lazy("suspid.workflows.simulate")
_verdict = _lazy("suspid.workflows.verdict")

app = typer.Typer(add_completion=False, no_args_is_help=True, pretty_exceptions_enable=False, rich_markup_mode=None,
                  help="Identify train suspension parameters from on-track accelerations.")
# rich_markup_mode=None: click's plain help, whose metavars are words (:data:`METAVARS`), not typer's <list[str]>
console = Console(soft_wrap=True)

ConfigArg = typer.Argument(..., help="YAML config file.", show_default=False)
SetOpt = typer.Option(None, "--set", help="Override a config value: key.path=value (repeatable).")
StrictOpt = typer.Option(False, "--strict", help="Unusual measured data (higher vibration or speed than usual) "
                                                 "are errors, not warnings (data.strict).")


def _overrides(set_: Optional[List[str]], strict: bool) -> list[str]:
    return [*(set_ or []), *(["data.strict=true"] if strict else [])]


def _version(value: bool) -> None:
    if value:
        console.print(f"suspid {suspid.__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print the version and exit."),
          debug: bool = typer.Option(False, "--debug", help="Show tracebacks of errors.")) -> None:
    """suspid: EGO identification of train suspension parameters (see README)."""


@app.command()
def plugins() -> None:
    """List every plugin: kind, name, entry point, distribution, version, module."""
    rows, failures = registry.plugins()
    if not console.is_terminal:
        console.width = 240  # keep rows whole when piped
    table = Table(title="suspid plugins")
    for col in ("kind", "name", "entry point", "distribution", "version", "module"):
        table.add_column(col)
    for r in rows:
        table.add_row(r.kind, r.name, r.plugin.name, r.plugin.distribution or "-", r.plugin.version or "-",
                      f"{r.cls.__module__}.{r.cls.__qualname__}")
    for f in failures:
        table.add_row("[red]broken[/red]", "-", f.name, f.distribution or "-", f.version or "-",
                      f"{f.module}: {f.error}")
    console.print(table)


@app.command()
def validate(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt, strict: bool = StrictOpt) -> None:
    """Check a config (every section, plugins' options, parameters, data files, study/monitor/diagnose); exit 0 when valid.

    Everything that needs no simulation is checked: what this accepts, run will not reject for the config's sake.
    """
    checked = api.validate(config, _overrides(set_, strict))
    cfg = checked.config
    data = f", {checked.n_measured_segments} measured segments" if checked.n_measured_segments else ""
    console.print(f"{config}: valid (simulator {cfg.simulator.plugin}, objective {cfg.objective.plugin}, "
                  f"surrogate {cfg.surrogate.plugin}, optimizer {cfg.optimizer.plugin}, "
                  f"executor {cfg.executor.plugin}{data})")
    for note in cfg._notes:
        console.print(f"note: {note}", markup=False, highlight=False)


@app.command()
def run(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt,
        fresh: bool = typer.Option(False, "--fresh", help="Start over: forget the run's ledger."),
        retry_failed: bool = typer.Option(False, "--retry-failed",
                                          help="Simulate again the points whose simulation failed before."),
        force: bool = typer.Option(False, "--force", help="Take over a run directory that holds another "
                                                          "config's run."),
        strict: bool = StrictOpt,
        quiet: bool = typer.Option(False, "--quiet", help="No progress bars.")) -> None:
    """Identify the parameters: design, Kriging, EGO; writes result.json and report.md in the run directory.

    Interrupt with Ctrl-C at any time; running the same command again resumes
    from the ledger without recomputing finished simulations.
    """
    out = api.identify(config, _overrides(set_, strict), fresh=fresh, progress=not quiet, log=_log(quiet),
                       retry_failed=retry_failed, force=force)
    _print_result(out.to_dict(), out.run_dir)


@app.command()
def monitor(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt,
            fresh: bool = typer.Option(False, "--fresh", help="Start every date (and the reference date) over."),
            quiet: bool = typer.Option(False, "--quiet", help="No progress bars.")) -> None:
    """Identify at every date of the config's monitor: section and flag parameters leaving their acceptable domain.

    Writes monitor.csv, monitor.json, monitor.md and a plot per parameter. The
    noise model of the reference date is reused at every date; each date runs
    in <run dir>/dates/<date>/ with its own ledger, so running again resumes.
    """
    out = api.monitor(config, set_ or [], fresh=fresh, progress=not quiet, log=_log(quiet))
    console.print((out.monitor_dir / "monitor.md").read_text(encoding="utf-8"), markup=False, highlight=False)


@app.command()
def diagnose(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt,
             fresh: bool = typer.Option(False, "--fresh", help="Start the identifications over."),
             quiet: bool = typer.Option(False, "--quiet", help="No progress bars.")) -> None:
    """Find where model and measurements disagree, name the missing effect, add it and show the gap shrink.

    Writes diagnosis.json, diagnosis.md (with PNG maps), augmented.yaml and the
    identifications before/ and after/ in the run directory; see docs/diagnose.md.
    """
    out = api.diagnose(config, set_ or [], fresh=fresh, progress=not quiet, log=_log(quiet))
    console.print((out.out_dir / "diagnosis.md").read_text(encoding="utf-8"), markup=False, highlight=False)


def _parse_params(items: list[str] | None) -> dict[str, float]:
    """``--param name=value`` items as a mapping (names are checked against the simulator by the API)."""
    out = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ConfigError("expected name=value", option=f"--param {item}")
        try:
            out[name] = float(value)
        except ValueError:
            raise ConfigError(f"'{value}' is not a number", option=f"--param {item}") from None
    return out


@contextmanager
def _options_named(options: dict[str, str]):
    """Inside, an API error about one of its arguments (``ConfigError.key``: ``w.c_yaw``, ``speed_mps``) names
    the command-line option the value came from (``options``: key -> ``--param c_yaw=1``), not a config line."""
    try:
        yield
    except ConfigError as exc:
        if exc.key in options and exc.file is None:
            raise ConfigError(exc.detail, option=options[exc.key]) from None
        raise


@app.command()
def simulate(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt,
             out: Optional[Path] = typer.Option(None, "--out", help="Output folder (default: <run dir>/simulation)."),
             param: Optional[List[str]] = typer.Option(None, "--param", help="name=value in SI units (repeatable); "
                                                       "other parameters nominal.")) -> None:
    """Simulate the nominal (or given) parameters on the configured segments; writes simulation.h5 and a PNG."""
    w = _parse_params(param)
    with _options_named({f"w.{item.partition('=')[0]}": f"--param {item}" for item in param or []}):
        path = api.simulate(config, set_ or [], w=w, out_dir=out)
    console.print(f"wrote {path} and {path.parent / 'spectra.png'}")


@app.command()
def observability(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt,
                  quiet: bool = typer.Option(False, "--quiet", help="No progress lines.")) -> None:
    """Which element groups the sensors separate, which only as a sum, and which extra channel would help.

    Writes observability.json in the run directory (the config's localisation: section sets the kinds,
    the change judged and the χ² threshold).
    """
    out = api.observability(config, set_ or [], log=_log(quiet))
    console.print(out.table(), markup=False, highlight=False)
    console.print(f"wrote {out.path}")


@app.command()
def modes(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt,
          speed_kmh: Optional[float] = typer.Option(None, "--speed-kmh", help="Speed (default: the simulator's)."),
          out: Optional[Path] = typer.Option(None, "--out", help="Folder of modes.json (default: the run dir)."),
          max_hz: float = typer.Option(20.0, "--max-hz", help="Print modes up to this frequency.")) -> None:
    """Eigenmodes at the configured speed: frequency, damping ratio, body and motion; writes modes.json."""
    with _options_named({"speed_mps": f"--speed-kmh {speed_kmh:g}" if speed_kmh is not None else ""}):
        report = api.modes(config, set_ or [], speed_mps=None if speed_kmh is None else speed_kmh / 3.6,
                           out_dir=out)
    console.print(_simulate.format_modes(report, max_hz), markup=False, highlight=False)
    where = out if out is not None else api.load_config(config, set_ or []).run_dir()
    console.print(f"stable: {str(report['stable']).lower()}; wrote {Path(where) / 'modes.json'}")


@app.command()
def stability(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt,
              n_points: int = typer.Option(3, "--points", min=2, help="Values per parameter over its bounds."),
              out: Optional[Path] = typer.Option(None, "--out", help="Folder of stability.json (default: the run dir).")
              ) -> None:
    """Linear critical speed of the train model, against conicity and each identified parameter over its bounds."""
    report = api.stability(config, set_ or [], n_points=n_points, out_dir=out)
    console.print(_simulate.format_stability(report), markup=False, highlight=False)


@app.command()
def study(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt,
          fresh: bool = typer.Option(False, "--fresh", help="Start every variant over."),
          quiet: bool = typer.Option(False, "--quiet", help="No progress bars."),
          report_only: bool = typer.Option(False, "--report-only",
                                           help="Run nothing: the outputs from the variants that have finished.")
          ) -> None:
    """Run the variants of the config's study: section, once per seed; study.csv (over seeds), study_runs.csv, study.md."""
    out = api.study(config, set_ or [], fresh=fresh, progress=not quiet, log=_log(quiet), report_only=report_only)
    console.print((out.study_dir / "study.md").read_text(encoding="utf-8"))


@app.command()
def ingest(ingest_file: Path = typer.Argument(..., help="Ingest YAML file (docs/ingest.md).", show_default=False),
           set_: Optional[List[str]] = SetOpt,
           out: Optional[Path] = typer.Option(None, "--out", help="Output folder (default: the file's output.dir)."),
           quiet: bool = typer.Option(False, "--quiet", help="No progress lines."),
           strict: bool = typer.Option(False, "--strict", help="Refuse a static 1 g on a vertical channel "
                                       "instead of removing it (quality.strict).")) -> None:
    """Cut a long recording (mf4, mat, tdms, csv, hdf5) into segments: units, track alignment, quality report."""
    global _interrupted_note
    where = str(out) if out is not None else "the output folder"
    _interrupted_note = (f"ingest keeps no partial work (it has no ledger): {where} still holds the segments "
                         f"and reports of the previous ingest, if any; run the same command to ingest again")
    r = api.ingest(ingest_file, [*(set_ or []), *(["quality.strict=true"] if strict else [])], out_dir=out,
                   log=_log(quiet))
    dates = (("reference date: ", r.reference), ("measurement date: ", r)) if r.reference else (("", r),)
    for date, res in dates:
        for w in res.warnings:
            print(f"warning: {date}{w}", file=sys.stderr)
    for date, res in dates:
        console.print(f"{date}{len(res.segments)} segments, offset {res.offset_m:.2f} m (peak ratio "
                      f"{res.peak_ratio:.2f}); data.track_file: {res.track_path}, data.measurements: "
                      f"{res.measurements_path}; report: {res.out_dir / 'ingest.md'}", markup=False, highlight=False)
    if r.config_path is not None:
        for w in r.config_warnings:
            print(f"warning: {w}", file=sys.stderr)
        console.print(f"two-date config: {r.config_path} (suspid validate {r.config_path}; suspid run "
                      f"{r.config_path})", markup=False, highlight=False)


fleet_app = typer.Typer(no_args_is_help=True, rich_markup_mode=None,
                        help="The fleet's monitoring database (docs/fleet.md).")
app.add_typer(fleet_app, name="fleet")


@fleet_app.command("import")
def fleet_import(folders: List[Path] = typer.Argument(..., help="monitor or run folders", show_default=False),
                 db: str = typer.Option(..., "--db", help="SQLite path or database URL (postgresql://...)."),
                 fleet: str = typer.Option("fleet", "--fleet"),
                 trainset: str = typer.Option(..., "--trainset"),
                 vehicle: str = typer.Option("car1", "--vehicle"),
                 date: Optional[str] = typer.Option(None, "--date", help="date of a run folder (YYYY-MM-DD)."),
                 mileage_km: Optional[float] = typer.Option(None, "--mileage-km",
                                                            help="mileage at the (first) date."),
                 km_per_day: Optional[float] = typer.Option(None, "--km-per-day",
                                                            help="mileage per day between a monitor's dates."),
                 no_indicators: bool = typer.Option(False, "--no-indicators", help="Do not compute indicators."),
                 quiet: bool = typer.Option(False, "--quiet", help="No progress lines.")) -> None:
    """Record existing monitor folders (every date) or run folders into the monitoring database."""
    import datetime as dt
    try:
        day = None if date is None else dt.date.fromisoformat(date)
    except ValueError:
        raise ConfigError(f"--date: '{date}' is not a date YYYY-MM-DD") from None
    out = api.fleet_import(db, folders, fleet=fleet, trainset=trainset, vehicle=vehicle, date=day,
                           mileage_km=mileage_km, km_per_day=km_per_day, indicators=not no_indicators,
                           log=_log(quiet))
    console.print(f"{out.n_created} runs recorded, {len(out.runs) - out.n_created} already there", markup=False)


@fleet_app.command("upgrade")
def fleet_upgrade(db: str = typer.Option(..., "--db", help="SQLite path or database URL (postgresql://...)."),
                  quiet: bool = typer.Option(False, "--quiet", help="No progress lines.")) -> None:
    """Upgrade a monitoring database's schema to this suspid's (back a PostgreSQL one up first: pg_dump)."""
    api.fleet_upgrade(db, log=_log(quiet))
    console.print("the database's schema is this suspid's newest", markup=False)


@fleet_app.command("demo")
def fleet_demo(plan: Path = typer.Argument(..., help="Fleet plan (configs/fleet-demo.yaml).", show_default=False),
               serve: bool = typer.Option(True, "--serve/--no-serve", help="Start the dashboard afterwards."),
               port: int = typer.Option(8050, "--port"),
               quiet: bool = typer.Option(False, "--quiet", help="No progress lines.")) -> None:
    """Monitor a small demo fleet into its database, check its degrading elements, then serve the dashboard."""
    out = api.fleet_demo(plan, log=_log(quiet))
    console.print((out.out_dir / "fleet-demo.md").read_text(encoding="utf-8"), markup=False, highlight=False)
    if serve:
        api.dashboard(out.database, port=port, log=_log(False))


def _levels(v) -> str:
    """``4.52 / 5.65``: the warning and alarm levels an indicator value was judged against."""
    w, a = v.detail.get("warning_level"), v.detail.get("alarm_level")
    return "no bogie mass" if a is None else f"{w:.3g} / {a:.3g}"


@app.command()
def indicators(config: Path = ConfigArg, set_: Optional[List[str]] = SetOpt,
               out: Optional[Path] = typer.Option(None, "--out", metavar="DIR",
                                                  help="Also write indicators.json and indicators.csv there.")
               ) -> None:
    """EN 14363 bogie-frame instability and EN 12299 comfort of the config's recordings, per segment and run."""
    values, rec = api.indicators(config, set_ or [], out_dir=out)
    if not console.is_terminal:
        console.width = 200  # keep rows whole when piped
    table = Table(title="indicators")
    for col in ("indicator", "segment", "value", "warning / alarm", "f0", "verdict"):
        table.add_column(col)
    for v in values:
        f0 = v.detail.get("f0_hz")
        table.add_row(v.name, v.segment or "[b]run[/b]", f"{v.value:.3g}" + ("" if v.unit == "-" else f" {v.unit}"),
                      _levels(v), "-" if f0 is None else f"{f0:.2f} Hz", v.verdict)
    console.print(table)
    inst = next((v for v in values if v.detail.get("bogie_mass_kg") is not None), None)
    if inst is not None:
        console.print(f"EN 14363 limit (12 - m_b / 5) / 2 = {inst.detail['alarm_level']:.3g} m/s^2 from the bogie "
                      f"mass m_b = {inst.detail['bogie_mass_kg']:g} kg; band f0 +- 2 Hz, f0: "
                      f"{inst.detail['hunting_hz_source']} (fleet.hunting_hz sets it); EN 12299 N_MV: warning from "
                      f"2 (medium), alarm from 4 (uncomfortable)", markup=False, highlight=False)
    if out is not None:
        console.print(f"wrote {out / 'indicators.json'} and {out / 'indicators.csv'}", markup=False, highlight=False)
    if rec is not None:
        console.print(f"recorded as run {rec.run_id} in the monitoring database", markup=False)


def _elements_text(groups: tuple[str, ...]) -> str:
    """``4 at bogie1/bogie2, left/right``: how many elements a parameter sets, and where they sit."""
    if not groups:
        return "-"
    tags = [g[g.index("[") + 1:-1].split(",") for g in groups]
    places = [list(dict.fromkeys(t[i] for t in tags if len(t) > i)) for i in range(max(map(len, tags)))]
    return f"{len(groups)} at " + ", ".join("/".join(p) for p in places)


@app.command("parameters")
def parameters_(config: Optional[Path] = typer.Argument(None, show_default=False,
                                                        help="YAML config: its simulator, and what it identifies."),
                set_: Optional[List[str]] = SetOpt,
                simulator: Optional[str] = typer.Option(None, "--simulator", metavar="NAME",
                                                        help="A simulator's registered name, without a config "
                                                             "(default: exudyn-train; `suspid plugins` lists them)."),
                as_json: bool = typer.Option(False, "--json", help="JSON on stdout (every field, the descriptions "
                                                                   "with their sources)."),
                identified_only: bool = typer.Option(False, "--identified", help="Only the parameters the config "
                                                                                 "identifies.")) -> None:
    """A simulator's parameters: description, unit, nominal value, bounds, the elements each sets; with a config,
    the ones it identifies and within which bounds (SI units)."""
    with _options_named({"simulator": f"--simulator {simulator}"}):
        rows = api.parameters(config, set_ or [], simulator=simulator)
    if identified_only:
        rows = [p for p in rows if p.identified is not None]
    if as_json:
        print(json.dumps([dataclasses.asdict(p) for p in rows], indent=2))
        return
    if not console.is_terminal:
        console.width = 200  # keep rows whole when piped
    table = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False)
    for col in ("parameter", "description", "unit", "nominal", "bounds", "elements",
                *(["identified within"] if config else [])):
        table.add_column(Text(col), no_wrap=col != "description")
    for p in rows:
        ident = [] if config is None else ["-" if p.identified is None else
                                           f"{p.identified[0]:.6g} to {p.identified[1]:.6g}"]
        table.add_row(*map(Text, [p.name, _verdict.short_description(p.description), p.unit, f"{p.nominal:.6g}",
                                  f"{p.lower:.6g} to {p.upper:.6g}", _elements_text(p.elements), *ident]))
    console.print(table)


@app.command()
def dashboard(db: str = typer.Option(..., "--db", help="SQLite path or database URL (postgresql://...)."),
              host: str = typer.Option("127.0.0.1", "--host", help="Address to bind (default: this machine only)."),
              port: int = typer.Option(8050, "--port"),
              allow_ack: bool = typer.Option(False, "--allow-ack", help="Let the database's users (suspid fleet user "
                                                                        "add) log in and acknowledge alarms."),
              create: bool = typer.Option(False, "--create", help="Make the SQLite database if it does not exist.")
              ) -> None:
    """Serve the fleet dashboard: overview, trainset trends and forecasts, runs, alarms, CSV/JSON export."""
    api.dashboard(db, host=host, port=port, allow_ack=allow_ack, create=create, log=_log(False),
                  warn=lambda s: print(s, file=sys.stderr))


user_app = typer.Typer(no_args_is_help=True, help="Users who may acknowledge alarms on the dashboard.")
fleet_app.add_typer(user_app, name="user")
DbOpt = typer.Option(..., "--db", help="The monitoring database (SQLite path or database URL).")


def _read_password(name: str, from_stdin: bool) -> str:
    """The new user's password: one line of standard input (``--password-stdin``, or input that is not a
    terminal), else typed twice without echo."""
    import getpass

    if from_stdin or not sys.stdin.isatty():
        return sys.stdin.readline().rstrip("\r\n")
    first = getpass.getpass(f"password for {name}: ")
    if getpass.getpass("again: ") != first:
        raise ConfigError(f"user {name}: the two passwords differ; nothing was changed")
    return first


@user_app.command("add")
def user_add(name: str = typer.Argument(..., help="The user's name.", show_default=False), db: str = DbOpt,
             password_stdin: bool = typer.Option(False, "--password-stdin",
                                                 help="Read the password from standard input (one line).")) -> None:
    """Add a user who may acknowledge alarms (the password is asked without echo, or read from stdin)."""
    from suspid.fleet.users import check_name

    check_name(name)
    api.fleet_user("add", db, name, _read_password(name, password_stdin))
    console.print(f"user {name} added: may log in to a dashboard started with --allow-ack", markup=False)


@user_app.command("remove")
def user_remove(name: str = typer.Argument(..., help="The user's name.", show_default=False),
                db: str = DbOpt) -> None:
    """Take away a user's right to acknowledge (their past acknowledgements keep their name)."""
    api.fleet_user("remove", db, name)
    console.print(f"user {name} removed", markup=False)


@user_app.command("list")
def user_list(db: str = DbOpt) -> None:
    """The users who may acknowledge alarms (and those removed)."""
    for u in api.fleet_user("list", db):
        print(f"{u.name}\t{'active' if u.active else 'removed'}\tadded {u.created_at} UTC")


def _log(quiet: bool):
    """Progress messages of a command: dimmed lines on the console, none with --quiet."""
    return (lambda s: None) if quiet else (lambda s: console.print(f"[dim]{s}[/dim]"))


_STYLE = {"no": "red", "not assessed": "yellow", "not identifiable": "dim", "warning": "yellow",
          "warning (borderline)": "yellow", "alarm": "bold red", "alarm (borderline)": "bold red",
          "not assessable": "dim"}
"""Styles of the verdict table's trust and verdict cells."""


def _verdict_table(rows, with_reference: bool, with_nominal: bool) -> Table:
    """The verdict table (verdict first; :func:`suspid.workflows.verdict.terminal_table`) as a rich table
    without vertical rules: every column's content on one line, nothing truncated."""
    header, cells = _verdict.terminal_table(rows, with_reference=with_reference, with_nominal=with_nominal)
    table = Table(box=box.SIMPLE_HEAD, show_edge=False, pad_edge=False, collapse_padding=True)
    for col in header:
        table.add_column(Text(col), no_wrap=True)
    for row in cells:
        table.add_row(*[Text(c, style=_STYLE.get(c, "")) if h in ("trust", "verdict") else Text(c)
                        for h, c in zip(header, row)])
    return table


def _print_verdicts(result: dict) -> None:
    """The verdict table at the console's width: with the nominal values where they fit, without them where
    they do not, else (below about 100 columns for the quickstart) a few lines per parameter."""
    rows = _verdict.rows_of(result)
    if not rows:
        return
    for with_nominal in (True, False):
        table = _verdict_table(rows, "w_ref" in result, with_nominal)
        natural = Measurement.get(console, console.options.update_width(10_000), table).maximum  # unclamped
        if natural <= console.width:
            console.print(table)
            return
    for line in _verdict.vertical_lines(rows):
        console.print(line, markup=False, highlight=False)


def _print_result(result: dict, run_dir: Path) -> None:
    stop = result["stop_reason"]
    if result.get("refine_stop_reason"):
        stop += f", then {result['n_refine_iterations']} refinement steps: {result['refine_stop_reason']}"
    if not console.is_terminal:
        console.width = 200  # keep rows whole when piped
    n, new = result["n_simulator_calls"], result.get("n_simulator_calls_this_session")
    reused = ", none new: all reused from the ledger" if new == 0 and n else ""
    console.print(f"{result['name']}: J_max = {result['J_max']:.6g} ({stop}, {n} simulations{reused}, "
                  f"{result['wall_time_s']:.0f} s)", markup=False, highlight=False)
    _print_verdicts(result)
    for r in _verdict.rows_of(result):
        console.print(_verdict.summary_line(r, markdown=False), markup=False, highlight=False)
    checks = _report.checks_line(result)
    if checks:
        console.print(checks, markup=False, highlight=False)
    unchanged = _report.no_change_line(result)
    if unchanged:
        console.print(unchanged, markup=False, highlight=False)
    kept = f" (run {result['run_id']}, kept in {run_dir / 'history' / result['run_id']})" if "run_id" in result else ""
    console.print(f"results: {run_dir / 'result.json'}, report: {run_dir / 'report.md'}{kept}")


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"warning: {message}", file=sys.stderr)


def _one_line(exc: BaseException) -> tuple[str, int]:
    """The one-line message and exit code of an error that ended a command.

    suspid's own errors say what went wrong (exit 2, or 1 for a plugin's bug);
    the operating system's (a path, a full disk, permissions), SQLite's and
    memory errors are user-side conditions (exit 2); an exception raised inside
    a plugin's code is the plugin's bug, reported with its name and
    distribution (exit 1); anything else is a bug of suspid (exit 1).
    """
    if isinstance(exc, SuspidError):
        return str(exc), exc.exit_code
    what = f"{type(exc).__name__}: {exc}"
    if isinstance(exc, OSError):
        where = " -> ".join(str(p) for p in (exc.filename, exc.filename2) if p is not None)
        return f"{where + ': ' if where else ''}{exc.strerror or exc}" + (
            " (disk full?)" if exc.errno == errno.ENOSPC else ""), 2
    if isinstance(exc, sqlite3.Error):
        return f"run ledger: {exc} (disk full, read-only folder or a damaged ledger.sqlite; "\
               f"--fresh starts over)", 2
    if isinstance(exc, MemoryError):
        return "out of memory: reduce the sizes in the config (segments, n_initial, n_freqs)", 2
    if isinstance(exc, RecursionError):
        return "input nested too deeply (recursion limit)", 2
    modules, tb = [], exc.__traceback__
    while tb is not None:
        modules.append(tb.tb_frame.f_globals.get("__name__", ""))
        tb = tb.tb_next
    row = registry.provider_of(modules)
    if row is not None:
        return (f"{registry.describe(row.kind, row.name)} failed: {what} "
                f"(a bug in the plugin; --debug shows the traceback)"), 1
    return f"internal error: {what} (a bug in suspid; --debug shows the traceback)", 1


def _click_exceptions() -> dict[str, tuple[type, ...]]:
    """click's Exit, ClickException and Abort, with typer's own classes of the same names.

    Recent typer versions parse the command line with a vendored copy of click
    (``typer._click``), whose usage errors (unknown command or option, missing
    argument) are not ``click.ClickException``, and raise their own ``Exit``/``Abort``.
    """
    modules = [click.exceptions, typer.exceptions]
    try:
        from typer._click import exceptions as vendored   # typer's private copy, when it has one
        modules.append(vendored)
    except ImportError:
        pass
    return {name: tuple({getattr(m, name) for m in modules if hasattr(m, name)})
            for name in ("Exit", "ClickException", "Abort")}


_CLICK = _click_exceptions()


METAVARS = {"set_": "KEY=VALUE", "param": "NAME=VALUE", "out": "DIR", "db": "PATH|URL", "host": "ADDRESS",
            "port": "PORT", "speed_kmh": "KM/H", "max_hz": "HZ", "n_points": "N", "fleet": "NAME",
            "trainset": "NAME", "vehicle": "NAME", "date": "YYYY-MM-DD", "mileage_km": "KM", "km_per_day": "KM",
            "simulator": "NAME", "config": "CONFIG", "ingest_file": "INGEST.yaml", "plan": "PLAN.yaml",
            "folders": "FOLDER"}
"""Help metavars in words (``--set KEY=VALUE``, ``--out DIR``), by parameter name; others by type (N, NUMBER,
TEXT, PATH); a flag takes none."""
_TYPE_WORDS = {"integer": "N", "float": "NUMBER", "text": "TEXT", "path": "PATH"}


def _command() -> click.Command:
    """The click command of :data:`app` with the help's metavars in words a user knows (:data:`METAVARS`)
    instead of typer's Python types (``<list[str]>``, ``<bool>``)."""
    command = typer.main.get_command(app)

    def name(cmd) -> None:
        for p in cmd.params:
            if isinstance(p, click.Argument) or getattr(p, "param_type_name", "") == "argument":
                # the name says what it is (CONFIG, FOLDER...); typer would add its Python type (<list[Path]>)
                # and braces in the usage line: both set on the instance, typer's classes are left as they are
                p.display_type_rich = lambda ctx=None: None
                p.metavar = shown = p.metavar or METAVARS.get(p.name, p.name.upper())
                p._usage_display_name = lambda shown=shown, p=p: (shown if p.required else f"[{shown}]") + (
                    "..." if p.nargs != 1 else "")
                continue
            if p.metavar is not None:
                continue
            if getattr(p, "is_flag", False):
                p.metavar = ""
            elif p.name in METAVARS:
                p.metavar = METAVARS[p.name]
            elif getattr(p.type, "name", "") in _TYPE_WORDS:
                p.metavar = _TYPE_WORDS[p.type.name]
        for sub in getattr(cmd, "commands", {}).values():
            name(sub)

    name(command)
    return command


_interrupted_note: str | None = None
"""What an interrupted command keeps, set by a command without a ledger (``ingest``); else :func:`_kept`."""


def _kept() -> str:
    """What an interrupted command leaves: the finished simulations in the ledgers it opened."""
    from suspid.infra.ledger import count_finished
    from suspid.infra.lock import OPENED_LEDGERS

    counts = [n for n in map(count_finished, OPENED_LEDGERS) if n is not None]
    if not counts:
        return "every finished simulation is kept in the run ledger"
    where = OPENED_LEDGERS[0] if len(OPENED_LEDGERS) == 1 else f"{len(OPENED_LEDGERS)} run ledgers"
    return f"{sum(counts)} finished simulations are kept in {where}"


def main(argv: list[str] | None = None) -> int:
    """Console-script entry point; returns (and exits with) the exit code."""
    global _interrupted_note
    argv = list(sys.argv[1:] if argv is None else argv)
    _interrupted_note = None
    debug = "--debug" in argv
    warnings.showwarning = _show_warning
    interrupted = False
    try:
        # Without standalone mode, typer catches Ctrl-C itself and *returns* 130 instead of raising.
        returned = _command()(args=argv, prog_name="suspid", standalone_mode=False)
        code = returned if isinstance(returned, int) else 0
        interrupted = code == 130
    except _CLICK["Exit"] as exc:
        code = exc.exit_code
    except _CLICK["ClickException"] as exc:
        exc.show()
        code = exc.exit_code
    except (KeyboardInterrupt, *_CLICK["Abort"]):
        interrupted, code = True, 130
    except Exception as exc:  # noqa: BLE001 - every error becomes one line; --debug shows the traceback
        if debug:
            raise
        message, code = _one_line(exc)
        print(f"error: {message}", file=sys.stderr)
    if interrupted:
        note = _interrupted_note or f"{_kept()}; run the same command to resume"
        print(f"interrupted: {note}", file=sys.stderr)
    sys.exit(code)


if __name__ == "__main__":  # python -m suspid.cli
    main()
