"""A throw-away PostgreSQL server for the tests: Debian's initdb into a temporary folder, pg_ctl on a loopback port.

PostgreSQL refuses to run as root: as root the cluster is made and run as the
``postgres`` system user (Debian's package creates it) through ``runuser``.
"""

from __future__ import annotations

import glob
import os
import shutil
import socket
import subprocess
import tempfile
from pathlib import Path


def _binaries() -> Path | None:
    found = shutil.which("initdb")
    if found:
        return Path(found).resolve().parent
    versions = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"))
    return Path(versions[-1]).parent if versions else None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class PostgresServer:
    """Start with :meth:`start`, stop with :meth:`stop`; :attr:`url` is a SQLAlchemy URL of database ``suspid``."""

    def __init__(self) -> None:
        self.bin = _binaries()
        self.root = Path(tempfile.mkdtemp(prefix="suspid-pg-"))
        self.port = _free_port()
        self.user = "postgres" if os.geteuid() == 0 else None

    @property
    def available(self) -> bool:
        return self.bin is not None

    def _run(self, *args: str) -> None:
        cmd = [str(self.bin / args[0]), *args[1:]]
        if self.user:
            cmd = ["runuser", "-u", self.user, "--", *cmd]
        subprocess.run(cmd, check=True, capture_output=True, timeout=120)

    def start(self) -> str:
        data = self.root / "data"
        if self.user:
            shutil.chown(self.root, self.user)
            os.chmod(self.root, 0o700)
        self._run("initdb", "-D", str(data), "-A", "trust", "-U", "suspid", "--no-sync", "-E", "UTF8")
        self.start_again()
        self._run("createdb", "-h", "127.0.0.1", "-p", str(self.port), "-U", "suspid", "suspid")
        return self.url

    def start_again(self) -> None:
        """Start the server on its data folder (after :meth:`kill`: PostgreSQL's crash recovery runs)."""
        self._run("pg_ctl", "-D", str(self.root / "data"), "-l", str(self.root / "log"), "-w", "-t", "60", "-o",
                  f"-p {self.port} -k {self.root} -c listen_addresses=127.0.0.1 -c fsync=off -c max_connections=60",
                  "start")

    def kill(self) -> None:
        """Stop the server at once, as a crash would (``pg_ctl -m immediate``: no shutdown checkpoint)."""
        self._run("pg_ctl", "-D", str(self.root / "data"), "-m", "immediate", "-w", "stop")

    @property
    def url(self) -> str:
        return f"postgresql://suspid@127.0.0.1:{self.port}/suspid"

    def fresh_database(self, name: str) -> str:
        """A new empty database on the server; its URL."""
        self._run("createdb", "-h", "127.0.0.1", "-p", str(self.port), "-U", "suspid", name)
        return f"postgresql://suspid@127.0.0.1:{self.port}/{name}"

    def stop(self) -> None:
        try:
            self._run("pg_ctl", "-D", str(self.root / "data"), "-m", "immediate", "-w", "stop")
        finally:
            shutil.rmtree(self.root, ignore_errors=True)
