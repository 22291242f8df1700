"""What went wrong with the monitoring database, in one line: a driver's error sorted into a kind of fault.

SQLite says what happened by its result code (``SQLITE_FULL``, ``SQLITE_CORRUPT``,
``SQLITE_READONLY``, ...); PostgreSQL by its SQLSTATE (``53100`` disk full,
``25006`` read-only transaction, class ``08`` and ``57P0x`` a lost or refused
connection). :func:`fault_of` turns the error SQLAlchemy raised into a
:class:`Fault` of one of :data:`KINDS`; :meth:`Fault.message` is the line a
user reads. Three kinds are passing conditions that a writer retries
(:data:`TRANSIENT`): another writer holds the lock (``busy``), the server cannot
be reached or dropped the connection (``unreachable``), two writers raced for
the same unique key (``conflict``: the retry finds the other's row). Every other
kind ends the operation, which has written nothing (both backends commit a
transaction whole or not at all).
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path

from sqlalchemy.exc import DBAPIError

KINDS = ("busy", "unreachable", "conflict", "full", "io", "damaged", "readonly", "cantopen")
TRANSIENT = frozenset({"busy", "unreachable", "conflict"})

_SQLITE = {"SQLITE_BUSY": "busy", "SQLITE_LOCKED": "busy", "SQLITE_FULL": "full", "SQLITE_IOERR": "io",
           "SQLITE_CORRUPT": "damaged", "SQLITE_NOTADB": "damaged", "SQLITE_READONLY": "readonly",
           "SQLITE_CANTOPEN": "cantopen", "SQLITE_PERM": "cantopen", "SQLITE_CONSTRAINT_UNIQUE": "conflict",
           "SQLITE_CONSTRAINT_PRIMARYKEY": "conflict"}
_PG = {"08": "unreachable", "57P01": "unreachable", "57P02": "unreachable", "57P03": "unreachable",
       "53300": "unreachable", "40001": "busy", "40P01": "busy", "23505": "conflict", "53100": "full",
       "25006": "readonly", "3D000": "cantopen", "28": "cantopen", "42501": "readonly", "XX001": "damaged",
       "XX002": "damaged", "58030": "io"}


@dataclass(frozen=True)
class Fault:
    """One fault of the database: its kind (one of :data:`KINDS`) and the driver's first line."""

    kind: str
    detail: str

    @property
    def transient(self) -> bool:
        return self.kind in TRANSIENT

    def message(self, label: str, sqlite_file: Path | None = None) -> str:
        """The line a user reads: what the database ``label`` did, and what to do.

        :param sqlite_file: the SQLite file (its disk's free space is said on a write error).
        """
        free = ""
        if sqlite_file is not None and self.kind in ("full", "io"):
            try:
                free = f"; {_bytes(shutil.disk_usage(sqlite_file.parent).free)} free on its disk"
            except OSError:
                pass
        return {
            "busy": f"{label}: still locked by another writer ({self.detail})",
            "unreachable": f"{label}: the database server cannot be reached ({self.detail})",
            "conflict": f"{label}: another writer keeps recording the same run ({self.detail})",
            "full": f"{label}: the disk is full ({self.detail}{free})",
            "io": f"{label}: the disk failed a read or write ({self.detail}{free})",
            "damaged": f"{label}: damaged database ({self.detail}); nothing was written to it: restore it from a "
                       f"backup or move it aside" + (" (`sqlite3 FILE .recover` may save its records)"
                                                     if sqlite_file is not None else ""),
            "readonly": f"{label}: read-only ({self.detail}); nothing was written",
            "cantopen": f"{label}: cannot be opened ({self.detail})",
        }[self.kind]


def _bytes(n: int) -> str:
    for unit in ("bytes", "KB", "MB", "GB"):
        if n < 1024 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n} bytes"


def first_line(exc: BaseException) -> str:
    """The first line of an error's text (a driver's message without SQLAlchemy's background link)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def fault_of(exc: DBAPIError) -> Fault | None:
    """The fault behind an error SQLAlchemy raised, or None when it is not a fault of the database (a bug)."""
    orig = exc.orig
    detail = first_line(orig) if orig is not None else first_line(exc)
    name = getattr(orig, "sqlite_errorname", None)
    if name is not None:   # SQLITE_IOERR_WRITE is an SQLITE_IOERR; SQLITE_CONSTRAINT_NOTNULL is a bug
        kind = _SQLITE.get(name) or _SQLITE.get("_".join(name.split("_")[:2]))
        return Fault(kind, detail) if kind else None
    sqlstate = getattr(orig, "sqlstate", None)
    if sqlstate is not None:
        kind = _PG.get(sqlstate) or _PG.get(sqlstate[:2])
        return Fault(kind, detail) if kind else None
    if exc.connection_invalidated or type(orig).__name__ == "OperationalError" and "psycopg" in \
            type(orig).__module__:
        return Fault("unreachable", detail)   # refused, reset or timed out before the server could answer
    return None
