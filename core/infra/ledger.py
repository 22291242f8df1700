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
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np

from suspid.infra.files import canonical

SCHEMA_VERSION = 1

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
    run TEXT NOT NULL,          -- which loop: 'design', 'ego', or a study variant
    iteration INTEGER NOT NULL,
    record TEXT NOT NULL,       -- JSON: w, J, EI, J_max, hyperparameters, times
    PRIMARY KEY (run, iteration)
);
CREATE TABLE IF NOT EXISTS artifacts (key TEXT PRIMARY KEY, value BLOB NOT NULL, created_at REAL NOT NULL);
"""


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
            self.path.parent.mkdir(parents=True, exist_ok=True)
            conn = sqlite3.connect(self.path, timeout=self.timeout_s, isolation_level=None)
            conn.execute("PRAGMA journal_mode=WAL")
            conn.execute("PRAGMA synchronous=NORMAL")
            conn.execute(f"PRAGMA busy_timeout={int(self.timeout_s * 1000)}")
            conn.executescript(_SCHEMA)
            conn.execute("INSERT OR IGNORE INTO meta VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),))
            self._local.conn, self._local.pid = conn, os.getpid()
        return conn

    def close(self) -> None:
        conn = getattr(self._local, "conn", None)
        if conn is not None:
            conn.close()
            self._local.conn = None

    def _write(self, sql: str, params: tuple) -> None:
        conn = self.connection
        conn.execute("BEGIN IMMEDIATE")
        try:
            conn.execute(sql, params)
            conn.execute("COMMIT")
        except BaseException:
            conn.execute("ROLLBACK")
            raise

    # -- evaluations -----------------------------------------------------------
    def put(self, ev: Evaluation) -> None:
        """Commit one evaluation now (replacing a failed one with the same key)."""
        self._write(
            "INSERT OR REPLACE INTO evaluations VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (ev.key, json.dumps(canonical(ev.w)), ev.J, json.dumps(ev.psi) if ev.psi is not None else None,
             ev.status, ev.error, ev.wall_time_s, ev.finished_at, ev.worker or f"pid{os.getpid()}"))

    def get(self, key: str) -> Evaluation | None:
        row = self.connection.execute("SELECT * FROM evaluations WHERE key = ?", (key,)).fetchone()
        return self._row(row) if row else None

    def evaluations(self, status: str | None = None) -> Iterator[Evaluation]:
        """Every evaluation, in the order it was committed."""
        sql = "SELECT * FROM evaluations" + (" WHERE status = ?" if status else "") + " ORDER BY rowid"
        for row in self.connection.execute(sql, (status,) if status else ()):
            yield self._row(row)

    def count(self, status: str | None = "ok") -> int:
        sql = "SELECT COUNT(*) FROM evaluations" + (" WHERE status = ?" if status else "")
        return self.connection.execute(sql, (status,) if status else ()).fetchone()[0]

    @staticmethod
    def _row(row: tuple) -> Evaluation:
        key, w, J, psi, status, error, wall, finished, worker = row
        return Evaluation(key=key, w=json.loads(w), J=J, psi=json.loads(psi) if psi else None,
                          status=status, error=error, wall_time_s=wall, finished_at=finished, worker=worker)

    # -- optimiser iterations ----------------------------------------------------
    def put_iteration(self, run: str, iteration: int, record: Mapping[str, Any]) -> None:
        """Record one design point or EGO iteration (w, J, EI, hyperparameters, times)."""
        self._write("INSERT OR REPLACE INTO iterations VALUES (?, ?, ?)",
                    (run, int(iteration), json.dumps(canonical(record))))

    def iterations(self, run: str) -> list[dict[str, Any]]:
        rows = self.connection.execute(
            "SELECT record FROM iterations WHERE run = ? ORDER BY iteration", (run,)).fetchall()
        return [json.loads(r[0]) for r in rows]

    # -- artifacts (arrays, small files) -------------------------------------------
    def put_array(self, key: str, array: np.ndarray) -> None:
        """Store an array (e.g. reference-date spectra) under ``key``."""
        from io import BytesIO

        buf = BytesIO()
        np.save(buf, np.asarray(array), allow_pickle=False)
        self._write("INSERT OR REPLACE INTO artifacts VALUES (?, ?, ?)", (key, buf.getvalue(), time.time()))

    def get_array(self, key: str) -> np.ndarray | None:
        from io import BytesIO

        row = self.connection.execute("SELECT value FROM artifacts WHERE key = ?", (key,)).fetchone()
        return np.load(BytesIO(row[0]), allow_pickle=False) if row else None

    def clear(self) -> None:
        """Forget everything (``--fresh``)."""
        conn = self.connection
        conn.execute("BEGIN IMMEDIATE")
        for table in ("evaluations", "iterations", "artifacts"):
            conn.execute(f"DELETE FROM {table}")
        conn.execute("COMMIT")
