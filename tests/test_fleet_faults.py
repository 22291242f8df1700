"""The monitoring database under faults, on SQLite and on a real PostgreSQL server (issue 48).

Every case ends the same way: one line for the user, no record lost, none
doubled, the run's own files as they were, and doing it again records what is
missing exactly once. The faults are real: processes killed by SIGKILL in the
middle of a transaction, the PostgreSQL server stopped as a crash would
(``pg_ctl -m immediate``) and started again, damaged files, a small tmpfs that
fills up (a PostgreSQL tablespace on it), a read-only file system, forked
writers racing for the same rows, and an older schema (a test revision added
on a copy of the shipped migrations).

On the main branch before this file (commit bb35277) the same faults, written
with the API both share, end as: a damaged file a raw ``DatabaseError``
(exit 1, two lines) or, pages overwritten, opened and written to; a run ledger
given as the database silently given the monitoring tables; a newer schema a
raw Alembic ``CommandError``; an older schema upgraded without a copy (SQLite)
or without being asked (PostgreSQL); a full disk a raw ``OperationalError``;
the server down or killed mid-transaction a raw ``OperationalError``, no wait,
no retry; a run folder recorded for another vehicle silently "already there";
no read-only open (the dashboard could not start on a read-only file system).
Killed writers, the power-cut cases and the concurrent writers held already
(SQLite's and PostgreSQL's own atomic commit).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import errno
import hashlib
import json
import multiprocessing
import os
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import yaml
from sqlalchemy import create_engine, event, func, select, text
from sqlalchemy.orm import Session

from fleet_fixtures import db_url, pg_server  # noqa: F401 - fixtures
from test_fleet import DOMAIN, result
from suspid.errors import DataError
from suspid.fleet import db as fleet_db
from suspid.fleet import queries
from suspid.fleet.db import database_url, open_database, upgrade_database
from suspid.fleet.record import RunRecord, VehicleKey, record_result, record_results
from suspid.fleet.schema import ElementValue, Indicator, Run
from suspid.indicators.standard import IndicatorValue

KEY = VehicleKey("demo", "TS01", "car1")
FORK = multiprocessing.get_context("fork")


def _run(i: int, run_dir: Path, key: VehicleKey = KEY, detail_bytes: int = 0) -> RunRecord:
    """Run i of a vehicle: two element groups, one run-level indicator (with a detail of ``detail_bytes``)."""
    ind = IndicatorValue("en14363-instability", 2.0, "m/s^2", "ok", None, "bogie", 5.65,
                         {"note": "x" * detail_bytes} if detail_bytes else {})
    return RunRecord(key, dt.date(2026, 1, 1) + dt.timedelta(days=7 * i), result(f"r{i}", 300e3 - 5e3 * i),
                     run_dir, 1000.0 * i, "monitor-date", DOMAIN, [ind])


def census(url: str) -> dict:
    """What the database holds (read with a plain engine, not the code under test): run folders, how often
    each is there, rows, rows without their run."""
    engine = create_engine(database_url(url))
    try:
        with Session(engine) as s:
            runs = s.execute(select(Run.run_dir)).scalars().all()
            return {"runs": sorted(Path(r).name for r in runs), "n_runs": len(runs),
                    "values": s.scalar(select(func.count()).select_from(ElementValue)),
                    "indicators": s.scalar(select(func.count()).select_from(Indicator)),
                    "orphans": s.scalar(select(func.count()).select_from(ElementValue)
                                        .where(ElementValue.run_id.not_in(select(Run.id))))}
    finally:
        engine.dispose()


def assert_exactly(url: str, names: list[str]) -> None:
    """Each of the runs ``names`` once, nothing else, every run with its 2 values and 1 indicator."""
    c = census(url)
    assert c["runs"] == sorted(names), c
    assert (c["values"], c["indicators"], c["orphans"]) == (2 * len(names), len(names), 0), c


def one_line(exc: BaseException) -> str:
    text_ = str(exc)
    assert "\n" not in text_ and "Traceback" not in text_, text_
    return text_


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _in_child(target, *args) -> int:
    """``target(*args)`` in a forked process (no interpreter start-up); its exit code (-9: SIGKILL)."""
    proc = FORK.Process(target=target, args=args)
    proc.start()
    proc.join(60)
    return proc.exitcode


# -- a writer killed in the middle of its transaction, both backends -------------------------------------
def _record_and_die(url: str, records: list[RunRecord], at: str, k: int) -> None:
    """Record ``records`` in one transaction; SIGKILL at the k-th run's insert (``flush``) or before commit."""
    seen = [0]

    def flush(session, _ctx):
        seen[0] += sum(isinstance(o, Run) for o in session.new)
        if at == "flush" and seen[0] >= k:
            os.kill(os.getpid(), signal.SIGKILL)

    event.listen(Session, "after_flush", flush)
    if at == "commit":
        event.listen(Session, "before_commit", lambda s: os.kill(os.getpid(), signal.SIGKILL))
    record_results(open_database(url), records)
    os._exit(0)


@pytest.mark.parametrize("what, n_dates, at, k", [
    ("a run killed once its rows are written, before its commit", 1, "commit", 1),
    ("a monitor of 3 dates killed after writing its 2nd date", 3, "flush", 2),
    ("a monitor of 3 dates killed just before its commit", 3, "commit", 3),
])
def test_a_writer_killed_mid_transaction_leaves_nothing_and_the_rerun_records_once(db_url, tmp_path, what,
                                                                                   n_dates, at, k):
    """Atomic commit: a SIGKILL in the transaction leaves no part of it; the same recording again records
    every date once, and a third time nothing."""
    open_database(db_url).dispose()
    records = [_run(i, tmp_path / f"d{i}") for i in range(n_dates)]
    assert _in_child(_record_and_die, db_url, records, at, k) == -signal.SIGKILL
    assert_exactly(db_url, [])
    db = open_database(db_url)
    try:
        assert all(r.created for r in record_results(db, records))
        assert not any(r.created for r in record_results(db, records))
    finally:
        db.dispose()
    assert_exactly(db_url, [f"d{i}" for i in range(n_dates)])


# -- the PostgreSQL server killed and started again ------------------------------------------------------
def test_server_killed_mid_transaction_and_restarted_the_write_completes_once(pg_server, tmp_path):
    """The server dies (immediate stop) after a monitor's first date is written, and is back 1 s later: the
    writer says once that it waits, reaches the server again and records the 3 dates once."""
    url = pg_server.fresh_database(f"kill{os.getpid()}")
    lines: list[str] = []
    db = open_database(url, wait_s=60, log=lines.append)
    restart = threading.Timer(1.0, pg_server.start_again)

    def kill_server(session, _ctx):
        if not restart.is_alive() and not restart.finished.is_set() and any(isinstance(o, Run) for o in session.new):
            pg_server.kill()
            restart.start()

    event.listen(Session, "after_flush", kill_server)
    try:
        out = record_results(db, [_run(i, tmp_path / f"d{i}") for i in range(3)])
    finally:
        event.remove(Session, "after_flush", kill_server)
        if restart.is_alive() or restart.finished.is_set():
            restart.join()
        db.dispose()
    assert restart.finished.is_set()
    waiting = [s for s in lines if "cannot be reached" in s]
    assert len(waiting) == 1 and "retrying for up to 60 s" in waiting[0], lines
    assert any("reached again after" in s for s in lines), lines
    assert [r.created for r in out] == [True] * 3
    assert_exactly(url, ["d0", "d1", "d2"])


def test_server_down_longer_than_the_wait_fails_in_one_line_and_records_nothing(pg_server, tmp_path):
    url = pg_server.fresh_database(f"down{os.getpid()}")
    db = open_database(url, wait_s=1.5)
    pg_server.kill()
    try:
        t0 = time.monotonic()
        with pytest.raises(DataError) as info:
            record_result(db, KEY, dt.date(2026, 1, 1), result("r0", 300e3), tmp_path / "d0")
        assert 1.0 < time.monotonic() - t0 < 10, info.value
    finally:
        db.dispose()
        pg_server.start_again()
    message = one_line(info.value)
    assert "cannot be reached" in message and "gave up after" in message and "fleet.wait_s: 1.5" in message
    assert_exactly(url, [])


TINY = {"name": "tiny", "seed": 2,
        "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0}},
        "parameters": {"c_sec_z": {}}, "data": {"track": {"n_segments": 2, "length_m": 800.0}},
        "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 30}, "design": {"n_initial": 5},
        "ego": {"max_iter": 1}, "identifiability": {"n_redraws": 4}}


def _suspid(*args: str) -> subprocess.Popen:
    env = dict(os.environ, SUSPID_DISABLE_PLUGIN_AUTOLOAD="1", PYTHONUNBUFFERED="1", COLUMNS="400")
    return subprocess.Popen([sys.executable, "-m", "suspid", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=env)


def _wait_for_line(proc: subprocess.Popen, words: str, seen: list[str]) -> None:
    for line in proc.stdout:
        seen.append(line)
        if words in line:
            return
    raise AssertionError(f"'{words}' never printed: {''.join(seen)} {proc.stderr.read()}")


def test_suspid_run_with_the_server_killed_keeps_its_results_and_the_rerun_records_once(pg_server, tmp_path):
    """`suspid run` recording into PostgreSQL. The server is killed while the run computes; with
    fleet.wait_s: 2 the run ends in one line (exit 2) keeping result.json and the ledger. The same command,
    the server still down, waits (one line) until the server is started again, then records the run once;
    wait_s is not part of the run id (the same run), the identification is the same."""
    url = pg_server.fresh_database(f"cli{os.getpid()}")
    open_database(url).dispose()
    cfg = tmp_path / "tiny.yaml"
    fleet = {"database": url, "trainset": "TS01", "date": "2026-02-01", "indicators": False}
    cfg.write_text(yaml.safe_dump(TINY | {"fleet": fleet | {"wait_s": 2}}, sort_keys=False))
    run_dir = tmp_path / "runs" / "tiny"
    first = _suspid("run", str(cfg))
    seen: list[str] = []
    try:
        _wait_for_line(first, "executor", seen)          # the run has started: the server dies under it
        pg_server.kill()
        out, err = first.communicate(timeout=120)
        assert first.returncode == 2, (out, err)
        (line,) = err.strip().splitlines()
        assert "cannot be reached" in line and "gave up after" in line and "nothing was recorded" in line
        assert f"the run's results are kept in {run_dir}" in line, line
        first_result = json.loads((run_dir / "result.json").read_text())
        assert (run_dir / "ledger.sqlite").is_file()
        cfg.write_text(yaml.safe_dump(TINY | {"fleet": fleet | {"wait_s": 120}}, sort_keys=False))
        again = _suspid("run", str(cfg))
        seen = []
        _wait_for_line(again, "cannot be reached", seen)
        assert "retrying for up to 120 s" in seen[-1]
        pg_server.start_again()
        out, err = again.communicate(timeout=120)
    finally:
        with contextlib.suppress(subprocess.CalledProcessError):
            pg_server.start_again()                      # up again whatever happened (an error: it was up)
    assert again.returncode == 0, (out, err)
    assert "reached again after" in out and "recorded in the monitoring database as run" in out, out
    second_result = json.loads((run_dir / "result.json").read_text())
    assert second_result["run_id"] == first_result["run_id"]
    assert second_result["w_opt"] == first_result["w_opt"] and second_result["J_max"] == first_result["J_max"]
    db = open_database(url)
    try:
        rec = record_result(db, VehicleKey("fleet", "TS01", "car1"), dt.date(2026, 2, 1), second_result,
                            run_dir)                   # a third recording, as `suspid fleet import` would
        assert not rec.created
        assert [h["element_group"] for h in queries.history(db, "TS01")] == ["c_sec_z"]
        assert queries.count_runs(db) == 1
    finally:
        db.dispose()


# -- damaged SQLite files --------------------------------------------------------------------------------
def _good(tmp_path: Path) -> Path:
    path = tmp_path / "good.sqlite"
    db = open_database(path)
    try:
        record_results(db, [_run(i, tmp_path / f"d{i}") for i in range(6)])
    finally:
        db.dispose()
    return path


def _overwrite(path: Path, offset: int, data: bytes) -> None:
    with open(path, "r+b") as fh:
        fh.seek(offset)
        fh.write(data)


DAMAGES = {
    "random bytes": (lambda p, good: p.write_bytes(os.urandom(16384)), "file is not a database"),
    "a YAML file given as the database": (lambda p, good: p.write_text("name: tiny\nseed: 2\n"),
                                          "file is not a database"),
    "the header overwritten": (lambda p, good: (shutil.copy(good, p), _overwrite(p, 0, b"\0" * 100)),
                               "file is not a database"),
    "pages in the middle overwritten": (lambda p, good: (shutil.copy(good, p), _overwrite(p, 3 * 4096,
                                                                                          b"\xa5" * 8192)),
                                        "quick_check"),
    "truncated to half": (lambda p, good: (shutil.copy(good, p), os.truncate(p, p.stat().st_size // 2)),
                          "malformed"),
}


@pytest.mark.parametrize("read_only", [False, True], ids=["for writing", "read-only"])
@pytest.mark.parametrize("damage", list(DAMAGES))
def test_a_damaged_sqlite_file_is_refused_in_one_line_and_left_as_it_was(tmp_path, damage, read_only):
    good = _good(tmp_path)
    path = tmp_path / "fleet.sqlite"
    make, words = DAMAGES[damage]
    make(path, good)
    before = path.read_bytes()
    with pytest.raises(DataError) as info:
        open_database(path, read_only=read_only)
    message = one_line(info.value)
    assert message.startswith(f"database {path}: damaged database (") and words in message, message
    assert path.read_bytes() == before
    assert not list(tmp_path.glob("fleet.sqlite.*")), "no lock file, no copy"


def test_a_file_that_is_not_a_monitoring_database_is_refused(tmp_path):
    """A valid SQLite file with other tables (a run ledger given as --db): refused, not given our schema."""
    path = tmp_path / "ledger.sqlite"
    with contextlib.closing(sqlite3.connect(path)) as con:
        con.execute("CREATE TABLE evaluations (key TEXT PRIMARY KEY, value REAL)")
        con.commit()
    before = path.read_bytes()
    for read_only in (False, True):
        with pytest.raises(DataError, match="holds tables \\(evaluations\\) but no suspid schema revision"):
            open_database(path, read_only=read_only)
    assert path.read_bytes() == before


def test_cli_on_a_damaged_database_one_line_exit_2(tmp_path):
    """Today's main: exit 1, 'internal error: DatabaseError' on two lines."""
    from conftest import run_cli

    path = tmp_path / "fleet.sqlite"
    path.write_bytes(os.urandom(8192))
    before = path.read_bytes()
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "result.json").write_text(json.dumps(result("r0", 300e3)))
    res = run_cli("fleet", "import", str(tmp_path / "run"), "--db", str(path), "--trainset", "TS01",
                  "--date", "2026-01-01", "--no-indicators")
    assert res.returncode == 2, res.stderr
    (line,) = res.stderr.strip().splitlines()
    assert line.startswith(f"error: database {path}: damaged database (file is not a database)"), line
    assert path.read_bytes() == before


def _record_two_and_crash(path: str, tmp: str) -> None:
    db = open_database(path)
    for i in range(2):
        record_results(db, [_run(i, Path(tmp) / f"d{i}")])
    os._exit(0)                   # no close, no checkpoint: both commits are only in the write-ahead log


@pytest.mark.parametrize("tear, survivors", [
    ("the log's last frame torn (a power cut while the 2nd commit was written)", ["d0"]),
    ("garbage after the log's last frame (a power cut while a 3rd transaction was written)", ["d0", "d1"]),
])
def test_what_a_power_cut_leaves_of_the_write_ahead_log(tmp_path, tear, survivors):
    """SQLite's WAL: a commit counts once its commit frame is whole (checksummed); a torn or trailing frame is
    dropped on reopening. What remains is every run before it, whole, and the rerun records the lost one."""
    path = tmp_path / "fleet.sqlite"
    open_database(path).dispose()
    assert _in_child(_record_two_and_crash, str(path), str(tmp_path)) == 0
    wal = path.with_name(path.name + "-wal")
    size = wal.stat().st_size
    assert size > 4096
    if "torn" in tear:
        os.truncate(wal, size - 100)
    else:
        with open(wal, "ab") as fh:
            fh.write(os.urandom(4096 + 24))
    url = database_url(path)
    assert_exactly(url, survivors)
    with contextlib.closing(sqlite3.connect(path)) as con:
        assert con.execute("PRAGMA integrity_check").fetchone() == ("ok",)
    db = open_database(path)
    try:
        record_results(db, [_run(i, tmp_path / f"d{i}") for i in range(2)])
    finally:
        db.dispose()
    assert_exactly(url, ["d0", "d1"])


# -- a full disk while recording ---------------------------------------------------------------------------
@contextlib.contextmanager
def small_disk(size: str):
    """A tmpfs of ``size`` (root only), in a folder the ``postgres`` user can reach; skips the test where
    mounting is not allowed."""
    path = Path(tempfile.mkdtemp(prefix="suspid-disk-"))
    path.chmod(0o755)
    res = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size},mode=0777", "tmpfs", str(path)],
                         capture_output=True, text=True)
    if res.returncode:
        path.rmdir()
        pytest.skip(f"a small tmpfs cannot be mounted here ({res.stderr.strip()}): the full-disk and read-only "
                    f"file system cases need root")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=True)
        path.rmdir()


def fill(folder: Path) -> Path:
    """Fill the disk of ``folder`` to its last byte; the filler file."""
    filler = folder / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT)
    try:
        for chunk in (1 << 20, 1 << 16, 4096, 512, 1):
            try:
                while True:
                    os.write(fd, b"\0" * chunk)
            except OSError as exc:
                assert exc.errno == errno.ENOSPC
    finally:
        os.close(fd)
    assert shutil.disk_usage(folder).free == 0
    return filler


@contextlib.contextmanager
def _database_on(disk: Path, backend: str, server):
    """A monitoring database whose files are on ``disk``: an SQLite file, or a PostgreSQL database in a
    tablespace there (the server's write-ahead log stays on its own disk)."""
    if backend == "sqlite":
        yield database_url(disk / "fleet.sqlite")
        return
    space = disk / "pg"
    space.mkdir()
    shutil.chown(space, server.user) if server.user else None
    name = f"full{os.getpid()}"
    admin = create_engine(database_url(server.url), isolation_level="AUTOCOMMIT")
    with admin.connect() as c:
        c.execute(text(f"CREATE TABLESPACE {name} LOCATION '{space}'"))
        c.execute(text(f"CREATE DATABASE {name} TABLESPACE {name}"))
    try:
        yield database_url(f"postgresql://suspid@127.0.0.1:{server.port}/{name}")
    finally:
        with admin.connect() as c:
            c.execute(text(f"DROP DATABASE {name} WITH (FORCE)"))
            c.execute(text(f"DROP TABLESPACE {name}"))
        admin.dispose()


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_a_full_disk_while_recording_one_line_no_partial_record_and_the_run_files_intact(tmp_path, backend,
                                                                                         request):
    """Runs are recorded until the disk is full: the one that does not fit is not there at all (no value, no
    indicator of it), the others are whole, the run folders (on the same disk) are untouched; once space is
    freed the same recording adds it, once."""
    server = request.getfixturevalue("pg_server") if backend == "postgresql" else None
    with small_disk("24m") as disk, _database_on(disk, backend, server) as url:
        from suspid.infra.files import write_json

        runs = []
        for i in range(200):
            (disk / f"d{i}").mkdir()
            write_json(disk / f"d{i}" / "result.json", result(f"r{i}", 300e3 - 5e3 * i))
            runs.append(_run(i, disk / f"d{i}", detail_bytes=3000))
        kept = {i: _digest(disk / f"d{i}" / "result.json") for i in range(200)}
        db = open_database(url)
        try:
            record_results(db, runs[:2])
            filler = fill(disk)
            failed = None
            for i in range(2, 200):
                try:
                    record_results(db, [runs[i]])
                except DataError as exc:
                    failed, message = i, one_line(exc)
                    break
            assert failed is not None, "the disk never filled"
            assert "the disk is full" in message, message
            if backend == "sqlite":
                assert message.startswith(f"database {disk / 'fleet.sqlite'}: ") and "0 bytes free" in message
            assert_exactly(url, [f"d{i}" for i in range(failed)])
            assert {i: _digest(disk / f"d{i}" / "result.json") for i in range(200)} == kept
            filler.unlink()
            assert record_results(db, [runs[failed]])[0].created
            assert not record_results(db, runs[:failed + 1])[-1].created
        finally:
            db.dispose()
        assert_exactly(url, [f"d{i}" for i in range(failed + 1)])
        if backend == "sqlite":
            with contextlib.closing(sqlite3.connect(disk / "fleet.sqlite")) as con:
                assert con.execute("PRAGMA integrity_check").fetchone() == ("ok",)


# -- many writers at once -----------------------------------------------------------------------------------
def _writer(url: str, w: int, tmp: str, barrier) -> None:
    db = open_database(url)
    barrier.wait(30)
    shared = [_run(i, Path(tmp) / f"shared{i}") for i in range(2)]        # every writer records these too
    own = [_run(i, Path(tmp) / f"w{w}-{i}", VehicleKey("demo", f"TS{w % 3}", f"car{w}")) for i in range(4)]
    for rec in own[:2] + shared + own[2:]:
        record_results(db, [rec])
    db.dispose()
    os._exit(0)


def test_six_writers_at_once_lose_and_double_nothing(db_url, tmp_path):
    """6 forked processes start together; each records 4 runs of its own vehicle and the same 2 runs as all
    the others: 26 runs, each once, with every value and indicator; the alarms of each vehicle once."""
    open_database(db_url).dispose()
    barrier = FORK.Barrier(6)
    procs = [FORK.Process(target=_writer, args=(db_url, w, str(tmp_path), barrier)) for w in range(6)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0] * 6
    assert_exactly(db_url, [f"w{w}-{i}" for w in range(6) for i in range(4)] + ["shared0", "shared1"])
    db = open_database(db_url, read_only=True)
    try:
        keys = [(a["trainset"], a["vehicle"], a["source"]) for a in queries.alarms(db)]
        assert len(keys) == len(set(keys))
    finally:
        db.dispose()


def test_a_run_folder_recorded_for_another_vehicle_is_refused(db_url, tmp_path):
    db = open_database(db_url)
    try:
        record_results(db, [_run(0, tmp_path / "d0")])
        with pytest.raises(DataError) as info:
            record_results(db, [_run(1, tmp_path / "d1", VehicleKey("demo", "TS02", "car1")),
                                _run(0, tmp_path / "d0", VehicleKey("demo", "TS02", "car1"))])
    finally:
        db.dispose()
    assert "is recorded already for demo/TS01/car1" in one_line(info.value)
    assert_exactly(db_url, ["d0"])        # d1, in the same transaction, is not there either


# -- read-only ------------------------------------------------------------------------------------------------
def test_read_only_open_reads_and_refuses_every_write(db_url, tmp_path):
    db = open_database(db_url)
    try:
        record_results(db, [_run(i, tmp_path / f"d{i}") for i in range(3)])
    finally:
        db.dispose()
    path = fleet_db._sqlite_file(db_url)
    before = path.read_bytes() if path else None
    ro = open_database(db_url, read_only=True)
    try:
        assert queries.count_runs(ro) == 3 and len(queries.history(ro, "TS01")) == 6
        with pytest.raises(DataError, match="opened read-only; nothing was written"):
            record_results(ro, [_run(3, tmp_path / "d3")])
        with pytest.raises(DataError, match="opened read-only"), ro.session():
            pass
        with pytest.raises(DataError, match="read-only \\("), ro.read() as s:   # the connection itself refuses
            s.execute(text("DELETE FROM element_values"))
            s.commit()
    finally:
        ro.dispose()
    assert_exactly(db_url, ["d0", "d1", "d2"])
    if path:
        assert path.read_bytes() == before


def test_a_read_only_reader_sees_what_writers_record_after_it_opened(db_url, tmp_path):
    """The dashboard's case: open for reading while runs keep recording (SQLite's WAL: readers and one writer)."""
    open_database(db_url).dispose()
    ro = open_database(db_url, read_only=True)
    db = open_database(db_url)
    try:
        for i in range(3):
            record_results(db, [_run(i, tmp_path / f"d{i}")])
            assert queries.count_runs(ro) == i + 1
    finally:
        db.dispose()
        ro.dispose()


def test_a_select_only_postgresql_role_reads_and_cannot_record(pg_server, tmp_path):
    url = pg_server.fresh_database(f"role{os.getpid()}")
    _older_database(url, tmp_path)
    admin = create_engine(database_url(url), isolation_level="AUTOCOMMIT")
    with admin.connect() as c:
        c.execute(text("DROP ROLE IF EXISTS depot_reader"))
        c.execute(text("CREATE ROLE depot_reader LOGIN"))
        c.execute(text("GRANT SELECT ON ALL TABLES IN SCHEMA public TO depot_reader"))
    reader = url.replace("suspid@", "depot_reader@")
    try:
        ro = open_database(reader, read_only=True)
        try:
            assert queries.count_runs(ro) == 2
        finally:
            ro.dispose()
        db = open_database(reader)
        try:
            with pytest.raises(DataError) as info:
                record_results(db, [_run(5, tmp_path / "d5")])
        finally:
            db.dispose()
        assert "read-only (permission denied for table" in one_line(info.value)
        assert_exactly(url, ["d0", "d1"])
    finally:
        with admin.connect() as c:
            c.execute(text("DROP OWNED BY depot_reader"))
            c.execute(text("DROP ROLE depot_reader"))
        admin.dispose()


def test_read_only_open_of_a_missing_file_creates_nothing(tmp_path):
    missing = tmp_path / "typo" / "fleet.sqlite"
    with pytest.raises(DataError) as info:
        open_database(missing, read_only=True)
    assert one_line(info.value) == f"database {missing}: no such file (a read-only open creates nothing)"
    assert not missing.parent.exists()


def test_read_only_open_of_an_empty_server_database_creates_nothing(pg_server):
    url = pg_server.fresh_database(f"empty{os.getpid()}")
    with pytest.raises(DataError, match="holds no monitoring tables yet"):
        open_database(url, read_only=True)
    assert census_tables(url) == []


def census_tables(url: str) -> list[str]:
    from sqlalchemy import inspect

    engine = create_engine(database_url(url))
    try:
        with engine.connect() as c:
            return inspect(c).get_table_names()
    finally:
        engine.dispose()


@contextlib.contextmanager
def read_only_fs():
    """A folder with a recorded database (and a run folder), then remounted read-only."""
    with small_disk("8m") as disk:
        (disk / "d0").mkdir()
        (disk / "d0" / "report.md").write_text("# report\n")
        db = open_database(disk / "fleet.sqlite")
        try:
            record_results(db, [_run(i, disk / f"d{i}") for i in range(3)])
        finally:
            db.dispose()
        subprocess.run(["mount", "-o", "remount,ro", str(disk)], check=True)
        yield disk / "fleet.sqlite"


def test_a_database_on_a_read_only_file_system():
    """Read-only: it reads (SQLite's immutable mode: no -shm can be made there); for writing: one line."""
    with read_only_fs() as path:
        ro = open_database(path, read_only=True)
        try:
            assert queries.count_runs(ro) == 3
            assert {r["element_group"] for r in queries.overview(ro)} == {"c_yaw[bogie1]", "c_sec_z"}
        finally:
            ro.dispose()
        with pytest.raises(DataError) as info:
            open_database(path)
        assert one_line(info.value) == (f"database {path}: on a read-only file system: it can be opened read-only "
                                        f"only (nothing can be recorded there)")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_suspid_dashboard_serves_a_database_on_a_read_only_file_system():
    """`suspid dashboard` (read-only without --allow-ack) opens the database read-only and serves it.
    Today's main: it cannot start (it opens the database for writing and migrates)."""
    with read_only_fs() as path:
        port = _free_port()
        proc = _suspid("dashboard", "--db", str(path), "--port", str(port))
        try:
            deadline, page = time.monotonic() + 60, None
            while page is None and time.monotonic() < deadline and proc.poll() is None:
                try:
                    page = urllib.request.urlopen(f"http://127.0.0.1:{port}/export.json?what=history&trainset=TS01",
                                                  timeout=5).read()
                except (urllib.error.URLError, ConnectionError):
                    time.sleep(0.2)
            assert page is not None, proc.communicate(timeout=10)
            rows = json.loads(page)
            assert len(rows) == 6 and {r["trainset"] for r in rows} == {"TS01"}
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5) as res:
                assert res.status == 200 and b"TS01" in res.read()
        finally:
            proc.terminate()
            proc.communicate(timeout=30)


# -- an older schema --------------------------------------------------------------------------------------------
REVISION = '''"""A test revision after the shipped ones: a table more{failing}."""
from alembic import op
import sqlalchemy as sa

revision = "t_extra"
down_revision = {head!r}
branch_labels = None
depends_on = None


def upgrade():
    op.create_table("test_extra", sa.Column("id", sa.Integer, primary_key=True))
    {failure}


def downgrade():
    op.drop_table("test_extra")
'''


def _revision(url: str) -> tuple[str | None, bool]:
    """The database's revision, and whether the test revision's table is there."""
    engine = create_engine(database_url(url))
    try:
        with engine.connect() as c:
            from sqlalchemy import inspect

            rev = c.execute(text("SELECT version_num FROM alembic_version")).scalar()
            return rev, "test_extra" in inspect(c).get_table_names()
    finally:
        engine.dispose()


@pytest.fixture
def newer_suspid(tmp_path, monkeypatch):
    """Make this suspid one revision newer (the shipped migrations plus a test revision); ``failing=True``
    makes that revision fail half-way on the data (a NOT NULL insert after creating its table)."""
    head = fleet_db.ScriptDirectory.from_config(fleet_db._alembic_config()).get_current_head()

    def make(failing: bool = False) -> str:
        where = tmp_path / f"migrations{'-failing' if failing else ''}"
        shutil.copytree(fleet_db.MIGRATIONS, where, ignore=shutil.ignore_patterns("__pycache__"))
        (where / "versions" / "t_extra.py").write_text(REVISION.format(
            head=head, failing=" (failing half-way)" if failing else "",
            failure='op.execute("INSERT INTO runs (id) VALUES (1)")' if failing else "pass"))
        monkeypatch.setattr(fleet_db, "MIGRATIONS", where)
        return head
    return make


def _older_database(url: str, tmp_path: Path) -> None:
    db = open_database(url)
    try:
        record_results(db, [_run(i, tmp_path / f"d{i}") for i in range(2)])
    finally:
        db.dispose()


def test_an_older_sqlite_database_is_copied_then_upgraded(tmp_path, newer_suspid):
    path = tmp_path / "fleet.sqlite"
    _older_database(database_url(path), tmp_path)
    old = newer_suspid()
    lines: list[str] = []
    open_database(path, log=lines.append).dispose()
    backup = tmp_path / f"fleet.sqlite.schema-{old}.bak"
    assert lines == [f"database {path}: schema upgraded from revision {old} to t_extra; the copy before the "
                     f"upgrade is {backup}"]
    assert _revision(database_url(path)) == ("t_extra", True)
    assert _revision(database_url(backup)) == (old, False)
    assert_exactly(database_url(path), ["d0", "d1"])
    assert_exactly(database_url(backup), ["d0", "d1"])


@pytest.mark.parametrize("backend", ["sqlite", "postgresql"])
def test_an_older_schema_refused_or_upgraded_never_altered_silently(tmp_path, newer_suspid, backend, request):
    """Read-only: refused. PostgreSQL for writing: refused (back it up, then `suspid fleet upgrade`), then
    upgraded by upgrade_database. A migration that fails half-way: rolled back whole (transactional DDL),
    one line; SQLite keeps its copy."""
    if backend == "sqlite":
        url = database_url(tmp_path / "fleet.sqlite")
    else:
        url = request.getfixturevalue("pg_server").fresh_database(f"old{os.getpid()}")
    _older_database(url, tmp_path)
    old = newer_suspid(failing=True)
    with pytest.raises(DataError) as info:
        open_database(url, read_only=True)
    assert f"schema revision {old}, older than this suspid's t_extra: open it for writing once" in \
        one_line(info.value)
    if backend == "postgresql":
        with pytest.raises(DataError) as info:
            open_database(url)
        assert "back the database up (pg_dump) and upgrade it with `suspid fleet upgrade --db URL`; nothing was " \
               "changed" in one_line(info.value)
        assert _revision(url) == (old, False)
    with pytest.raises(DataError) as info:
        upgrade_database(url)
    message = one_line(info.value)
    assert f"the schema upgrade from {old} to t_extra failed (" in message and "nothing was changed" in message
    assert _revision(url) == (old, False)
    assert_exactly(url, ["d0", "d1"])
    newer_suspid()
    code, out, err = _cli("fleet", "upgrade", "--db", url)
    assert (code, err) == (0, ""), err
    assert "schema upgraded from revision" in out and "the database's schema is this suspid's newest" in out
    assert _revision(url) == ("t_extra", True)
    assert_exactly(url, ["d0", "d1"])


def _cli(*args: str) -> tuple[int, str, str]:
    """The command line in this process (the monkeypatched migrations apply): exit code, stdout, stderr."""
    import io
    from contextlib import redirect_stderr, redirect_stdout

    from suspid.cli import console, main

    out, err = io.StringIO(), io.StringIO()
    console.file = out
    try:
        with redirect_stdout(out), redirect_stderr(err), pytest.raises(SystemExit) as info:
            main(list(args))
    finally:
        console.file = None
    return info.value.code, out.getvalue(), err.getvalue()


def test_a_database_of_a_newer_suspid_is_refused(db_url, tmp_path):
    _older_database(db_url, tmp_path)
    engine = create_engine(database_url(db_url))
    with engine.begin() as c:
        c.execute(text("UPDATE alembic_version SET version_num = 'z_future'"))
    engine.dispose()
    for read_only in (False, True):
        with pytest.raises(DataError) as info:
            open_database(db_url, read_only=read_only)
        assert "schema revision z_future, unknown to this suspid" in one_line(info.value)
    assert _revision(db_url) == ("z_future", False)
