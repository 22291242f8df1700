"""The run ledger: an SQLite file that keeps every expensive result the moment it exists.

One evaluation is one parameter vector w through the simulator on the run's
segments, then the objective: its J, Ψ_k, timing, status and error text. It is
committed as soon as it finishes, keyed by :func:`evaluation_key`, a hash of
the simulator identity (plugin name and options), the parameter vector and the
identity of the data it was compared with. Running again over the same run
directory reuses every finished evaluation.

Durability and concurrency: the database is in WAL mode with
``synchronous=NORMAL``, so every committed transaction survives the process
being killed (SIGKILL); only an operating-system crash or power loss could
lose the last transactions. Each process (or thread) opens its own connection;
writes are short ``BEGIN IMMEDIATE`` transactions and wait for the lock up to
``timeout_s``, so several worker processes can write to one ledger.

Checks on open. The first connection of a process checks the file: an SQLite
header, ``PRAGMA quick_check``, the tables of a suspid ledger and its
``schema_version`` (:data:`SCHEMA_VERSION`). A file that fails one of them
raises :class:`suspid.errors.LedgerError` naming the file and the remedy
(move it away, or start over with ``--fresh``); nothing in it is changed.
:meth:`Ledger.clear` (``--fresh``) clears a sound ledger and moves a damaged
or foreign one aside as ``ledger.sqlite.damaged-<UTC time>`` (with its
``-wal`` and ``-shm`` files) without opening it. A write that fails (a full
disk, a read-only folder, a ledger locked for longer than ``timeout_s``)
raises :class:`~suspid.errors.LedgerError` with SQLite's own reason; what was
committed before is kept.
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import threading
import time
import warnings
from datetime import datetime, timezone
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np

from suspid.errors import LedgerError, LedgerWarning
from suspid.infra.arrays import load_npy_bytes, npy_bytes_problem
from suspid.infra.files import canonical

SCHEMA_VERSION = 2
"""Version of the records below. 2: the loop's record is one ``trials`` row per trial (its evaluation's
key, phase, status and the proposal's figures; w and J only in ``evaluations``). A version-1 ledger is
migrated when it is opened (:func:`migrate_v1`); another version is refused with the remedy."""

SQLITE_HEADER = b"SQLite format 3\x00"
_REMEDY = "move it away or run with --fresh (which sets it aside)"

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS evaluations (
    key TEXT PRIMARY KEY,
    w TEXT NOT NULL,            -- JSON name -> SI value
    J REAL,
    psi TEXT,                   -- JSON list, one value per channel
    status TEXT NOT NULL,       -- 'ok' or 'failed'
    error TEXT,
    wall_time_s REAL,
    finished_at REAL NOT NULL,
    worker TEXT
);
CREATE TABLE IF NOT EXISTS iterations (
    run TEXT NOT NULL,          -- 'trials', or 'history/<run id>/trials' for another run of the folder
    iteration INTEGER NOT NULL, -- the trial id
    record TEXT NOT NULL,       -- JSON: key (of evaluations), phase, status, EI, J_max, hyperparameters, times
    PRIMARY KEY (run, iteration)
);
CREATE TABLE IF NOT EXISTS artifacts (key TEXT PRIMARY KEY, value BLOB NOT NULL, created_at REAL NOT NULL);
"""

_COLUMNS = {
    "meta": ["key", "value"],
    "evaluations": ["key", "w", "J", "psi", "status", "error", "wall_time_s", "finished_at", "worker"],
    "iterations": ["run", "iteration", "record"],
    "artifacts": ["key", "value", "created_at"],
}
"""The tables of a suspid ledger and their columns, as created by the schema above."""


ALIAS_PREFIX = "alias:"
"""The ``worker`` of an evaluation filed again under a newer key (:meth:`Ledger.get_migrating`), followed by the
key it was found under: a copy, not a simulation, so :meth:`Ledger.count` does not count it."""
_NOT_ALIAS = f"(worker IS NULL OR substr(worker, 1, {len(ALIAS_PREFIX)}) != '{ALIAS_PREFIX}')"


def stable_hash(*parts: Any) -> str:
    """SHA-256 hex digest of the canonical JSON of ``parts``."""
    text = json.dumps(canonical(list(parts)), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def evaluation_key(simulator_identity: Mapping[str, Any], w: Mapping[str, float], data_identity: str) -> str:
    """The ledger key of one evaluation.

    :param simulator_identity: ``Simulator.identity()`` (plugin name and options).
    :param w: parameter name -> SI value.
    :param data_identity: a hash of everything else J depends on (measured
        spectra, noise paths, objective and weights, spectra options).
    """
    return stable_hash("evaluation", simulator_identity, dict(w), data_identity)


@dataclass
class Evaluation:
    """One finished evaluation of J at ``w``."""

    key: str
    w: dict[str, float]
    J: float | None
    psi: list[float] | None
    status: str = "ok"
    error: str | None = None
    wall_time_s: float | None = None
    finished_at: float = field(default_factory=time.time)
    worker: str | None = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def _reason(exc: BaseException) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def write_error(path: Path, exc: sqlite3.Error, timeout_s: float) -> LedgerError:
    """A one-line LedgerError for an SQLite error raised while writing or reading ``path``."""
    reason = _reason(exc)
    low = reason.lower()
    if "locked" in low or "busy" in low:
        return LedgerError(f"{path}: the run ledger stayed locked by another process for more than "
                           f"{timeout_s:g} s ({reason})")
    if "malformed" in low or "not a database" in low or "corrupt" in low:
        return LedgerError(f"{path}: the run ledger is damaged ({reason}); {_REMEDY}")
    if isinstance(exc, sqlite3.OperationalError) or "i/o" in low or "full" in low or "readonly" in low:
        return LedgerError(f"{path}: cannot write the run ledger: disk full or not writable ({reason})")
    return LedgerError(f"{path}: run ledger error ({reason})")


def count_finished(path: str | Path) -> int | None:
    """Successful evaluations in the ledger at ``path``, read without opening it for writing.

    For another process's view of a run (the CLI after Ctrl-C, tests watching a run):
    :returns: the count, or None when the file is absent, locked past the timeout or not readable.
    """
    path = Path(path)
    if not path.exists():
        return None
    try:
        conn = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=5.0)
        try:
            return conn.execute(f"SELECT COUNT(*) FROM evaluations WHERE status = 'ok' AND {_NOT_ALIAS}").fetchone()[0]
        finally:
            conn.close()
    except sqlite3.Error:
        return None


def check_ledger_file(path: str | Path) -> None:
    """Check, without changing anything, that ``path`` is absent, empty or a sound suspid ledger.

    :raises LedgerError: not an SQLite database, damaged (``PRAGMA quick_check``),
        other tables (not a suspid ledger), or a ``schema_version`` other than this one's
        and 1 (which the run migrates); one line naming the file and the remedy.
    """
    path = Path(path)
    if not _check_header(path):
        return
    try:
        conn = sqlite3.connect(f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=5.0)
    except sqlite3.Error as exc:
        raise LedgerError(f"{path}: cannot open the run ledger ({_reason(exc)}); {_REMEDY}") from None
    try:
        _check_connection(conn, path, migrate=False)   # a version-1 ledger is migrated when the run opens it
    finally:
        conn.close()


def _check_header(path: Path) -> bool:
    """False for an absent or empty file; True for an SQLite file; else LedgerError."""
    try:
        if not path.exists() or path.stat().st_size == 0:
            return False
        with open(path, "rb") as fh:
            head = fh.read(len(SQLITE_HEADER))
    except OSError as exc:
        raise LedgerError(f"{path}: cannot read the run ledger ({(exc.strerror or _reason(exc)).lower()})") from None
    if head != SQLITE_HEADER:
        raise LedgerError(f"{path}: not an SQLite database, so not a run ledger; {_REMEDY}")
    return True


def _check_connection(conn: sqlite3.Connection, path: Path, migrate: bool = True) -> bool:
    """Integrity, tables and schema version of an open ledger (see :func:`check_ledger_file`); a
    version-1 ledger is migrated (:func:`migrate_v1`) when ``migrate``, else accepted as it is.

    :returns: True when the ledger is complete (every table and its schema version), False when it
        still has to be created.
    """
    try:
        problems = [r[0] for r in conn.execute("PRAGMA quick_check").fetchall()]
        if problems != ["ok"]:
            first = " ".join(" ".join(problems).split("*** in database main ***")).split()
            raise LedgerError(f"{path}: the run ledger is damaged (quick_check: {' '.join(first)[:160]}); "
                              f"{_REMEDY}")
        tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")
                  if not r[0].startswith("sqlite_")}
        if not tables:
            return False
        if tables != set(_COLUMNS):
            raise LedgerError(f"{path}: not a suspid run ledger (tables: {', '.join(sorted(tables))}); {_REMEDY}")
        for table, columns in _COLUMNS.items():
            found = [r[1] for r in conn.execute(f"PRAGMA table_info({table})")]
            if found != columns:
                raise LedgerError(f"{path}: not a suspid run ledger (table {table} has columns "
                                  f"{', '.join(found)}); {_REMEDY}")
        row = conn.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()
    except sqlite3.Error as exc:
        if "locked" in str(exc).lower() or "busy" in str(exc).lower():
            return False   # a writer is creating it right now
        raise LedgerError(f"{path}: the run ledger is damaged ({_reason(exc)}); {_REMEDY}") from None
    if row is None:
        return False   # created, schema version not yet written
    if row[0] == "1":
        if migrate:
            migrate_v1(conn, path)
        return True
    if row[0] != str(SCHEMA_VERSION):
        newer = row[0].isdigit() and int(row[0]) > SCHEMA_VERSION
        raise LedgerError(f"{path}: the run ledger has schema version {row[0]}, this suspid reads version "
                          f"{SCHEMA_VERSION}" + (" (written by a newer suspid: upgrade suspid, or " if newer
                                                 else " (") + f"{_REMEDY})")
    return True


V1_LOOP_RUNS = ("evaluations", "design")
"""Version-1 loop rows that repeated (w, J) of the evaluations: replaced by ``trials`` rows on migration."""


def migrate_v1(conn: sqlite3.Connection, path: Path) -> None:
    """Migrate a version-1 ledger to version 2 in one transaction.

    Version 1 wrote each evaluation's (w, J) three times: the ``evaluations`` table, an
    ``evaluations`` loop row (by its index in the run) and the optimiser's own row
    (``design``, ``ego``, ...). Each ``evaluations`` loop row (of every run kept in the
    folder, ``history/<id>/`` included) becomes a ``trials`` row with the same index, holding
    the key of its evaluation (found by its w) and its status; the ``evaluations`` and
    ``design`` loop rows are removed. The optimisers' logs (``ego``, ``refine``, ...) stay as
    they were written. Evaluations, artifacts and meta are not touched, so a run resumes and
    reads every finished evaluation.

    :raises LedgerError: the migration could not be written (the ledger is left as it was).
    """
    try:
        conn.execute("BEGIN IMMEDIATE")
        if conn.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()[0] != "1":
            conn.execute("ROLLBACK")   # another process migrated it meanwhile
            return
        by_w = {canonical_w(w): key for key, w in conn.execute("SELECT key, w FROM evaluations")}
        rows = conn.execute("SELECT run, iteration, record FROM iterations").fetchall()
        for run, i, record in rows:
            prefix, _, loop = run.rpartition("/")
            if loop != "evaluations":
                continue
            r = json.loads(record)
            key = by_w.get(canonical_w(json.dumps(r.get("w")))) if r.get("w") is not None else None
            trial = {"key": key, "id": int(i), "phase": "v1", "status": "ok" if r.get("J") is not None else "failed"}
            conn.execute("INSERT OR REPLACE INTO iterations VALUES (?, ?, ?)",
                         (f"{prefix}/trials" if prefix else "trials", int(i), json.dumps(canonical(trial))))
        for run, _, _ in rows:
            if run.rpartition("/")[2] in V1_LOOP_RUNS:
                conn.execute("DELETE FROM iterations WHERE run = ?", (run,))
        conn.execute("UPDATE meta SET value = ? WHERE key = 'schema_version'", (str(SCHEMA_VERSION),))
        conn.execute("COMMIT")
    except (sqlite3.Error, ValueError, TypeError) as exc:
        if conn.in_transaction:
            conn.execute("ROLLBACK")
        raise LedgerError(f"{path}: the run ledger of schema version 1 could not be migrated to version "
                          f"{SCHEMA_VERSION} ({_reason(exc)}); {_REMEDY}") from None


def canonical_w(text: str) -> str:
    """A parameter mapping's JSON text in one spelling (sorted keys), to find an evaluation by its w."""
    return json.dumps(json.loads(text), sort_keys=True)


def move_aside(path: str | Path) -> Path | None:
    """Rename a ledger (and its ``-wal``/``-shm`` files) to ``<name>.damaged-<UTC time>``, unopened.

    :returns: the new path of the ledger, or None when there was no file.
    """
    path = Path(path)
    stamp = datetime.now(timezone.utc).strftime("%Y%m%dT%H%M%S.%fZ")
    target = path.with_name(f"{path.name}.damaged-{stamp}")
    moved = None
    for suffix in ("", "-wal", "-shm", "-journal"):
        src = path.with_name(path.name + suffix)
        if src.exists():
            try:
                os.replace(src, target.with_name(target.name + suffix))
            except OSError as exc:
                raise LedgerError(f"{src}: cannot move the run ledger aside "
                                  f"({(exc.strerror or _reason(exc)).lower()})") from None
            if suffix == "":
                moved = target
    return moved


class Ledger:
    """An SQLite ledger at ``path`` (created on first use)."""

    def __init__(self, path: str | Path, timeout_s: float = 60.0) -> None:
        self.path = Path(path)
        self.timeout_s = timeout_s
        self._local = threading.local()

    # -- connection ------------------------------------------------------------
    @property
    def connection(self) -> sqlite3.Connection:
        """This thread's connection (one per thread and per process)."""
        conn = getattr(self._local, "conn", None)
        pid = getattr(self._local, "pid", None)
        if conn is None or pid != os.getpid():
            conn = self._connect()
            self._local.conn, self._local.pid = conn, os.getpid()
        return conn

    def _connect(self) -> sqlite3.Connection:
        """A checked connection (module docstring); every failure is one LedgerError naming the file."""
        _check_header(self.path)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise LedgerError(f"{self.path}: cannot create the folder of the run ledger "
                              f"({(exc.strerror or _reason(exc)).lower()})") from None
        conn = None
        try:
            conn = sqlite3.connect(self.path, timeout=self.timeout_s, isolation_level=None)
            conn.execute(f"PRAGMA busy_timeout={int(self.timeout_s * 1000)}")
            complete = _check_connection(conn, self.path)   # before anything is written to the file
            if not complete:   # (a complete one is opened without writing: no wait for a busy writer)
                conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
            if not complete:
                conn.executescript(_SCHEMA)
                conn.execute("INSERT OR IGNORE INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),))
        except LedgerError:
            conn.close()
            raise
        except sqlite3.Error as exc:
            if conn is not None:
                conn.close()
            raise write_error(self.path, exc, self.timeout_s) from exc
        return conn

    @classmethod
    def fresh(cls, path: str | Path, timeout_s: float = 60.0,
              log: Callable[[str], None] | None = None) -> "Ledger":
        """The ledger at ``path`` emptied for ``--fresh`` (:meth:`clear`, which copes with a damaged file)."""
        ledger = cls(path, timeout_s)
        ledger.clear(log)
        return ledger

    def close(self) -> None:
        conn = getattr(self._local, "conn", None)
        if conn is not None:
            conn.close()
            self._local.conn = None

    def _write(self, sql: str, params: tuple) -> None:
        self._transaction([(sql, params)])

    def _transaction(self, statements: list[tuple[str, tuple]]) -> None:
        """Run ``statements`` in one write transaction; a failure rolls back and raises LedgerError.

        A failed COMMIT (disk full, I/O error) is reported with SQLite's reason;
        when SQLite has already rolled the transaction back, no second error
        hides the first one.
        """
        conn = self.connection
        try:
            conn.execute("BEGIN IMMEDIATE")
            try:
                for sql, params in statements:
                    conn.execute(sql, params)
                conn.execute("COMMIT")
            except BaseException:
                if conn.in_transaction:
                    try:
                        conn.execute("ROLLBACK")
                    except sqlite3.Error:
                        pass   # the error being raised says what went wrong
                raise
        except sqlite3.Error as exc:
            raise write_error(self.path, exc, self.timeout_s) from exc

    def _read(self, sql: str, params: tuple = ()) -> list[tuple]:
        """All rows of a query; an SQLite error (a page damaged since the checks) raises LedgerError."""
        try:
            return self.connection.execute(sql, params).fetchall()
        except sqlite3.Error as exc:
            raise write_error(self.path, exc, self.timeout_s) from exc

    # -- meta ------------------------------------------------------------------------
    def get_meta(self, key: str) -> str | None:
        """A value of the meta table (``schema_version``, ...), or None."""
        rows = self._read("SELECT value FROM meta WHERE key = ?", (key,))
        return rows[0][0] if rows else None

    def set_meta(self, key: str, value: str) -> None:
        """Set a value of the meta table."""
        self._write("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, str(value)))

    # -- evaluations -----------------------------------------------------------
    def put(self, ev: Evaluation) -> None:
        """Commit one evaluation now (replacing a failed one with the same key)."""
        self._write(
            "INSERT OR REPLACE INTO evaluations VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (ev.key, json.dumps(canonical(ev.w)), ev.J, json.dumps(ev.psi) if ev.psi is not None else None,
             ev.status, ev.error, ev.wall_time_s, ev.finished_at, ev.worker or f"pid{os.getpid()}"))

    def get(self, key: str) -> Evaluation | None:
        rows = self._read("SELECT * FROM evaluations WHERE key = ?", (key,))
        return self._row(rows[0]) if rows else None

    def get_migrating(self, key: str, legacy: Sequence[str | None] = ()) -> Evaluation | None:
        """The evaluation under ``key``, else under the first of the ``legacy`` keys that has one (keys a ledger
        written by an earlier suspid used for the same evaluation), which is then committed under ``key`` too, so
        that the next lookup finds it at once."""
        ev = self.get(key)
        for old in legacy:
            if ev is not None:
                break
            if old and old != key and (ev := self.get(old)) is not None:
                ev = replace(ev, key=key, worker=ALIAS_PREFIX + old)
                self.put(ev)
        return ev

    def evaluations(self, status: str | None = None) -> Iterator[Evaluation]:
        """Every evaluation, in the order it was committed."""
        sql = "SELECT * FROM evaluations" + (" WHERE status = ?" if status else "") + " ORDER BY rowid"
        for row in self._read(sql, (status,) if status else ()):
            yield self._row(row)

    def count(self, status: str | None = "ok") -> int:
        """Evaluations of that status (any with None), each once: a copy filed under a newer key is not counted."""
        sql = f"SELECT COUNT(*) FROM evaluations WHERE {_NOT_ALIAS}" + (" AND status = ?" if status else "")
        return self._read(sql, (status,) if status else ())[0][0]

    def _damaged_row(self, where: str, exc: BaseException | str) -> LedgerError:
        """The one error for a row that SQLite reads but suspid cannot decode (edited or written by other code)."""
        reason = exc if isinstance(exc, str) else f"{type(exc).__name__}: {_reason(exc)}"
        return LedgerError(f"{self.path}: the run ledger is damaged ({where}: {reason[:160]}); {_REMEDY}")

    def _json(self, text: Any, where: str) -> Any:
        """A JSON column decoded; anything else (not text, not JSON) raises :meth:`_damaged_row`."""
        try:
            return json.loads(text)
        except (TypeError, ValueError) as exc:   # JSONDecodeError is a ValueError
            raise self._damaged_row(where, exc) from None

    def _row(self, row: tuple) -> Evaluation:
        key, w, J, psi, status, error, wall, finished, worker = row
        where = f"evaluation {str(key)[:16]}"
        w = self._json(w, f"{where}, column w")
        if not isinstance(w, dict) or not all(isinstance(v, (int, float)) for v in w.values()):
            raise self._damaged_row(f"{where}, column w", "not a mapping of names to numbers")
        if status == "ok" and not (isinstance(J, (int, float)) and not np.isnan(J)):   # SQLite keeps NaN as NULL
            raise self._damaged_row(f"{where}, column J", f"{J!r} is not a number")
        return Evaluation(key=key, w=w, J=J, psi=self._json(psi, f"{where}, column psi") if psi else None,
                          status=status, error=error, wall_time_s=wall, finished_at=finished, worker=worker)

    # -- optimiser iterations ----------------------------------------------------
    def put_iteration(self, run: str, iteration: int, record: Mapping[str, Any]) -> None:
        """Record one design point or EGO iteration (w, J, EI, hyperparameters, times)."""
        self._write("INSERT OR REPLACE INTO iterations VALUES (?, ?, ?)",
                    (run, int(iteration), json.dumps(canonical(record))))

    def put_trial(self, trial_id: int, record: Mapping[str, Any]) -> None:
        """Record one trial of the run's loop: its evaluation's ``key``, phase, status and the proposal's
        figures (EI, J_max, hyperparameters, times). w and J stay in the evaluation (:meth:`trials`)."""
        self.put_iteration("trials", trial_id, record)

    def trials(self, run: str = "trials") -> list[dict[str, Any]]:
        """The trials of the run's loop in id order, each with ``w`` and ``J`` of its evaluation
        (``J`` None for a failed one); ``run``: ``history/<run id>/trials`` for another run of the folder."""
        out = []
        for row in self.iterations(run):
            ev = self.get(row["key"]) if row.get("key") else None
            out.append({**row, "w": ev.w if ev is not None else None, "J": ev.J if ev is not None and ev.ok else None})
        return out

    def iterations(self, run: str) -> list[dict[str, Any]]:
        rows = self._read("SELECT iteration, record FROM iterations WHERE run = ? ORDER BY iteration", (run,))
        return [self._json(r, f"iteration {i} of {run}") for i, r in rows]

    def all_iterations(self) -> list[tuple[str, int, dict[str, Any]]]:
        """Every recorded iteration as ``(run, iteration, record)``, ordered by run name, then iteration."""
        rows = self._read("SELECT run, iteration, record FROM iterations ORDER BY run, iteration")
        return [(run, int(i), self._json(record, f"iteration {i} of {run}")) for run, i, record in rows]

    HISTORY_PREFIX = "history/"
    """Iteration rows of a run that is not the current one are kept under ``history/<run id>/<loop>``."""

    def select_run(self, run_id: str, previous: str | None = None) -> None:
        """Make ``run_id``'s optimiser records the current ones, keeping every other run's.

        The iteration rows (``evaluations``, ``design``, ``ego``, ...) of the run
        directory's current run (the meta key ``run_id``, else ``previous``: the
        run that wrote a ledger older than this key) move under
        ``history/<its id>/``, and ``run_id``'s own rows, from an earlier run of
        that config, move back; one transaction. Evaluations (the content-keyed
        cache of J) are shared by every run and not touched.
        """
        current = self.get_meta("run_id") or previous
        if current == run_id:
            if self.get_meta("run_id") != run_id:
                self.set_meta("run_id", run_id)
            return
        prefix, n = self.HISTORY_PREFIX, len(self.HISTORY_PREFIX)
        statements: list[tuple[str, tuple]] = []
        if current is not None:
            statements.append(("UPDATE iterations SET run = ? || run WHERE substr(run, 1, ?) != ?",
                               (f"{prefix}{current}/", n, prefix)))
        else:   # rows of an unknown earlier run: kept apart all the same
            statements.append(("UPDATE iterations SET run = ? || run WHERE substr(run, 1, ?) != ?",
                               (f"{prefix}earlier/", n, prefix)))
        mine = f"{prefix}{run_id}/"
        statements += [("UPDATE iterations SET run = substr(run, ?) WHERE substr(run, 1, ?) = ?",
                        (len(mine) + 1, len(mine), mine)),
                       ("INSERT OR REPLACE INTO meta VALUES (?, ?)", ("run_id", run_id))]
        self._transaction(statements)

    # -- artifacts (arrays, small files) -------------------------------------------
    def put_array(self, key: str, array: np.ndarray) -> None:
        """Store an array (e.g. reference-date spectra) under ``key``."""
        from io import BytesIO

        buf = BytesIO()
        np.save(buf, np.asarray(array), allow_pickle=False)
        self._write("INSERT OR REPLACE INTO artifacts VALUES (?, ?, ?)", (key, buf.getvalue(), time.time()))

    def get_array(self, key: str) -> np.ndarray | None:
        """The array stored under ``key`` (None when there is none); its declared size is checked against the
        bytes stored before it is allocated, and an object array (pickled) is refused, never unpickled."""
        rows = self._read("SELECT value FROM artifacts WHERE key = ?", (key,))
        if not rows:
            return None
        blob = rows[0][0]
        if not isinstance(blob, bytes):
            raise self._damaged_row(f"array {key[:24]}", f"a {type(blob).__name__}, not an array")
        problem = npy_bytes_problem(blob)
        if problem is not None:
            raise self._damaged_row(f"array {key[:24]}", problem)
        try:
            return load_npy_bytes(blob, str(self.path))
        except (TypeError, ValueError, OSError, EOFError) as exc:
            raise self._damaged_row(f"array {key[:24]}", exc) from None

    def get_array_migrating(self, key: str, legacy: Sequence[str | None] = ()) -> np.ndarray | None:
        """:meth:`get_array` under ``key``, else under the first ``legacy`` key that has it (stored under ``key``
        too): :meth:`get_migrating` for arrays."""
        found = self.get_array(key)
        for old in legacy:
            if found is not None:
                break
            if old and old != key and (found := self.get_array(old)) is not None:
                self.put_array(key, found)
        return found

    def clear(self, log: Callable[[str], None] | None = None) -> None:
        """Forget every result (``--fresh``).

        A damaged or foreign file (see :func:`check_ledger_file`) is not opened
        but moved aside (:func:`move_aside`) and an empty ledger started; where
        it went is passed to ``log``, or else issued as a :class:`LedgerWarning`.
        """
        if getattr(self._local, "conn", None) is None:
            try:
                check_ledger_file(self.path)
            except LedgerError as exc:
                moved = move_aside(self.path)
                message = f"{exc}; moved to {moved}, starting an empty ledger"
                if log is not None:
                    log(message)
                else:
                    warnings.warn(message, LedgerWarning, stacklevel=2)
        self._transaction([(f"DELETE FROM {table}", ()) for table in ("evaluations", "iterations", "artifacts")])
