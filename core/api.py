"""suspid's Python API: what every ``suspid`` command does, as one documented function each.

A notebook user calls these directly; the command line is a thin shell over
them (progress bars on in the CLI, off here by default)::

    import suspid

    r = suspid.identify("configs/quickstart.yaml", {"ego.max_iter": 10})
    r.w_opt, r.intervals, r.identifiable, r.errors_percent
    r.to_dict() == json.load(open(r.run_dir / "result.json"))

A config is a YAML file or a mapping with the same content; ``overrides`` are
``{"key.path": value}`` (or ``["key.path=value", ...]`` as ``--set`` takes
them). Every function validates the whole config first (:func:`validate`), so
a mistake is one :class:`~suspid.errors.ConfigError` naming the file, the key
and what was expected, before any simulation.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence, Union

from suspid import registry
from suspid.config import Config, build_simulator, identified_bounds, load_config as _load, override_arguments
from suspid.data.ingest import IngestResult
from suspid.data.ingest import run as _run_ingest
from suspid.data.files import read_track
from suspid.data.plausibility import refused, speed_doubts
from suspid.errors import ConfigError, DataWarning, UnknownPluginError
from suspid.indicators.recordings import config_indicators, write_indicator_files
from suspid.interfaces import ElementSimulator, TrackSegment
from suspid.method.spectra import compute_spectra
from suspid.workflows import diagnose as _diagnose
from suspid.workflows import identify as _identify
from suspid.workflows import monitor as _monitor
from suspid.workflows import simulate as _simulate
from suspid.workflows import study as _study
from suspid.workflows.identify import IdentificationResult
from suspid.workflows.checks import data_shortfalls, dry_run
from suspid.workflows.problem import synthetic_track

ConfigSource = Union[str, Path, Mapping[str, Any], Config]
"""A config: a YAML file, a mapping with the same content, or a loaded :class:`~suspid.config.Config`."""
Overrides = Union[Mapping[str, Any], Sequence[str], None]
"""``{"key.path": value}`` or ``["key.path=value", ...]``."""

Log = Callable[[str], None]


def _override_list(overrides: Overrides) -> list[str]:
    if overrides is None:
        return []
    if isinstance(overrides, Mapping):
        return override_arguments(overrides)
    return [str(o) for o in overrides]


def _fleet():
    """:mod:`suspid.fleet.api`, which needs the ``fleet`` extra (SQLAlchemy, Alembic): imported when a config
    records into a monitoring database, so that suspid without the extra runs everything else."""
    try:
        from suspid.fleet import api as fleet_api
    except ImportError as exc:
        raise ConfigError(f"the monitoring database needs the fleet extra ({exc.name} is missing): "
                          f"pip install 'suspid[fleet]'") from None
    return fleet_api


def _dashboard():
    """:mod:`suspid.dashboard.server` (Flask, Flask-WTF, SQLAlchemy: the ``fleet`` extra), without the workflows
    that :func:`_fleet` brings: the dashboard's commands start in about a second."""
    try:
        from suspid.dashboard import server
    except ImportError as exc:
        raise ConfigError(f"the dashboard needs the fleet extra ({exc.name} is missing): "
                          f"pip install 'suspid[fleet]'") from None
    return server


def _source(config: ConfigSource) -> str | Path | Mapping[str, Any]:
    """What the workflows reload variants and dates from: a path or a mapping."""
    if isinstance(config, Config):
        if config.source_file is None:
            return config.model_dump(mode="json", exclude={"source_file"})
        return config.source_file
    return config


def load_config(config: ConfigSource, overrides: Overrides = None) -> Config:
    """Read and validate a config: every section resolved into its typed model, plugins checked.

    :param config: a YAML file, a mapping with the same content, or a loaded config (returned as is
        when there are no overrides).
    :param overrides: ``{"key.path": value}`` or ``["key.path=value", ...]``.
    :raises suspid.errors.ConfigError: one line naming the file, the key path and what was expected.
    """
    if isinstance(config, Config) and not overrides:
        return config
    return _load(_source(config), _override_list(overrides))


@dataclass
class Validation:
    """What :func:`validate` checked: the resolved config and the measured segments it read (0: experiment)."""

    config: Config
    n_measured_segments: int


def validate(config: ConfigSource, overrides: Overrides = None) -> Validation:
    """Every check that needs no simulation, as ``suspid validate`` runs it (a dry run).

    The config with every section and plugin option; the measured data files
    (read and turned into spectra); the variants of ``study:``, the dates of
    ``monitor:`` and the effects of ``diagnose:`` when those sections are present.

    :raises suspid.errors.SuspidError: the first problem, in one line.
    """
    cfg = load_config(config, overrides)
    n = dry_run(cfg)
    for shortfall in data_shortfalls(cfg):   # what the run will not assess for want of data
        warnings.warn(shortfall, DataWarning, stacklevel=2)
    source, extra = _source(config), _override_list(overrides)  # as study and monitor will reload them
    if cfg.study is not None:
        _study.study_variants(source, extra, cfg)
    if cfg.monitor is not None:
        _monitor.monitor_plan(source, extra, cfg)
    if cfg.fleet is not None and cfg.fleet.database is not None:
        _fleet().check_fleet(cfg)
    return Validation(cfg, n)


def identify(config: ConfigSource, overrides: Overrides = None, *, fresh: bool = False,
             progress: bool = False, log: Log | None = None, retry_failed: bool = False,
             force: bool = False) -> IdentificationResult:
    """The identification (``suspid run``): noise model, maximin design, Kriging, EGO, intervals.

    Writes ``result.json``, ``report.md``, the figures, ``noise_model.npz`` and
    ``ledger.sqlite`` in the run directory; running it again resumes from the
    ledger without simulating finished points again.

    :param fresh: forget the ledger of a previous run in the same directory.
    :param progress: show rich progress bars.
    :param log: receives one line per step (default: silent).
    :param retry_failed: simulate again the points whose simulation failed in an earlier run.
    :param force: take over a run directory that holds the run of another config.
    :returns: the typed result; ``result.to_dict()`` equals ``result.json``.
    """
    cfg = validate(config, overrides).config
    result = _identify.run(cfg, fresh=fresh, progress=progress, log=log or (lambda s: None),
                           retry_failed=retry_failed, force=force)
    if cfg.fleet is not None and cfg.fleet.database is not None:   # the config's monitoring database
        _fleet().record_identification(cfg, result, log=log or (lambda s: None))
    return result


def study(config: ConfigSource, overrides: Overrides = None, *, fresh: bool = False, progress: bool = False,
          log: Log | None = None, report_only: bool = False) -> _study.StudyResult:
    """The variants of the config's ``study:`` section (``suspid study``): one identification each.

    :param report_only: run nothing; write the study outputs from the variants that have finished.
    :returns: the study folder and one :class:`IdentificationResult` per variant (in order).
    """
    cfg = validate(config, overrides).config
    return _study.run_study(_source(config), _override_list(overrides), cfg, fresh=fresh, progress=progress,
                            log=log or (lambda s: None), report_only=report_only)


def monitor(config: ConfigSource, overrides: Overrides = None, *, fresh: bool = False, progress: bool = False,
            log: Log | None = None) -> _monitor.MonitorResult:
    """One identification per measurement date of ``monitor:`` (``suspid monitor``), with alerts.

    :returns: the monitor folder, the per-date rows and the alerts.
    """
    cfg = validate(config, overrides).config
    result = _monitor.run_monitor(_source(config), _override_list(overrides), cfg, fresh=fresh, progress=progress,
                                  log=log or (lambda s: None))
    if cfg.fleet is not None and cfg.fleet.database is not None:   # every date into the monitoring database
        plans = _monitor.monitor_plan(_source(config), _override_list(overrides), cfg)[3]
        _fleet().record_monitor(cfg, plans, result, log=log or (lambda s: None))
    return result


def diagnose(config: ConfigSource, overrides: Overrides = None, *, fresh: bool = False, progress: bool = False,
             log: Log | None = None) -> _diagnose.DiagnosisResult:
    """The discrepancy workflow (``suspid diagnose``): locate, name the missing effect, add it, re-identify.

    :returns: the diagnosis folder and the content of ``diagnosis.json``.
    """
    cfg = validate(config, overrides).config
    return _diagnose.run_diagnose(_source(config), _override_list(overrides), cfg, fresh=fresh,
                                  progress=progress, log=log or (lambda s: None))


def segments(config: ConfigSource, overrides: Overrides = None) -> list[TrackSegment]:
    """The configured track segments: the measurement date's synthetic track, or the measured track file."""
    cfg = load_config(config, overrides)
    if cfg.data.source == "experiment":
        return synthetic_track(cfg, "measurement")
    if cfg.data.track_file is None:
        raise cfg.error("measured data need data.track_file", "data.track_file")
    return read_track(cfg.data.track_file, strict=cfg.data.strict, accept=cfg.data.accept)


@dataclass(frozen=True)
class ParameterInfo:
    """One parameter of a simulator, as ``suspid parameters`` lists it (SI units).

    :ivar lower, upper: the simulator's admissible interval C_w; :ivar domain: where the parameter is physical.
    :ivar elements: for a simulator with suspension elements, the groups ``kind[tags]`` of the elements this
        parameter sets (empty otherwise).
    :ivar identified: ``(lower, upper)`` the config identifies it within, None when it does not.
    """

    name: str
    description: str
    unit: str
    nominal: float
    lower: float
    upper: float
    domain: tuple[float, float]
    elements: tuple[str, ...]
    identified: tuple[float, float] | None


def parameters(config: ConfigSource | None = None, overrides: Overrides = None, *,
               simulator: str | None = None) -> list[ParameterInfo]:
    """A simulator's parameters (``suspid parameters``): description, unit, nominal value, bounds, physical
    domain, the elements each sets, and which the config identifies within which bounds.

    :param config: the config whose simulator (with its options: a preset, ``vehicle:`` overrides) is listed;
        None lists ``simulator`` built with its default options.
    :param simulator: a registered simulator's name (default ``exudyn-train``), without a config.
    :raises ConfigError: both a config and ``simulator`` given, or an unknown simulator.
    """
    if config is not None and simulator is not None:
        raise ConfigError("give a config or a simulator's name, not both (the config names its simulator)",
                          key="simulator")
    identified: dict[str, tuple[float, float]] = {}
    if config is not None:
        cfg = load_config(config, overrides)
        sim = build_simulator(cfg)
        if cfg.parameters:
            identified = identified_bounds(cfg, sim)
    else:
        name = simulator or "exudyn-train"
        try:
            sim = registry.get("simulator", name)()
        except UnknownPluginError as exc:
            raise ConfigError(str(exc), key="simulator") from None
    by_kind: dict[str, list[str]] = {}
    for e in sim.elements() if isinstance(sim, ElementSimulator) else []:
        by_kind.setdefault(e.kind, []).append(f"{e.kind}[{','.join(e.tags)}]")
    return [ParameterInfo(p.name, p.description, p.unit, float(p.nominal), float(p.lower), float(p.upper),
                          (float(p.domain[0]), float(p.domain[1])), tuple(by_kind.get(p.name, ())),
                          identified.get(p.name)) for p in sim.parameters()]


def simulate(config: ConfigSource, overrides: Overrides = None, *, w: Mapping[str, float] | None = None,
             out_dir: str | Path | None = None) -> Path:
    """Simulate ``w`` (other parameters nominal) on the configured segments (``suspid simulate``).

    :param w: parameter values, SI units; ``None`` simulates the nominal vehicle.
    :param out_dir: default ``<run dir>/simulation``.
    :returns: the path of ``simulation.h5`` (accelerations, spectra ``y`` and ``freqs``).
    """
    cfg = load_config(config, overrides)
    sim = build_simulator(cfg)
    known = {p.name for p in sim.parameters()}
    for name in w or {}:   # the values are the caller's, not the config's: the error names w, not a line
        if name not in known:
            raise ConfigError(f"unknown parameter '{name}' for simulator '{cfg.simulator.plugin}'; known: "
                              f"{', '.join(sorted(known))}", key=f"w.{name}")
    out = Path(out_dir) if out_dir is not None else cfg.run_dir() / "simulation"
    return _simulate.write_simulation(sim, segments(cfg), dict(w or {}), out,
                                      lambda rs: compute_spectra(rs, cfg.spectra))


def stability(config: ConfigSource, overrides: Overrides = None, *, n_points: int = 3,
              out_dir: str | Path | None = None) -> dict[str, Any]:
    """Linear critical speed of the train model and its sweep over conicity and each identified parameter
    over its bounds (``suspid stability``); writes ``stability.json``.

    :param n_points: values per parameter between its bounds.
    :param out_dir: where ``stability.json`` goes (default: the run directory).
    """
    cfg = load_config(config, overrides)
    simulator = build_simulator(cfg)
    names = [n for n in identified_bounds(cfg, simulator) if "/" not in n]
    out = Path(out_dir) if out_dir is not None else cfg.run_dir()
    return _simulate.stability_report(simulator, out, parameters=names, n_points=n_points)


def observability(config: ConfigSource, overrides: Overrides = None, *, log: Log | None = None):
    """Which element groups the sensors separate (``suspid observability``): Fisher information of the spectra
    over every element of the analysed kinds, its rank and conditioning, the clusters only seen as a sum, and
    which extra channel would split which cluster; writes ``observability.json`` in the run directory.

    :returns: :class:`suspid.workflows.elements.ObservabilityResult`.
    """
    from suspid.workflows.elements import observability as _observability

    cfg = load_config(config, overrides)
    return _observability(cfg, log=log or (lambda s: None))


def modes(config: ConfigSource, overrides: Overrides = None, *, speed_mps: float | None = None,
          w: Mapping[str, float] | None = None, out_dir: str | Path | None = None) -> dict[str, Any]:
    """Eigenmodes of the train model (``suspid modes``): frequency, damping ratio, body, motion, ``stable``.

    :param speed_mps: default: the simulator's configured speed.
    :param out_dir: where ``modes.json`` goes (default: the run directory; the folder is created).
    """
    cfg = load_config(config, overrides)
    if speed_mps is not None:   # judged as a track file's speed is (suspid.data.plausibility)
        refusal = refused(speed_doubts(speed_mps), accept=cfg.data.accept)
        if refusal is not None:
            raise ConfigError(refusal, key="speed_mps")
    out = Path(out_dir) if out_dir is not None else cfg.run_dir()
    out.mkdir(parents=True, exist_ok=True)
    return _simulate.modes_report(build_simulator(cfg), speed_mps, out, w)


def ingest(ingest_file: str | Path | Mapping[str, Any], overrides: Overrides = None, *,
           out_dir: str | Path | None = None, log: Log | None = None) -> IngestResult:
    """Cut a long recording into measured-data segments (``suspid ingest``): units, alignment, quality.

    :param ingest_file: an ingest YAML file (or a mapping with the same content, see ``docs/ingest.md``):
        the recording and its channel mapping, the speed or distance channel, the track record, and the
        suspid ``config`` whose simulator's channels the recorded ones map to.
    :param out_dir: default ``output.dir`` of the file, else ``ingested/<recording stem>/`` beside it.
    :returns: a :class:`suspid.data.ingest.IngestResult`: the track and accelerations written (the
        ``data.track_file`` and ``data.measurements`` of a measured-data config), the offset and its
        confidence, the segments, the warnings (and, for two dates, ``config_warnings``: what a run of the
        two-date config will not assess for want of data); ``ingest.md``, ``ingest.json`` and PNGs in ``out_dir``.
    :raises suspid.errors.SuspidError: a config or data problem, in one line.
    """
    result = _run_ingest(ingest_file, _override_list(overrides), out_dir=out_dir, log=log or (lambda s: None))
    if result.config_path is not None:   # what a run of the two-date config will not assess, said now
        result.config_warnings = data_shortfalls(load_config(result.config_path),
                                                 n_reference=len(result.reference.segments))
    return result


def fleet_import(database: str | Path, folders: Sequence[str | Path], *, fleet: str, trainset: str,
                 vehicle: str = "car1", date: Any = None, mileage_km: float | None = None,
                 km_per_day: float | None = None, indicators: bool = True, log: Log | None = None):
    """Record existing run folders into the monitoring database (``suspid fleet import``).

    :param database: an SQLite path or a database URL (``postgresql://user@host:port/db``).
    :param folders: ``suspid monitor`` folders (every date) or ``suspid run`` folders.
    :param date: the date of a run folder (a monitor folder's dates are its own); default: when it was written.
    :param mileage_km: mileage at that date (at a monitor's first date); ``km_per_day`` for the later dates.
    :returns: a :class:`suspid.fleet.record.ImportResult` (one row per run, ``created`` False if already there).
    """
    return _fleet().import_runs(database, folders, fleet=fleet, trainset=trainset, vehicle=vehicle, date=date,
                                mileage_km=mileage_km, km_per_day=km_per_day, indicators=indicators,
                                log=log or (lambda s: None))


def indicators(config: ConfigSource, overrides: Overrides = None, *, log: Log | None = None,
               out_dir: str | Path | None = None):
    """EN 14363 bogie-frame instability and EN 12299 mean comfort of the config's recordings, per segment and
    per run (``suspid indicators``; ``docs/fleet.md``); stored when the config has a ``fleet.database``.

    Each value's ``detail`` holds what it was judged against: ``warning_level`` and ``alarm_level``, and for the
    instability the limit's inputs ``bogie_mass_kg`` and ``f0_hz`` (the band's hunting frequency, with
    ``hunting_hz_source``).

    :param out_dir: also write ``indicators.json`` and ``indicators.csv`` there
        (:func:`suspid.indicators.recordings.write_indicator_files`: the date, the levels, the limit's inputs).
    :returns: (the list of :class:`suspid.indicators.IndicatorValue`, the database record or None).
    """
    cfg = load_config(config, overrides)
    if cfg.fleet is not None and cfg.fleet.database is not None:
        values, rec = _fleet().run_indicators(cfg, log=log or (lambda s: None))
    else:
        values, rec = config_indicators(cfg, hunting_hz=cfg.fleet.hunting_hz if cfg.fleet else None), None
    if out_dir is not None:
        write_indicator_files(out_dir, cfg, values)
    return values, rec


def dashboard(database: str | Path, *, host: str = "127.0.0.1", port: int = 8050, allow_ack: bool = False,
              create: bool = False, log: Log | None = None, warn: Log | None = None) -> None:
    """Serve the fleet dashboard over the monitoring database until interrupted (``suspid dashboard``).

    :param host: address to bind; the default serves this machine only (another address is said in ``warn``).
    :param allow_ack: let the database's users (``suspid fleet user add``) log in and acknowledge alarms.
    :param create: make the SQLite database when it does not exist (else a missing file is an error).
    :raises suspid.errors.ConfigError: a missing database, a port in use, an address this machine lacks,
        ``allow_ack`` without any user.
    """
    _dashboard().serve(database, host=host, port=port, allow_ack=allow_ack, create=create, log=log or (lambda s: None),
          warn=warn)


def fleet_user(action: str, database: str | Path, name: str | None = None, password: str | None = None):
    """Users who may acknowledge alarms on the dashboard (``suspid fleet user add|remove|list``).

    :param action: ``add`` (needs ``name`` and ``password``), ``remove`` (needs ``name``) or ``list``.
    :param database: an existing monitoring database (a missing SQLite file is an error).
    :returns: the :class:`suspid.fleet.users.UserInfo` added, None for ``remove``, the list for ``list``.
    """
    from suspid.fleet import users   # the fleet extra: _dashboard() has checked it

    db = _dashboard().open_dashboard_database(database)
    try:
        if action == "add":
            return users.add_user(db, name or "", password or "")
        if action == "remove":
            return users.remove_user(db, name or "")
        return users.list_users(db)
    finally:
        db.dispose()


def fleet_upgrade(database: str | Path, *, log: Log | None = None) -> None:
    """Bring a monitoring database's schema to this suspid's newest revision (``suspid fleet upgrade``).

    A PostgreSQL database is upgraded in one transaction (back it up first: ``pg_dump``); an SQLite one
    is copied beside itself first (``FILE.schema-REV.bak``). Recording upgrades SQLite by itself.
    """
    _fleet()
    from suspid.fleet.db import upgrade_database   # the fleet extra, checked just above

    upgrade_database(database, log=log or (lambda s: None))


def fleet_demo(plan: str | Path, *, log: Log | None = None):
    """Monitor the demo fleet of a fleet plan into its database and check its degrading elements
    (``suspid fleet demo``; :mod:`suspid.fleet.demo`).

    :returns: a :class:`suspid.fleet.demo.DemoResult` (database URL, output folder, checks).
    """
    _fleet()
    from suspid.fleet.demo import run_demo   # the fleet extra, checked just above
    return run_demo(plan, log=log or (lambda s: None))
