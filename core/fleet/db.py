"""Opening the monitoring database: a URL or a path, migrations, writes that survive concurrent writers.

SQLite is the embedded default (a path, or ``sqlite:///path``): no server to
set up. It runs in WAL mode with every write transaction started as ``BEGIN
IMMEDIATE`` and a long busy timeout, so that several runs finishing at once
queue for the write lock instead of failing ("database is locked"). A
depot server is a PostgreSQL URL (``postgresql://user@host:port/db``, driven by
psycopg 3). The schema is brought to the newest Alembic revision on opening,
under a lock (a lock file beside an SQLite database, an advisory lock on
PostgreSQL) so that writers opening a fresh database together migrate it once.
"""

from __future__ import annotations

import contextlib
import fcntl
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator, TypeVar

from alembic import command
from alembic.config import Config as AlembicConfig
from sqlalchemy import Engine, create_engine, event, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError, OperationalError
from sqlalchemy.orm import Session, sessionmaker

from suspid.errors import ConfigError

MIGRATIONS = Path(__file__).parent / "migrations"
T = TypeVar("T")
_ADVISORY_KEY = 0x5355_5350  # "SUSP": the PostgreSQL advisory lock held while migrating


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


@dataclass
class Database:
    """An open monitoring database: its engine and a session factory (see :func:`open_database`)."""

    url: str
    engine: Engine
    sessions: sessionmaker

    @property
    def backend(self) -> str:
        """``sqlite`` or ``postgresql``."""
        return self.engine.url.get_backend_name()

    @contextlib.contextmanager
    def session(self) -> Iterator[Session]:
        """A session in one transaction: committed on success, rolled back on any error."""
        with self.sessions() as session, session.begin():
            yield session

    @contextlib.contextmanager
    def read(self) -> Iterator[Session]:
        """A session for reading: on SQLite a deferred transaction, which does not queue for the write lock."""
        with self.sessions() as session:   # closing ends the transaction and keeps loaded objects readable
            session.connection(execution_options={"suspid_read": True})
            yield session

    def write(self, work: Callable[[Session], T], *, attempts: int = 20) -> T:
        """Run ``work(session)`` in one write transaction, retried when another writer holds the lock.

        SQLite's busy timeout already waits for the write lock; a PostgreSQL
        serialization failure or a lost race on a unique key is retried too.
        """
        for attempt in range(attempts):
            try:
                with self.session() as session:
                    return work(session)
            except OperationalError as exc:
                if attempt == attempts - 1 or "locked" not in str(exc).lower() and "serializ" not in str(exc):
                    raise
                time.sleep(0.05 * (attempt + 1))
        raise AssertionError("unreachable")

    def dispose(self) -> None:
        self.engine.dispose()


def _sqlite_pragmas(engine: Engine) -> None:
    @event.listens_for(engine, "connect")
    def _connect(dbapi_connection, _record):  # noqa: ANN001 - DB-API objects
        dbapi_connection.isolation_level = None   # SQLAlchemy emits BEGIN itself (below)
        cursor = dbapi_connection.cursor()
        cursor.execute("PRAGMA busy_timeout = 120000")
        cursor.execute("PRAGMA journal_mode = WAL")
        cursor.execute("PRAGMA foreign_keys = ON")
        cursor.close()

    @event.listens_for(engine, "begin")
    def _begin(connection):  # noqa: ANN001
        read = connection.get_execution_options().get("suspid_read", False)
        connection.exec_driver_sql("BEGIN" if read else "BEGIN IMMEDIATE")


@contextlib.contextmanager
def _migration_lock(engine: Engine) -> Iterator[None]:
    if engine.url.get_backend_name() == "sqlite":
        path = Path(engine.url.database or "")
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path.with_name(path.name + ".migrate.lock"), "a+") as fh:
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
    """Bring the schema to ``revision`` with the Alembic migrations shipped in ``suspid.fleet.migrations``."""
    cfg = AlembicConfig()
    cfg.set_main_option("script_location", str(MIGRATIONS))
    with _migration_lock(engine), engine.begin() as connection:
        cfg.attributes["connection"] = connection
        command.upgrade(cfg, revision)


def open_database(url_or_path: str | Path, *, upgrade: bool = True) -> Database:
    """Open (and create or upgrade) the monitoring database at ``url_or_path``.

    :param url_or_path: an SQLite file path, ``sqlite:///PATH`` or ``postgresql://USER@HOST:PORT/DB``.
    :param upgrade: apply the migrations up to the newest revision (the schema is created on first use).
    :raises ConfigError: an unusable URL; :class:`suspid.errors.DataError` when the server cannot be reached.
    """
    from suspid.errors import DataError

    url = database_url(url_or_path)
    engine = create_engine(url, pool_pre_ping=True)
    if engine.url.get_backend_name() == "sqlite":
        _sqlite_pragmas(engine)
    try:
        if upgrade:
            migrate(engine)
        else:
            with engine.connect():
                pass
    except OperationalError as exc:
        engine.dispose()
        shown = make_url(url).render_as_string(hide_password=True)
        raise DataError(f"database {shown}: {str(exc.orig).strip().splitlines()[0]}") from None
    return Database(url, engine, sessionmaker(engine, expire_on_commit=False))
