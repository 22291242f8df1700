"""Opening the monitoring database: a URL or a path, for writing or read-only, its schema, writes that survive faults.

SQLite is the embedded default (a path, or ``sqlite:///path``): no server to
set up. It runs in WAL mode with ``synchronous = FULL`` (a committed record
survives a power cut) and every write transaction started as ``BEGIN
IMMEDIATE`` with a long busy timeout, so that several runs finishing at once
queue for the write lock instead of failing ("database is locked"). A depot
server is a PostgreSQL URL (``postgresql://user@host:port/db``, psycopg 3).

**Modes.** :func:`open_database` opens for writing (``suspid run``,
``monitor``, ``fleet import``) or, with ``read_only=True``, for reading only
(the dashboard): SQLite's ``mode=ro`` (``immutable=1`` on a read-only file
system, where no one can write), a PostgreSQL session whose transactions are
read-only; nothing is created, migrated or written, and a write attempt is a
:class:`~suspid.errors.DataError`.

**Faults.** Every write is one transaction: both backends commit it whole or
not at all. :meth:`Database.write` retries it while another writer holds the
lock, after a lost race on a unique key, and while the server cannot be
reached (backoff from 0.5 s to 8 s, for at most ``wait_s`` seconds, one line
through ``log`` when the wait starts); any other fault (disk full, damaged
file, read-only) ends it at once in one line (:mod:`suspid.fleet.faults`).
An SQLite file is checked (``PRAGMA quick_check``) when opened, so that a
damaged one is refused before anything is written to it.

**Schema.** The Alembic revision of the database is read when it is opened.
A new (empty) database gets the schema; one at the newest revision is used as
it is; an older SQLite database is copied (``FILE.schema-REV.bak``, SQLite's
backup API) before it is upgraded in one transaction; an older PostgreSQL
database is refused until :func:`upgrade_database` (``suspid fleet upgrade``)
is asked to upgrade it, after the depot's own backup; a database of an unknown
revision (a newer suspid) or with foreign tables is refused. Writers opening a
database together migrate it once: under a lock (a lock file beside an SQLite
database, an advisory lock on PostgreSQL) the revision is read again.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import fcntl
import os
import sqlite3
import time
import urllib.parse
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, TypeVar

from alembic import command
from alembic.config import Config as AlembicConfig
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Engine, create_engine, event, inspect, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError, DBAPIError
from sqlalchemy.orm import Session, sessionmaker

from suspid.errors import ConfigError, DataError
from suspid.fleet.faults import Fault, fault_of, first_line
from suspid.fleet.options import DEFAULT_WAIT_S

MIGRATIONS = Path(__file__).parent / "migrations"
T = TypeVar("T")
Log = Callable[[str], None]
_ADVISORY_KEY = 0x5355_5350  # "SUSP": the PostgreSQL advisory lock held while migrating
_BACKOFF_S = (0.5, 8.0)        # first and longest pause between two attempts to reach the server
_BUSY_ATTEMPTS = 20            # "database is locked" beyond SQLite's own busy timeout
_CONFLICT_ATTEMPTS = 3         # a lost race on a unique key: the next attempt finds the other writer's row
_CONNECT_TIMEOUT_S = 10        # PostgreSQL: an unanswered connection attempt counts as unreachable after this


def _silent(_: str) -> None:
    pass


def database_url(url_or_path: str | Path) -> str:
    """A SQLAlchemy URL from a URL or a file path (a path is an SQLite database; ``postgresql://`` uses psycopg 3).

    :raises ConfigError: a URL SQLAlchemy cannot parse, or a backend other than SQLite and PostgreSQL.
    """
    text_ = str(url_or_path)
    if "://" not in text_:
        return f"sqlite:///{Path(text_).expanduser().resolve()}"
    try:
        url = make_url(text_)
    except ArgumentError:
        raise ConfigError(f"database: '{text_}' is not a database URL (sqlite:///PATH or "
                          f"postgresql://USER@HOST:PORT/DB)") from None
    if url.get_backend_name() == "postgresql" and url.drivername == "postgresql":
        url = url.set(drivername="postgresql+psycopg")
    if url.get_backend_name() not in ("sqlite", "postgresql"):
        raise ConfigError(f"database: backend '{url.get_backend_name()}' is not supported; "
                          f"give sqlite:///PATH or postgresql://USER@HOST:PORT/DB")
    return url.render_as_string(hide_password=False)


def _sqlite_file(url: str) -> Path | None:
    u = make_url(url)
    return Path(u.database) if u.get_backend_name() == "sqlite" and u.database else None


@dataclass
class Database:
    """An open monitoring database: its engine, a session factory and how it meets faults (module docstring)."""

    url: str
    engine: Engine
    sessions: sessionmaker
    read_only: bool = False
    wait_s: float = DEFAULT_WAIT_S
    log: Log = field(default=_silent, repr=False)

    @property
    def backend(self) -> str:
        """``sqlite`` or ``postgresql``."""
        return self.engine.url.get_backend_name()

    @property
    def sqlite_file(self) -> Path | None:
        """The SQLite file (None on PostgreSQL)."""
        return _sqlite_file(self.url)

    @property
    def label(self) -> str:
        """How messages name the database: the SQLite file, or the URL without its password."""
        path = self.sqlite_file
        if path:
            return f"database {path}"
        url = make_url(self.url)
        return f"database {url.set(drivername=url.get_backend_name()).render_as_string(hide_password=True)}"

    def fault(self, exc: DBAPIError) -> DataError | None:
        """The one-line error of a database fault, or None when ``exc`` is not one (a bug)."""
        f = fault_of(exc)
        return None if f is None else DataError(f.message(self.label, self.sqlite_file))

    @contextlib.contextmanager
    def _faults(self) -> Iterator[None]:
        try:
            yield
        except DBAPIError as exc:
            error = self.fault(exc)
            if error is None:
                raise
            raise error from None

    @contextlib.contextmanager
    def _transaction(self) -> Iterator[Session]:
        with self.sessions() as session, session.begin():
            yield session

    @contextlib.contextmanager
    def session(self) -> Iterator[Session]:
        """A session in one write transaction: committed on success, rolled back on any error.

        :raises DataError: the database was opened read-only, or a fault of the database (one line).
        """
        self._writable()
        with self._faults(), self._transaction() as session:
            yield session

    @contextlib.contextmanager
    def _reading(self) -> Iterator[Session]:
        with self.sessions() as session:   # closing ends the transaction and keeps loaded objects readable
            session.connection(execution_options={"suspid_read": True})
            yield session

    @contextlib.contextmanager
    def read(self) -> Iterator[Session]:
        """A session for reading: on SQLite a deferred transaction, which does not queue for the write lock.

        :raises DataError: a fault of the database (one line).
        """
        with self._faults(), self._reading() as session:
            yield session

    def write(self, work: Callable[[Session], T]) -> T:
        """Run ``work(session)`` in one write transaction, again after a passing fault (module docstring).

        ``work`` may run more than once and must give the same rows each time
        (a record looks for its run before adding it).

        :raises DataError: read-only, a lasting fault, or the server unreachable for ``wait_s`` seconds.
        """
        self._writable()

        def once() -> T:
            with self._transaction() as session:
                return work(session)
        return self.retrying(once)

    def query(self, work: Callable[[Session], T]) -> T:
        """``work(session)`` in a read transaction, again while the server cannot be reached (as :meth:`write`)."""
        def once() -> T:
            with self._reading() as session:
                return work(session)
        return self.retrying(once)

    def retrying(self, attempt: Callable[[], T]) -> T:
        """``attempt()``, repeated after a passing fault of the database (module docstring)."""
        busy = conflict = 0
        started: float | None = None
        pause = _BACKOFF_S[0]
        while True:
            try:
                result = attempt()
            except DBAPIError as exc:
                f = fault_of(exc)
                if f is None:
                    raise
                if f.kind == "busy" and busy < _BUSY_ATTEMPTS:
                    busy += 1
                    time.sleep(0.05 * busy)
                    continue
                if f.kind == "conflict" and conflict < _CONFLICT_ATTEMPTS:
                    conflict += 1
                    continue
                if f.kind != "unreachable":
                    raise DataError(f.message(self.label, self.sqlite_file)) from None
                now = time.monotonic()
                if started is None:
                    started = now
                    self.log(f"{self.label}: cannot be reached ({f.detail}); retrying for up to {self.wait_s:.0f} s")
                remaining = self.wait_s - (now - started)
                if remaining <= 0:
                    raise DataError(f"{f.message(self.label)}; gave up after {now - started:.0f} s "
                                    f"(fleet.wait_s: {self.wait_s:g})") from None
                time.sleep(min(pause, remaining))      # the last attempt at the end of the wait
                pause = min(2 * pause, _BACKOFF_S[1])
                continue
            if started is not None:
                self.log(f"{self.label}: reached again after {time.monotonic() - started:.0f} s")
            return result

    def _writable(self) -> None:
        if self.read_only:
            raise DataError(f"{self.label}: opened read-only; nothing was written")

    def dispose(self) -> None:
        self.engine.dispose()


def _sqlite_pragmas(engine: Engine, read_only: bool) -> None:
    @event.listens_for(engine, "connect")
    def _connect(dbapi_connection, _record):  # noqa: ANN001 - DB-API objects
        dbapi_connection.isolation_level = None   # SQLAlchemy emits BEGIN itself (below)
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA busy_timeout = 120000")
        cursor.execute("PRAGMA synchronous = FULL")   # WAL mode (set once, by _schema_state) syncs each commit
        cursor.execute("PRAGMA foreign_keys = ON")
        cursor.close()

    @event.listens_for(engine, "begin")
    def _begin(connection):  # noqa: ANN001
        options = connection.get_execution_options()
        if options.get("suspid_no_transaction"):
            return                                 # statements SQLite refuses inside a transaction
        read = read_only or options.get("suspid_read", False)
        connection.exec_driver_sql("BEGIN" if read else "BEGIN IMMEDIATE")


def _read_only_uri(path: Path) -> str:
    """SQLite's URI opening ``path`` read-only; ``immutable=1`` on a read-only file system (no one can write
    there, and SQLite could not create the ``-shm`` file a WAL database needs), unless an unfinished WAL waits."""
    uri = f"file:{urllib.parse.quote(str(path))}?mode=ro"
    wal = path.with_name(path.name + "-wal")
    if os.statvfs(path.parent).f_flag & os.ST_RDONLY and not (wal.is_file() and wal.stat().st_size):
        uri += "&immutable=1"
    return uri


def _engine(url: str, read_only: bool) -> Engine:
    path = _sqlite_file(url)
    if path is None:
        args: dict = {"connect_timeout": _CONNECT_TIMEOUT_S}
        if read_only:
            args["options"] = "-c default_transaction_read_only=on"
        return create_engine(url, pool_pre_ping=True, connect_args=args)
    if read_only:
        if not path.is_file():
            raise DataError(f"database {path}: no such file (a read-only open creates nothing)")
        uri = _read_only_uri(path)
        engine = create_engine(url, pool_pre_ping=True,
                               creator=lambda: sqlite3.connect(uri, uri=True, check_same_thread=False))
    else:
        if path.parent.is_dir() and os.statvfs(path.parent).f_flag & os.ST_RDONLY:
            raise DataError(f"database {path}: on a read-only file system: it can be opened read-only only "
                            f"(nothing can be recorded there)")
        engine = create_engine(url, pool_pre_ping=True)
    _sqlite_pragmas(engine, read_only)
    return engine


def _alembic_config() -> AlembicConfig:
    cfg = AlembicConfig()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    return cfg


@contextlib.contextmanager
def _migration_lock(engine: Engine) -> Iterator[None]:
    if engine.url.get_backend_name() == "sqlite":
        path = Path(engine.url.database or "")
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fh = open(path.with_name(path.name + ".migrate.lock"), "a+")
        except OSError as exc:
            raise DataError(f"database {path}: cannot create it ({exc.strerror})") from None
        with fh:
            fcntl.flock(fh, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)
    else:
        with engine.connect() as conn:
            conn.execute(text("SELECT pg_advisory_lock(:k)"), {"k": _ADVISORY_KEY})
            conn.commit()
            try:
                yield
            finally:
                conn.execute(text("SELECT pg_advisory_unlock(:k)"), {"k": _ADVISORY_KEY})
                conn.commit()


def migrate(engine: Engine, revision: str = "head") -> None:
    """Bring the schema behind ``engine`` to ``revision`` with the shipped migrations, without the checks of
    :func:`open_database` (to make a database of an older revision, as the tests of the migrations do)."""
    cfg = _alembic_config()
    with _migration_lock(engine), engine.begin() as connection:
        cfg.attributes["connection"] = connection
        command.upgrade(cfg, revision)


def _schema_state(db: Database) -> tuple[str | None, list[str]]:
    """The database's Alembic revision (None: none recorded) and its tables; a damaged SQLite file is refused."""
    with db.engine.connect() as conn:
        conn.execution_options(suspid_read=True)
        if db.backend == "sqlite":
            problem = conn.exec_driver_sql("PRAGMA quick_check(1)").scalar()
            if problem != "ok":
                raise DataError(Fault("damaged", f"quick_check: {' '.join(str(problem).split())}")
                                .message(db.label, db.sqlite_file))
        current = MigrationContext.configure(conn).get_current_revision()
        tables = sorted(inspect(conn).get_table_names())
        conn.rollback()
    return current, tables


def _write_ahead_log(db: Database) -> None:
    """Put an SQLite database to be written in WAL mode: the one write an open makes, after every check (a file
    it refuses keeps its bytes), once (the mode is kept in the file)."""
    if db.backend == "sqlite" and not db.read_only:
        with db.engine.connect() as conn:
            conn.execution_options(suspid_no_transaction=True).exec_driver_sql("PRAGMA journal_mode = WAL")
            conn.rollback()


def _backup_sqlite(path: Path, revision: str) -> Path:
    """A consistent copy of the SQLite database ``path`` (SQLite's backup API), written atomically beside it."""
    target = path.with_name(f"{path.name}.schema-{revision}.bak")
    if target.exists():
        target = path.with_name(f"{path.name}.schema-{revision}.{dt.datetime.now():%Y%m%dT%H%M%S}.bak")
    tmp = target.with_name(target.name + ".tmp")
    try:
        source = sqlite3.connect(f"file:{urllib.parse.quote(str(path))}?mode=ro", uri=True)
        try:
            copy = sqlite3.connect(tmp)
            try:
                source.backup(copy)
            finally:
                copy.close()
        finally:
            source.close()
        os.replace(tmp, target)
    except (OSError, sqlite3.Error) as exc:
        tmp.unlink(missing_ok=True)
        raise DataError(f"database {path}: the copy before the schema upgrade could not be written ({exc}); "
                        f"nothing was changed") from None
    return target


def _prepare(db: Database, *, upgrade: bool, server_upgrade: bool) -> None:
    """Check the schema of ``db`` and create or upgrade it as the module docstring says."""
    script = ScriptDirectory.from_config(_alembic_config())
    head = script.get_current_head()
    known = {r.revision for r in script.walk_revisions()}
    current, tables = _schema_state(db)
    if current == head:
        _write_ahead_log(db)
        return
    if current is None and tables:
        raise DataError(f"{db.label}: holds tables ({', '.join(tables[:6])}{', ...' if len(tables) > 6 else ''}) "
                        f"but no suspid schema revision: not a monitoring database; nothing was changed")
    if current is not None and current not in known:
        raise DataError(f"{db.label}: schema revision {current}, unknown to this suspid (newest {head}): it was "
                        f"made by a newer suspid; upgrade suspid (nothing was changed)")
    if current is None and not upgrade:
        raise DataError(f"{db.label}: holds no monitoring tables yet (nothing was ever recorded in it)")
    if current is not None and not upgrade:
        raise DataError(f"{db.label}: schema revision {current}, older than this suspid's {head}: open it for "
                        f"writing once (`suspid fleet upgrade --db ...`) to upgrade it; nothing was changed")
    if current is not None and db.backend == "postgresql" and not server_upgrade:
        raise DataError(f"{db.label}: schema revision {current}, older than this suspid's {head}: back the database "
                        f"up (pg_dump) and upgrade it with `suspid fleet upgrade --db URL`; nothing was changed")
    cfg = _alembic_config()
    backup = None
    _write_ahead_log(db)
    with _migration_lock(db.engine), db.engine.begin() as connection:   # SQLite: BEGIN IMMEDIATE, no writer in
        current = MigrationContext.configure(connection).get_current_revision()   # another writer may have done it
        if current == head:
            return
        if current is not None and db.sqlite_file is not None:
            backup = _backup_sqlite(db.sqlite_file, current)
        cfg.attributes["connection"] = connection
        try:
            command.upgrade(cfg, "head")
        except Exception as exc:   # noqa: BLE001 - whatever failed, the transaction is rolled back whole
            fault = fault_of(exc) if isinstance(exc, DBAPIError) else None
            if fault is not None and fault.transient:
                raise                              # retried whole
            cause = fault.detail if fault is not None else first_line(getattr(exc, "orig", None) or exc)
            raise DataError(f"{db.label}: the schema upgrade from {current or 'nothing'} to {head} failed "
                            f"({cause}); nothing was changed" + (f" (a copy: {backup})" if backup else "")) from None
    if current is not None:
        db.log(f"{db.label}: schema upgraded from revision {current} to {head}"
               + (f"; the copy before the upgrade is {backup}" if backup else ""))


def open_database(url_or_path: str | Path, *, read_only: bool = False, upgrade: bool = True,
                  wait_s: float = DEFAULT_WAIT_S, log: Log | None = None) -> Database:
    """Open the monitoring database at ``url_or_path`` (module docstring: modes, faults, schema).

    :param url_or_path: an SQLite file path, ``sqlite:///PATH`` or ``postgresql://USER@HOST:PORT/DB``.
    :param read_only: open for reading only: create, migrate and write nothing (the dashboard).
    :param upgrade: create the schema of a new database and upgrade an older SQLite one (after a copy);
        False refuses any database that is not at the newest revision.
    :param wait_s: how long to wait for a server that cannot be reached, here and in every write, s.
    :param log: receives one line when a wait starts and ends and when the schema is upgraded.
    :raises ConfigError: an unusable URL; :class:`suspid.errors.DataError` a fault, a schema it refuses.
    """
    return _open(url_or_path, read_only=read_only, upgrade=upgrade and not read_only, server_upgrade=False,
                 wait_s=wait_s, log=log)


def upgrade_database(url_or_path: str | Path, *, wait_s: float = DEFAULT_WAIT_S, log: Log | None = None) -> None:
    """Bring the database's schema to the newest revision, a PostgreSQL one too (``suspid fleet upgrade``).

    The caller has backed a PostgreSQL database up; an SQLite one is copied first as by :func:`open_database`.
    """
    _open(url_or_path, read_only=False, upgrade=True, server_upgrade=True, wait_s=wait_s, log=log).dispose()


def _open(url_or_path: str | Path, *, read_only: bool, upgrade: bool, server_upgrade: bool, wait_s: float,
          log: Log | None) -> Database:
    url = database_url(url_or_path)
    engine = _engine(url, read_only)
    db = Database(url, engine, sessionmaker(engine, expire_on_commit=False), read_only, wait_s, log or _silent)
    try:
        db.retrying(lambda: _prepare(db, upgrade=upgrade, server_upgrade=server_upgrade))
    except BaseException:
        engine.dispose()
        raise
    return db
