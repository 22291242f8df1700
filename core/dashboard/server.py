"""Serving the dashboard (``suspid dashboard``): the database checked, the port bound, the address said.

A database given by a path must exist (a typo would otherwise make a new,
empty one and its folders) unless ``create`` asks for one, and then only in a
folder that exists. The listening socket is bound here, before the WSGI
server is made, so that a port in use or an address this machine does not
have is one line (:class:`~suspid.errors.ConfigError`, exit 2 on the command
line) instead of Werkzeug's two lines and exit 1. The default address is
127.0.0.1 (this machine only, with the ``Host`` header checked against the
loopback names); any other address is said in a warning line, since anyone
who reaches it can read the fleet's state.
"""

from __future__ import annotations

import errno
import ipaddress
import socket
from pathlib import Path
from typing import Callable

from werkzeug.serving import WSGIRequestHandler, get_sockaddr, make_server, select_address_family

from suspid.dashboard.app import create_app
from suspid.errors import ConfigError
from suspid.fleet.db import Database, database_url, open_database
from suspid.fleet.users import has_users

Log = Callable[[str], None]
LOOPBACK_NAMES = ["127.0.0.1", "localhost", "::1", "[::1]"]


def open_dashboard_database(url_or_path: str | Path, *, create: bool = False, option: str = "--db",
                            read_only: bool = False) -> Database:
    """Open an existing monitoring database; a missing SQLite file is an error unless ``create``.

    :param read_only: create, migrate and write nothing (the dashboard without acknowledgements).

    :raises ConfigError: the SQLite file does not exist (without ``create``), or its folder does not.
    """
    url = database_url(url_or_path)
    if url.startswith("sqlite:///"):
        path = Path(url.removeprefix("sqlite:///"))
        if not path.is_file():
            if not create:
                raise ConfigError(f"{option} {path}: no such database file (check the path, or give --create to "
                                  f"make a new, empty one)")
            if not path.parent.is_dir():
                raise ConfigError(f"{option} {path}: folder {path.parent} does not exist")
    return open_database(url, read_only=read_only)


def is_loopback(host: str) -> bool:
    """Whether ``host`` serves this machine only (127.0.0.0/8, ::1, localhost)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port``.

    :raises ConfigError: one line for a port in use, an address this machine does not have, a bad port.
    """
    if not 0 <= port <= 65535:
        raise ConfigError(f"--port {port}: give a port number from 1 to 65535 (0: any free port)")
    try:
        family = select_address_family(host, port)
        address = get_sockaddr(host, port, family)
        sock = socket.socket(family, socket.SOCK_STREAM)
    except (OSError, UnicodeError) as exc:
        raise ConfigError(f"--host {host}: not an address of this machine ({exc})") from None
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind(address)
        sock.listen(128)
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise ConfigError(f"--port {port}: port {port} on {host} is in use (another dashboard?); stop it or "
                              f"give another --port") from None
        if exc.errno == errno.EACCES:
            raise ConfigError(f"--port {port}: not allowed to listen on port {port} (ports below 1024 need root); "
                              f"give a port from 1024") from None
        raise ConfigError(f"--host {host}: cannot listen on {host}:{port} ({exc.strerror})") from None
    return sock


class _Handler(WSGIRequestHandler):
    server_version = "suspid-dashboard"
    sys_version = ""


def serve(db: str | Path, *, host: str = "127.0.0.1", port: int = 8050, allow_ack: bool = False,
          create: bool = False, log: Log = lambda s: None, warn: Log | None = None) -> None:
    """Serve the dashboard until interrupted (werkzeug's threaded WSGI server; module docstring).

    :param create: make the SQLite database when it does not exist.
    :param warn: where the warning about a non-loopback address goes (default: ``log``).
    :raises ConfigError: a missing database, ``allow_ack`` without users, a port in use, a bad address.
    """
    warn = warn or log
    # read-only unless acknowledgements are allowed (or a new database is made): nothing is written then
    database = open_dashboard_database(db, create=create, read_only=not (allow_ack or create))
    try:
        if allow_ack and not has_users(database):
            raise ConfigError("--allow-ack: no user may acknowledge yet; add one with "
                              f"suspid fleet user add NAME --db {db}")
        sock = bind(host, port)
        try:
            app = create_app(database, allow_ack=allow_ack, log=log,
                             trusted_hosts=LOOPBACK_NAMES if is_loopback(host) else None)
            server = make_server(host, port, app, threaded=True, request_handler=_Handler, fd=sock.fileno())
            if not is_loopback(host):
                warn(f"warning: the dashboard listens on {host}, not only on this machine: anyone who can reach "
                     f"port {server.port} can read the fleet's state{' and try to log in' if allow_ack else ''}")
            shown = f"[{host.strip('[]')}]" if ":" in host else host
            log(f"dashboard on http://{shown}:{server.port}/ "
                f"({'acknowledgements by logged-in users' if allow_ack else 'read-only'}); Ctrl-C stops it")
            try:
                server.serve_forever()
            finally:
                server.server_close()
        finally:
            sock.close()
    finally:
        database.dispose()
