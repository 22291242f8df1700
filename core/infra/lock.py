"""One run per run directory: an exclusive lock, and the config that owns the directory.

Two processes working in one run directory would both simulate the same
points, and ``--fresh`` in one would delete the results of the other while it
is still working. :class:`RunLock` takes an exclusive lock on
``<run dir>/.lock`` for the length of a run; the file holds the process id,
host, start time and config name of the holder, so that a second process is
refused with one line naming them::

    run directory runs/demo is in use by process 4242 (config demo); wait for it or use another output.dir

The lock is ``fcntl.flock`` on POSIX and ``msvcrt.locking`` on one byte far
beyond the recorded text on Windows (the tests run on POSIX only). The
operating system releases it when the process ends, however it ends (even
SIGKILL), so a stale ``.lock`` file never blocks a later run; the file itself
stays. The lock is re-entrant within a process: a run that opens its own
directory again (a nested call) is not refused.

Two configs writing into one directory would replace each other's outputs.
:func:`check_same_config` records which config owns the directory in
``<run dir>/run_owner.json`` and refuses another one unless ``force``. The
digest to record is :func:`config_identity`: *which* config (its name and
its file's name), not its content, so that editing a config and running it again still
resumes from the ledger (the ledger's keys already tell which results still
apply).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
from pathlib import Path
from typing import Any, Callable, Iterator

from suspid.errors import RunDirError
from suspid.infra.files import write_json
from suspid.infra.ledger import Ledger, stable_hash

if os.name == "nt":   # pragma: no cover - not tested on Windows
    import msvcrt

    _WIN_BYTE = 1 << 20   # lock a byte past the recorded text, which stays readable by the refused process

    def _try_lock(fd: int) -> bool:
        os.lseek(fd, _WIN_BYTE, os.SEEK_SET)
        try:
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        except OSError:
            return False
        return True

    def _unlock(fd: int) -> None:
        os.lseek(fd, _WIN_BYTE, os.SEEK_SET)
        msvcrt.locking(fd, msvcrt.LK_UNLCK, 1)
else:
    import fcntl

    def _try_lock(fd: int) -> bool:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
        return True

    def _unlock(fd: int) -> None:
        fcntl.flock(fd, fcntl.LOCK_UN)

LOCK_FILE = ".lock"
"""Name of the lock file in a run directory."""
OWNER_FILE = "run_owner.json"

OPENED_LEDGERS: list[Path] = []
"""The ledgers this process has opened through :func:`open_run_dir`, in order (the CLI counts
what they keep when a run is interrupted)."""
"""Name of the file that records which config owns a run directory."""

_HELD: dict[str, list[Any]] = {}
"""Locks this process holds: resolved run directory -> [fd, count, pid]."""


def _key(run_dir: Path) -> str:
    return str(run_dir.resolve())


def _reason(exc: OSError) -> str:
    return (exc.strerror or str(exc)).lower()


def config_identity(name: str, source_file: str | Path | None = None) -> str:
    """The digest recorded for a config: its name and its file's name (if any), not its content.

    The file's name and not its full path, so that a project moved to another
    folder still resumes its runs.
    """
    return stable_hash("config", name, Path(source_file).name if source_file else None)


class RunLock:
    """An exclusive lock on a run directory for the length of a run (see the module docstring).

    ``with RunLock(run_dir, config_name="demo"):`` or ``lock = RunLock(...).acquire()`` then ``lock.release()``.

    :param run_dir: the run directory (created if absent).
    :param config_name: recorded in the lock file and named to a refused process.
    :param config_digest: recorded in the lock file.
    """

    def __init__(self, run_dir: str | Path, *, config_name: str | None = None,
                 config_digest: str | None = None) -> None:
        self.run_dir = Path(run_dir)
        self.config_name = config_name
        self.config_digest = config_digest
        self._acquired = False

    @property
    def path(self) -> Path:
        """The lock file, ``<run dir>/.lock``."""
        return self.run_dir / LOCK_FILE

    @staticmethod
    def holder(run_dir: str | Path) -> dict[str, Any]:
        """What the lock file of ``run_dir`` records (pid, host, config, started); ``{}`` if nothing readable."""
        try:
            data = json.loads((Path(run_dir) / LOCK_FILE).read_text(encoding="utf-8") or "{}")
        except (OSError, ValueError):
            return {}
        return data if isinstance(data, dict) else {}

    def acquire(self) -> "RunLock":
        """Take the lock now; returns ``self``.

        :raises RunDirError: another process holds it (one line naming its pid and config),
            or the lock file cannot be created.
        """
        if self._acquired:
            return self
        key = _key(self.run_dir) if self.run_dir.exists() else None
        held = _HELD.get(key) if key else None
        if held is not None and held[2] == os.getpid():
            held[1] += 1
            self._acquired = True
            return self
        try:
            self.run_dir.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise RunDirError(f"{self.path}: cannot create the lock file of the run directory "
                              f"({_reason(exc)})") from None
        if not _try_lock(fd):
            os.close(fd)
            info = self.holder(self.run_dir)
            for _ in range(20):  # the holder writes its record just after taking the lock: wait up to 1 s
                if "pid" in info:
                    break
                time.sleep(0.05)
                info = self.holder(self.run_dir)
            who = f"process {info['pid']}" if "pid" in info else "another process"
            if info.get("host") and info.get("host") != socket.gethostname():
                who += f" on {info['host']}"
            config = f" (config {info['config_name']})" if info.get("config_name") else ""
            raise RunDirError(f"run directory {self.run_dir} is in use by {who}{config}; wait for it or use "
                              f"another output.dir")
        record = {"pid": os.getpid(), "host": socket.gethostname(), "config_name": self.config_name,
                  "config_digest": self.config_digest,
                  "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}
        try:
            os.ftruncate(fd, 0)
            os.lseek(fd, 0, os.SEEK_SET)
            os.write(fd, (json.dumps(record) + "\n").encode())
        except OSError:
            pass   # the lock holds without the record; a refused process then names no pid
        _HELD[_key(self.run_dir)] = [fd, 1, os.getpid()]
        self._acquired = True
        return self

    def release(self) -> None:
        """Let the lock go (the last release of this process unlocks the file)."""
        if not self._acquired:
            return
        self._acquired = False
        key = _key(self.run_dir)
        held = _HELD.get(key)
        if held is None:
            return
        held[1] -= 1
        if held[1] > 0:
            return
        del _HELD[key]
        fd = held[0]
        try:
            if held[2] == os.getpid():   # a forked child shares the lock: only its owner unlocks it
                os.ftruncate(fd, 0)
                _unlock(fd)
        except OSError:
            pass
        finally:
            os.close(fd)

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, *exc: Any) -> None:
        self.release()


def check_same_config(run_dir: str | Path, config_digest: str, force: bool = False, *,
                      config_name: str | None = None, config_file: str | Path | None = None) -> None:
    """Refuse to run (or ``--fresh``) in a directory that holds the run of another config, unless ``force``.

    The first run records ``config_digest`` (see :func:`config_identity`), name
    and file in ``<run dir>/run_owner.json``; a later run with the same digest
    goes on; ``force`` records the new owner. A directory with results but no
    record (made before this check existed) is taken over.

    :raises RunDirError: one line naming the directory, the config that owns
        it and the remedies.
    """
    run_dir = Path(run_dir)
    owner_file = run_dir / OWNER_FILE
    record = {"config_digest": config_digest, "config_name": config_name,
              "config_file": str(config_file) if config_file else None}
    owner: Any = None
    if owner_file.exists():
        try:
            owner = json.loads(owner_file.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            if not force:
                raise RunDirError(f"{owner_file}: cannot read which config owns this run directory ({exc}); "
                                  f"delete the file or use --force") from None
        if isinstance(owner, dict) and owner.get("config_digest") == config_digest:
            return
        if not force:
            other = owner if isinstance(owner, dict) else {}
            named = " ".join(filter(None, [f"'{other.get('config_name')}'" if other.get("config_name") else None,
                                           f"({other['config_file']})" if other.get("config_file") else None]))
            raise RunDirError(f"run directory {run_dir} holds the run of another config {named or ''}".rstrip()
                              + "; use another output.dir, or --force to replace it")
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        write_json(owner_file, record)
    except OSError as exc:
        raise RunDirError(f"{owner_file}: cannot record the owner of the run directory ({_reason(exc)})") from None


@contextlib.contextmanager
def open_run_dir(run_dir: str | Path, *, config_name: str, config_file: str | Path | None = None,
                 fresh: bool = False, force: bool = False,
                 log: Callable[[str], None] = lambda s: None) -> Iterator[Ledger]:
    """Everything a run needs before it writes: lock, owner check, ledger (cleared or set aside if ``fresh``).

    ``with open_run_dir(run_dir, config_name=cfg.name, config_file=cfg.source_file, fresh=fresh) as ledger:``
    holds the lock until the block ends, then closes the ledger.

    :raises RunDirError: the directory is in use or owned by another config (see :func:`check_same_config`).
    :raises LedgerError: the ledger is damaged or foreign and ``fresh`` is not set.
    """
    digest = config_identity(config_name, config_file)
    with RunLock(run_dir, config_name=config_name, config_digest=digest):
        check_same_config(run_dir, digest, force, config_name=config_name, config_file=config_file)
        path = Path(run_dir) / "ledger.sqlite"
        ledger = Ledger.fresh(path, log=log) if fresh else Ledger(path)
        ledger.count()   # open and check it now, before any work
        if path not in OPENED_LEDGERS:
            OPENED_LEDGERS.append(path)
        try:
            yield ledger
        finally:
            ledger.close()
