"""Helpers of the cluster tests: a test simulator that worker processes import, and real dask processes.

``PidTrain`` is the exudyn train that, in whatever process it simulates,
leaves a file named after that process's id in the folder
``$SUSPID_TEST_PID_DIR`` (when set) and then sleeps ``$SUSPID_TEST_SLEEP_S``
seconds (default 0). Worker processes import it by reference from this
module: a LocalCluster's spawned workers inherit the driver's ``sys.path``,
and the scheduler/worker subprocesses started here get this folder on
``PYTHONPATH``.

Run as a script, ``python tests/cluster_helpers.py ARGS`` is the ``suspid``
command with ``PidTrain`` registered (as ``pid-train``).
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
import types
import uuid
from pathlib import Path

from suspid import hookimpl, registry
from suspid.plugins.simulators.exudyn_train import ExudynTrain

HERE = Path(__file__).resolve().parent
PID_DIR_VAR = "SUSPID_TEST_PID_DIR"
SLEEP_VAR = "SUSPID_TEST_SLEEP_S"


class PidTrain(ExudynTrain):
    """The exudyn train, recording the id of each process it simulates in (see the module docstring)."""

    name = "pid-train"

    def simulate(self, w, segments):
        folder = os.environ.get(PID_DIR_VAR)
        if folder:
            Path(folder, f"{os.getpid()}-{uuid.uuid4().hex}").touch()
        time.sleep(float(os.environ.get(SLEEP_VAR, "0")))
        return super().simulate(w, segments)


def register() -> None:
    """Register ``PidTrain`` in this process's registry."""
    registry.add_plugin(types.SimpleNamespace(suspid_register_simulators=hookimpl(
        lambda register: register(PidTrain))), "pid-train")


def recorded_pids(folder: Path) -> list[int]:
    """The process ids of every simulation recorded in ``folder``."""
    return [int(p.name.split("-")[0]) for p in folder.iterdir()]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(HERE), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def start_scheduler(port: int, timeout_s: float = 30.0) -> subprocess.Popen:
    """A ``dask scheduler`` process on 127.0.0.1:``port``, once it accepts connections."""
    proc = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                             "--port", str(port), "--no-dashboard"], env=_env(),
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=0.5).close()
            return proc
        except OSError:
            time.sleep(0.2)
    stop(proc)
    raise RuntimeError(f"the dask scheduler did not listen on port {port} within {timeout_s} s")


def start_worker(address: str, *, without_suspid: bool = False, sleep_s: float = 0.0) -> subprocess.Popen:
    """A ``dask worker`` process (no nanny, one thread); ``without_suspid``: one where ``import suspid`` fails;
    ``sleep_s``: each simulation of the test simulator sleeps that long on it (the simulations run there).

    ``sys.modules['suspid'] = None`` makes every import of suspid fail in that
    process (what a worker in an environment without suspid sees), while
    dask itself is there; without a nanny the worker is that very process.
    """
    args = ["dask-worker", address, "--no-nanny", "--nthreads", "1", "--no-dashboard"]
    code = (("import sys; sys.modules['suspid'] = None; " if without_suspid else "import sys; ")
            + f"sys.argv = {args!r}; from distributed.cli.dask_worker import main; main()")
    return subprocess.Popen([sys.executable, "-c", code], env={**_env(), SLEEP_VAR: str(sleep_s)},
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def wait_for_workers(address: str, n: int, timeout_s: float = 60.0) -> list[str]:
    """The addresses of the scheduler's workers, once there are ``n``."""
    from distributed import Client

    with Client(address, timeout=timeout_s) as client:
        client.wait_for_workers(n, timeout=timeout_s)
        return sorted(client.scheduler_info(n_workers=-1)["workers"])


def stop(proc: subprocess.Popen) -> None:
    """End a process started here, at once (SIGKILL), and reap it."""
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=30)


def cli(*args: str, env: dict[str, str] | None = None, timeout_s: float = 180.0) -> subprocess.Popen:
    """``suspid ARGS`` with ``PidTrain`` registered, in a subprocess (not waited for)."""
    from conftest import interruptible  # the tests send it SIGINT

    return subprocess.Popen([sys.executable, str(Path(__file__).resolve()), *args], env={**_env(), **(env or {})},
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=interruptible)


if __name__ == "__main__":
    sys.path.insert(0, str(HERE))
    from cluster_helpers import register as _register  # by module name, so workers import the same class

    _register()
    from suspid.cli import main

    main(sys.argv[1:])
