"""A damaged, foreign or unwritable run ledger: one-line LedgerErrors, and --fresh sets a bad file aside.

Every case: opening the ledger raises a :class:`suspid.errors.LedgerError` of
one line naming the file and the remedy, and the file is left byte for byte
as it was; :meth:`Ledger.fresh` then moves it (with its -wal/-shm files) to
``ledger.sqlite.damaged-<UTC time>`` unopened and starts an empty ledger.
"""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

from suspid.errors import LedgerError, LedgerWarning, SuspidError
from suspid.infra.ledger import SCHEMA_VERSION, Evaluation, Ledger, check_ledger_file, move_aside


def filled(path: Path, n: int = 50) -> Path:
    """A sound ledger with ``n`` evaluations and an array, closed."""
    led = Ledger(path)
    for i in range(n):
        led.put(Evaluation(f"k{i}", {"x": float(i)}, J=-float(i), psi=[0.0, 1.0], wall_time_s=0.5))
    led.put_array("y", np.arange(2000.0))
    led.close()
    return path


def assert_one_line(exc: BaseException, *fragments: str) -> None:
    msg = str(exc)
    assert isinstance(exc, SuspidError) and "\n" not in msg and "Traceback" not in msg, msg
    for f in fragments:
        assert f in msg, f"{f!r} not in {msg!r}"


def _sql(path: Path, *statements: str) -> None:
    conn = sqlite3.connect(path)
    for s in statements:
        conn.execute(s)
    conn.commit()
    conn.close()


def _truncated(p: Path) -> None:
    data = filled(p).read_bytes()
    p.write_bytes(data[: len(data) // 3])


def _pages_overwritten(p: Path) -> None:
    data = bytearray(filled(p).read_bytes())
    data[4096 + 8: 4096 + 8 + 3000] = np.random.default_rng(3).integers(0, 256, 3000, dtype=np.uint8).tobytes()
    p.write_bytes(bytes(data))


DAMAGED: dict[str, tuple[Callable[[Path], None], str]] = {
    "random_bytes": (lambda p: p.write_bytes(np.random.default_rng(0).integers(0, 256, 8192, dtype=np.uint8)
                                             .tobytes()), "not an SQLite database"),
    "text_file": (lambda p: p.write_text("key,J\nk1,-3.2\n"), "not an SQLite database"),
    "truncated": (_truncated, "damaged"),
    "pages_overwritten": (_pages_overwritten, "damaged"),
    "foreign_sqlite_schema": (lambda p: _sql(p, "CREATE TABLE users (id INTEGER, name TEXT)",
                                             "INSERT INTO users VALUES (1, 'a')"), "not a suspid run ledger"),
    "suspid_tables_other_columns": (lambda p: (filled(p), _sql(p, "ALTER TABLE evaluations ADD COLUMN extra TEXT")),
                                    "table evaluations has columns"),
    "newer_schema_version": (lambda p: (filled(p), _sql(p, f"UPDATE meta SET value = '{SCHEMA_VERSION + 1}' "
                                                           f"WHERE key = 'schema_version'")),
                             f"schema version {SCHEMA_VERSION + 1}, this suspid reads version {SCHEMA_VERSION} "
                             f"(written by a newer suspid"),
    "garbled_schema_version": (lambda p: (filled(p), _sql(p, "UPDATE meta SET value = 'x' "
                                                             "WHERE key = 'schema_version'")), "schema version x"),
}


@pytest.mark.parametrize("name", sorted(DAMAGED))
def test_bad_ledger_refused_untouched_then_fresh_sets_it_aside(tmp_path, name):
    make, fragment = DAMAGED[name]
    path = tmp_path / "ledger.sqlite"
    make(path)
    before = path.read_bytes()
    with pytest.raises(LedgerError) as err:
        Ledger(path).count()
    assert_one_line(err.value, str(path), fragment, "move it away or run with --fresh")
    with pytest.raises(LedgerError):
        check_ledger_file(path)
    assert path.read_bytes() == before                       # nothing written into a file we refused
    said = []
    led = Ledger.fresh(path, log=said.append) if "schema" not in name else Ledger(path)
    if "schema" in name:    # what --fresh does today: Ledger(path).clear(), which warns where the file went
        with pytest.warns(LedgerWarning) as caught:
            led.clear()
        said = [str(w.message) for w in caught]
    led.put(Evaluation("new", {"x": 1.0}, J=1.0, psi=[1.0]))
    assert led.count() == 1
    aside = [p for p in tmp_path.iterdir() if ".damaged-" in p.name and not p.name.endswith(("-wal", "-shm"))]
    assert len(aside) == 1 and aside[0].read_bytes() == before   # the bad file is kept, as it was
    assert len(said) == 1 and str(aside[0]) in said[0]
    led.close()


def _object_array(p: Path) -> None:
    import io

    buf = io.BytesIO()
    np.save(buf, np.array([{"a": 1}, None], dtype=object), allow_pickle=True)   # a pickle: never unpickled
    _sql(filled(p), "DELETE FROM artifacts")
    conn = sqlite3.connect(p)
    conn.execute("INSERT INTO artifacts VALUES ('y', ?, 0)", (buf.getvalue(),))
    conn.commit()
    conn.close()


# rows SQLite reads but suspid cannot decode (edited by hand, written by other code): (damage, read, fragment)
DAMAGED_ROWS: dict[str, tuple[Callable[[Path], None], Callable[[Ledger], object], str]] = {
    "J_edited_to_NaN_text": (lambda p: _sql(filled(p), "UPDATE evaluations SET J = 'NaN' WHERE key = 'k3'"),
                             lambda led: list(led.evaluations()), "evaluation k3, column J: 'NaN' is not a number"),
    "J_edited_to_null": (lambda p: _sql(filled(p), "UPDATE evaluations SET J = NULL WHERE key = 'k3'"),
                         lambda led: led.get("k3"), "evaluation k3, column J: None is not a number"),
    "w_not_json": (lambda p: _sql(filled(p), "UPDATE evaluations SET w = '{\"x\": nan' WHERE key = 'k5'"),
                   lambda led: led.get("k5"), "evaluation k5, column w: JSONDecodeError"),
    "w_not_a_mapping": (lambda p: _sql(filled(p), "UPDATE evaluations SET w = '[1, 2]' WHERE key = 'k5'"),
                        lambda led: list(led.evaluations()), "column w: not a mapping of names to numbers"),
    "psi_not_json": (lambda p: _sql(filled(p), "UPDATE evaluations SET psi = 'NaN,' WHERE key = 'k1'"),
                     lambda led: led.get("k1"), "evaluation k1, column psi"),
    "iteration_record_J_nan": (lambda p: (filled(p), _sql(p, "INSERT INTO iterations VALUES "
                                                             "('ego', 0, '{\"J\": nan}')")),
                               lambda led: led.iterations("ego"), "iteration 0 of ego: JSONDecodeError"),
    "pickled_object_array": (_object_array, lambda led: led.get_array("y"), "array y: holds Python objects (object), expected numbers"),
}


@pytest.mark.parametrize("name", sorted(DAMAGED_ROWS))
def test_a_damaged_row_is_a_ledger_error_naming_the_file(tmp_path, name):
    """A row edited to something suspid cannot decode: one LedgerError naming the file, the row and the remedy
    (it was a JSONDecodeError or a ValueError, reported as a bug); nothing written, --fresh starts over."""
    damage, read, fragment = DAMAGED_ROWS[name]
    path = tmp_path / "ledger.sqlite"
    damage(path)
    before = path.read_bytes()
    led = Ledger(path)
    with pytest.raises(LedgerError) as err:
        read(led)
    assert_one_line(err.value, str(path), "the run ledger is damaged", fragment, "move it away or run with --fresh")
    led.close()
    assert path.read_bytes() == before
    assert Ledger.fresh(path).count() == 0


def test_fresh_clears_a_sound_ledger_in_place(tmp_path):
    path = filled(tmp_path / "ledger.sqlite")
    led = Ledger.fresh(path)
    assert led.count(None) == 0 and led.get_array("y") is None
    assert led.get_meta("schema_version") == str(SCHEMA_VERSION)
    assert [p.name for p in tmp_path.iterdir() if "damaged" in p.name] == []


def test_move_aside_takes_the_wal_and_shm_files(tmp_path):
    path = tmp_path / "ledger.sqlite"
    for suffix in ("", "-wal", "-shm"):
        (tmp_path / f"ledger.sqlite{suffix}").write_bytes(b"x" + suffix.encode())
    moved = move_aside(path)
    assert moved.name.startswith("ledger.sqlite.damaged-") and moved.name.endswith("Z")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([moved.name, moved.name + "-wal", moved.name + "-shm"])
    assert move_aside(path) is None


def test_empty_file_becomes_a_ledger(tmp_path):
    path = tmp_path / "ledger.sqlite"
    path.touch()
    assert Ledger(path).count() == 0


def test_a_ledger_locked_too_long_is_one_line(tmp_path):
    path = filled(tmp_path / "ledger.sqlite", 3)
    other = sqlite3.connect(path, isolation_level=None)
    other.execute("BEGIN IMMEDIATE")                 # another process holds the write lock
    try:
        led = Ledger(path, timeout_s=0.2)
        with pytest.raises(LedgerError) as err:
            led.put(Evaluation("k9", {"x": 9.0}, J=9.0, psi=[9.0]))
        assert_one_line(err.value, str(path), "stayed locked by another process for more than 0.2 s")
        assert led.count() == 3                      # reading still works, nothing lost
    finally:
        other.execute("ROLLBACK")
        other.close()


FULL_DISK = textwrap.dedent("""
    import resource, signal, sys
    import numpy as np
    from suspid.errors import SuspidError
    from suspid.infra.ledger import Evaluation, Ledger
    led = Ledger(sys.argv[1])
    led.count()
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)     # the disk is full: writes fail with EFBIG
    resource.setrlimit(resource.RLIMIT_FSIZE, (int(sys.argv[2]), int(sys.argv[2])))
    done = 0
    try:
        for i in range(1000):
            led.put_array(f"big{i}", np.random.default_rng(i).standard_normal(20_000))
            led.put(Evaluation(f"new{i}", {"x": float(i)}, J=float(i), psi=[0.0]))
            done += 1
    except SuspidError as exc:
        print(type(exc).__name__, "|", exc)
    print("committed", done)
""")


def test_full_disk_during_a_write_is_one_clear_line_and_keeps_what_was_committed(tmp_path):
    path = filled(tmp_path / "ledger.sqlite", 20)
    script = tmp_path / "full.py"
    script.write_text(FULL_DISK)
    limit = path.stat().st_size + 400_000
    out = subprocess.run([sys.executable, str(script), str(path), str(limit)], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    first, last = out.stdout.strip().splitlines()
    kind, message = first.split(" | ", 1)
    assert kind == "LedgerError" and "cannot rollback" not in message and "\n" not in message
    assert message.startswith(f"{path}: cannot write the run ledger: disk full or not writable (")
    committed = int(last.split()[1])
    assert 0 < committed < 1000
    led = Ledger(path)                                # sound afterwards, everything committed is there
    assert led.count() == 20 + committed
    assert led.get("k7").J == -7.0 and led.get(f"new{committed - 1}") is not None
