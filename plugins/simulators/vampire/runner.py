"""Running an external command as an argument list, with its whole process tree under control.

- never through a shell: ``argv`` is a list handed to :class:`subprocess.Popen`;
- stdin is ``/dev/null`` (a program waiting for input would otherwise hang),
  stdout and stderr go to files;
- the command starts a session of its own (POSIX) or a process group of its
  own (Windows), so that on timeout or cancellation the whole tree is ended:
  SIGTERM to the group, then SIGKILL after a grace period (Windows:
  ``taskkill /T /F``);
- after a normal exit, processes the command left behind in its group are
  ended too (``kill_leftovers``), so no run leaves anything running.

A process that starts a new session itself (a daemon) escapes the group; that
is the only way to outlive a run.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

from suspid.errors import SimulatorError

_POLL_S = 0.05


@dataclass
class RunResult:
    """What happened to one command.

    :ivar returncode: exit code, or ``None`` when the process was killed by us.
    :ivar timed_out: the time limit was reached and the tree was killed.
    :ivar cancelled: ``cancel`` was set and the tree was killed.
    :ivar elapsed_s: wall-clock time in s.
    """

    returncode: int | None
    timed_out: bool
    cancelled: bool
    elapsed_s: float
    stdout: Path
    stderr: Path


def _group_members(pgid: int) -> list[int] | None:
    """Live (non-zombie) processes of group ``pgid`` from ``/proc``, or ``None`` without ``/proc``."""
    proc = Path("/proc")
    if not (proc / "self" / "stat").exists():
        return None
    members = []
    for entry in proc.iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        fields = stat[stat.rfind(")") + 2:].split()  # state ppid pgrp ...
        if len(fields) >= 3 and int(fields[2]) == pgid and fields[0] not in ("Z", "X"):
            members.append(int(entry.name))
    return members


def _group_alive(pgid: int) -> bool:
    members = _group_members(pgid)
    if members is not None:
        return bool(members)
    try:
        os.killpg(pgid, 0)
    except (ProcessLookupError, PermissionError):
        return False
    return True


def _signal_group(pgid: int, sig: int) -> None:
    if pgid == os.getpgrp():  # never signal our own group (it would end suspid itself)
        raise SimulatorError(f"refusing to signal process group {pgid}: it is suspid's own")
    try:
        os.killpg(pgid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def kill_tree(proc: subprocess.Popen, grace_s: float) -> None:
    """End ``proc`` and every process of its group: SIGTERM, wait up to ``grace_s``, SIGKILL.

    On Windows, ``taskkill /T /F`` ends the tree at once. Reaps ``proc``.
    """
    if os.name == "nt":  # pragma: no cover - exercised on Windows only
        subprocess.run(["taskkill", "/T", "/F", "/PID", str(proc.pid)], stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL, check=False)
        proc.wait()
        return
    pgid = proc.pid  # start_new_session=True: the child leads its own group
    _signal_group(pgid, signal.SIGTERM)
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline:
        if proc.poll() is not None and not _group_alive(pgid):
            break
        time.sleep(_POLL_S)
    _signal_group(pgid, signal.SIGKILL)
    proc.wait()


def end_leftovers(pgid: int, grace_s: float) -> bool:
    """End what is left of process group ``pgid`` after its leader exited; True if anything was left."""
    if os.name == "nt" or not _group_alive(pgid):
        return False
    _signal_group(pgid, signal.SIGTERM)
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline and _group_alive(pgid):
        time.sleep(_POLL_S)
    _signal_group(pgid, signal.SIGKILL)
    return True


def run_command(argv: Sequence[str], cwd: Path, env: Mapping[str, str], timeout_s: float, stdout: Path,
                stderr: Path, *, grace_s: float = 5.0, kill_leftovers: bool = True,
                cancel: threading.Event | None = None) -> RunResult:
    """Run ``argv`` in ``cwd`` and wait for it, at most ``timeout_s`` seconds.

    :param argv: program and arguments (no shell).
    :param env: the complete environment of the child.
    :param stdout: file receiving the child's stdout (created or replaced).
    :param stderr: file receiving the child's stderr.
    :param grace_s: time between SIGTERM and SIGKILL, s.
    :param kill_leftovers: end processes left in the group after a normal exit.
    :param cancel: when set by another thread, the tree is killed and the
        result says ``cancelled``.
    :raises SimulatorError: when the program cannot be started (not found,
        not executable), naming it.
    """
    argv = [str(a) for a in argv]
    kwargs: dict = {}
    if os.name == "nt":  # pragma: no cover - Windows
        kwargs["creationflags"] = subprocess.CREATE_NEW_PROCESS_GROUP
    else:
        kwargs["start_new_session"] = True
    start = time.monotonic()
    with open(stdout, "wb") as out, open(stderr, "wb") as err:
        try:
            proc = subprocess.Popen(argv, cwd=str(cwd), env=dict(env), stdin=subprocess.DEVNULL, stdout=out,
                                    stderr=err, close_fds=True, **kwargs)
        except FileNotFoundError:
            raise SimulatorError(f"command not found: {argv[0]!r} (command {argv})") from None
        except PermissionError:
            raise SimulatorError(f"command not executable: {argv[0]!r} (command {argv})") from None
        except OSError as exc:
            raise SimulatorError(f"cannot start {argv[0]!r}: {exc}") from None
        timed_out = cancelled = False
        try:
            while True:
                try:
                    proc.wait(timeout=_POLL_S)
                    break
                except subprocess.TimeoutExpired:
                    pass
                if cancel is not None and cancel.is_set():
                    cancelled = True
                elif time.monotonic() - start > timeout_s:
                    timed_out = True
                if timed_out or cancelled:
                    kill_tree(proc, grace_s)
                    break
        except BaseException:  # KeyboardInterrupt while waiting: leave nothing behind
            kill_tree(proc, grace_s)
            raise
        if not (timed_out or cancelled) and kill_leftovers and os.name != "nt":
            end_leftovers(proc.pid, grace_s)
    return RunResult(returncode=None if (timed_out or cancelled) else proc.returncode, timed_out=timed_out,
                     cancelled=cancelled, elapsed_s=time.monotonic() - start, stdout=Path(stdout),
                     stderr=Path(stderr))
