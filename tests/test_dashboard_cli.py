"""``suspid dashboard`` and ``suspid fleet user`` as a user runs them: a typo in ``--db``, a port in use, an address
that is not this machine's only, users added from standard input. Each is a real ``python -m suspid`` process."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import interruptible, run_cli
from suspid.fleet.db import open_database
from suspid.fleet.users import authenticate

pytest.importorskip("flask_wtf")


@pytest.fixture
def database(tmp_path) -> Path:
    path = tmp_path / "fleet.sqlite"
    open_database(path).dispose()
    return path


def _one_line(res) -> str:
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert res.stderr.count("\n") == 1 and "Traceback" not in res.stderr, res.stderr
    return res.stderr


def test_a_missing_database_is_an_error_unless_create(tmp_path):
    typo = tmp_path / "typo" / "flet.sqlite"
    err = _one_line(run_cli("dashboard", "--db", str(typo)))
    assert err == f"error: --db {typo}: no such database file (check the path, or give --create to make a new, " \
                  f"empty one)\n"
    assert not typo.parent.exists()                                    # nothing made, no folder either
    err = _one_line(run_cli("dashboard", "--db", str(typo), "--create"))
    assert err == f"error: --db {typo}: folder {typo.parent} does not exist\n" and not typo.parent.exists()
    err = _one_line(run_cli("fleet", "user", "list", "--db", str(typo)))
    assert "no such database file" in err


def test_a_busy_port_is_one_line(database):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        err = _one_line(run_cli("dashboard", "--db", str(database), "--port", str(port)))
    assert err == f"error: --port {port}: port {port} on 127.0.0.1 is in use (another dashboard?); stop it or give " \
                  f"another --port\n"


def test_allow_ack_needs_a_user(database):
    err = _one_line(run_cli("dashboard", "--db", str(database), "--allow-ack"))
    assert "no user may acknowledge yet; add one with suspid fleet user add NAME" in err


def _serve(*args: str) -> tuple[subprocess.Popen, str]:
    """Start ``suspid dashboard ARGS`` and wait for its address line; returns the process and stderr so far."""
    env = dict(os.environ, PYTHONUNBUFFERED="1", COLUMNS="200")
    proc = subprocess.Popen([sys.executable, "-m", "suspid", "dashboard", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, preexec_fn=interruptible)
    deadline = time.monotonic() + 60
    line = ""
    while time.monotonic() < deadline and "dashboard on http://" not in line:
        line = proc.stdout.readline()
        if not line and proc.poll() is not None:
            break
    assert "dashboard on http://" in line, (line, proc.stderr.read() if proc.poll() is not None else "")
    return proc, line


def _stop(proc: subprocess.Popen) -> str:
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    return err


def test_create_makes_the_database_and_loopback_is_the_default(tmp_path):
    path = tmp_path / "new.sqlite"
    proc, line = _serve("--db", str(path), "--create", "--port", "0")
    try:
        assert path.is_file() and line.startswith("dashboard on http://127.0.0.1:") and "read-only" in line
    finally:
        err = _stop(proc)
    assert "warning" not in err


def test_another_address_than_loopback_is_said(database):
    proc, _ = _serve("--db", str(database), "--host", "0.0.0.0", "--port", "0")
    err = _stop(proc)
    assert err.startswith("warning: the dashboard listens on 0.0.0.0, not only on this machine: anyone who can "
                          "reach port ")


@pytest.mark.slow   # five suspid processes: about 12 s on 2 cores
def test_users_are_added_from_stdin_with_a_hashed_password(database):
    res = subprocess.run([sys.executable, "-m", "suspid", "fleet", "user", "add", "m.martin", "--db", str(database),
                          "--password-stdin"], input="correct horse battery\n", capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert "user m.martin added" in res.stdout
    db = open_database(database)
    try:
        assert authenticate(db, "m.martin", "correct horse battery") == "m.martin"
        assert authenticate(db, "m.martin", "correct horse battery\n") is None
        with db.read() as s:
            stored = s.execute(__import__("sqlalchemy").text("SELECT password_hash FROM users")).scalar_one()
        assert stored.startswith("scrypt:") and "correct horse" not in stored
    finally:
        db.dispose()
    again = subprocess.run([sys.executable, "-m", "suspid", "fleet", "user", "add", "m.martin", "--db",
                            str(database)], input="another password\n", capture_output=True, text=True, timeout=120)
    assert _one_line(again) == "error: user m.martin already exists (suspid fleet user remove m.martin first)\n"
    short = subprocess.run([sys.executable, "-m", "suspid", "fleet", "user", "add", "bob", "--db", str(database)],
                           input="short\n", capture_output=True, text=True, timeout=120)
    assert "give at least 8" in _one_line(short)
    listed = run_cli("fleet", "user", "list", "--db", str(database))
    assert listed.returncode == 0 and listed.stdout.startswith("m.martin\tactive\tadded ")
    assert run_cli("fleet", "user", "remove", "m.martin", "--db", str(database)).returncode == 0
    db = open_database(database)
    try:
        assert authenticate(db, "m.martin", "correct horse battery") is None
    finally:
        db.dispose()
