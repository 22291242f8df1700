"""A run on a real dask cluster: nothing simulated in the driver, and every cluster fault ends in one line.

The cluster is real: a LocalCluster of worker processes, or a ``dask
scheduler`` and ``dask worker`` processes started here (``cluster_helpers``),
killed with SIGKILL where a test needs a fault. The run itself runs as the
``suspid`` command in a subprocess where a test checks its exit code and
output.
"""

from __future__ import annotations

import http.server
import json
import os
import signal
import socketserver
import sqlite3
import subprocess
import threading
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

import suspid
from suspid.errors import ClusterError
from suspid.plugins.executors.dask import DaskExecutor

from cluster_helpers import (PID_DIR_VAR, cli, free_port, recorded_pids, register, start_scheduler,
                             start_worker, stop, wait_for_workers)

TINY = {"name": "tiny", "seed": 4,
        "simulator": {"plugin": "pid-train", "options": {"solver": "frequency"}},
        "parameters": {"k_sec_z": {}, "c_sec_z": {}},
        "data": {"source": "experiment",
                 "track": {"spectrum": "german-low", "n_segments": 6, "length_m": 600.0, "speed_kmh": 300.0},
                 "w_ref": {"k_sec_z": 330.0e3, "c_sec_z": 27.0e3}},
        "spectra": {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 80},
        "design": {"n_initial": 6}, "ego": {"max_iter": 4, "batch": 2},
        "identifiability": {"n_redraws": 6}}


def _config(tmp_path: Path, name: str, **executor) -> dict:
    return {**TINY, "output": {"dir": str(tmp_path / name)},
            "executor": executor or {"plugin": "serial"}}


@pytest.fixture
def pid_train():
    register()


@pytest.fixture
def processes():
    """Processes started by a test, ended (SIGKILL) after it whatever happens."""
    started = []
    yield started
    for proc in started:
        stop(proc)


@pytest.fixture(scope="module")
def serial_result(tmp_path_factory):
    """The tiny run with the serial executor: the answer every cluster run must give."""
    register()
    out = suspid.identify(_config(tmp_path_factory.mktemp("serial"), "run"))
    return out.to_dict()


def _same_answer(result: dict, expected: dict) -> None:
    assert result["w_opt"] == expected["w_opt"]  # exactly: the same points and the same J values
    assert result["n_simulator_calls"] == expected["n_simulator_calls"] == 6 + 4
    assert result["interval"] == expected["interval"]


# -- acceptance: with a cluster, the driver simulates nothing -------------------------------------
@pytest.mark.slow
def test_no_simulation_of_a_run_in_the_driver(tmp_path, monkeypatch, pid_train, serial_result):
    pids = tmp_path / "pids"
    pids.mkdir()
    monkeypatch.setenv(PID_DIR_VAR, str(pids))  # inherited by the LocalCluster's worker processes
    config = _config(tmp_path, "dask", plugin="dask", options={"n_workers": 2, "threads_per_worker": 1})
    lines = []
    out = suspid.identify(config, log=lines.append)
    _same_answer(out.to_dict(), serial_result)
    seen = recorded_pids(pids)
    # reference date (y_mes0, y_sim0), measurement date, design + EGO, w_opt and the 2q interval points
    assert len(seen) == 3 + out.n_simulator_calls + 2 * 2 + 1, sorted(seen)
    assert os.getpid() not in seen, "a simulation ran in the driver process"
    assert len(set(seen)) == 2, f"both workers should have simulated: {sorted(set(seen))}"
    assert any(line.startswith("dask executor: scheduler tcp://") and "dashboard http" in line for line in lines), lines


@pytest.mark.slow
def test_asynchronous_ego_on_dask_simulates_nothing_in_the_driver_and_repeats_on_processes(
        tmp_path, monkeypatch, pid_train):
    """``ego.batch: 1`` on 2 workers: asynchronous EGO, every simulation on a worker, and the schedule
    (not the timing) fixes the points: a pool of 2 processes gives the same run."""
    ego = {"max_iter": 4, "tol": 0.0, "explore_tol": 0.0}
    pids = tmp_path / "pids"
    pids.mkdir()
    monkeypatch.setenv(PID_DIR_VAR, str(pids))  # inherited by the LocalCluster's worker processes
    config = _config(tmp_path, "dask", plugin="dask", options={"n_workers": 2, "threads_per_worker": 1})
    out = suspid.identify({**config, "ego": ego})
    assert out.ego.stop_reason == "max_iter" and out.n_simulator_calls == 6 + 4
    seen = recorded_pids(pids)
    assert len(seen) == 3 + out.n_simulator_calls + 2 * 2 + 1, sorted(seen)
    assert os.getpid() not in seen, "a simulation ran in the driver process"
    assert len(set(seen)) == 2, f"both workers should have simulated: {sorted(set(seen))}"
    monkeypatch.delenv(PID_DIR_VAR)
    pool = suspid.identify({**_config(tmp_path, "processes", plugin="processes", options={"workers": 2}),
                            "ego": ego}).to_dict()
    for key in ("w_opt", "anytime", "interval"):
        assert out.to_dict()[key] == pool[key], key


# -- faults of a real scheduler ---------------------------------------------------------------------
def _ledger_status(path: Path) -> dict[str, int]:
    for _ in range(50):
        try:
            with sqlite3.connect(f"file:{path}?mode=ro", uri=True, timeout=5) as db:
                return dict(db.execute("SELECT status, COUNT(*) FROM evaluations GROUP BY status").fetchall())
        except sqlite3.OperationalError:  # not created yet, or being written
            time.sleep(0.1)
    return {}


def _error_lines(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if line.strip()]


@pytest.mark.slow
def test_ctrl_c_then_scheduler_killed_mid_run_nothing_failed_and_the_rerun_gives_the_serial_result(
        tmp_path, processes, serial_result):
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes += [start_scheduler(port), start_worker(address, sleep_s=0.3)]  # slow enough to interrupt
    config = _config(tmp_path, "run", plugin="dask", options={"address": address, "timeout_s": 10})
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    ledger = tmp_path / "run" / "ledger.sqlite"

    def run_until(more: int) -> subprocess.Popen:
        """The run, started, once ``more`` simulations more than now are in the ledger."""
        n_ok = _ledger_status(ledger).get("ok", 0) + more
        run = cli("run", str(path), "--quiet")
        deadline = time.monotonic() + 120
        while _ledger_status(ledger).get("ok", 0) < n_ok and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        assert run.poll() is None, f"the run ended too early: {run.communicate()}"
        return run

    # Ctrl-C first: exit 130 as everywhere, nothing failed
    run = run_until(2)
    run.send_signal(signal.SIGINT)
    _, stderr = run.communicate(timeout=60)
    assert run.returncode == 130 and "interrupted" in stderr, stderr
    assert _ledger_status(ledger).get("failed", 0) == 0

    run = run_until(2)
    stop(processes[0])  # the scheduler
    t0 = time.monotonic()
    _, stderr = run.communicate(timeout=60)
    assert run.returncode == 2, stderr
    assert time.monotonic() - t0 < 30
    lines = _error_lines(stderr)
    assert len(lines) == 1 and "lost the connection to the dask" in lines[0] and address in lines[0], stderr
    assert "run the same command again" in lines[0]
    status = _ledger_status(ledger)
    assert status.get("failed", 0) == 0 and 4 <= status["ok"] < 10, status  # killed mid-design or mid-EGO

    # a new scheduler on the same port, new workers: the same command resumes and finishes
    for proc in processes[1:]:
        stop(proc)
    processes += [start_scheduler(port), start_worker(address)]
    rerun = cli("run", str(path), "--quiet")
    _, stderr = rerun.communicate(timeout=180)
    assert rerun.returncode == 0, stderr
    _same_answer(json.loads((tmp_path / "run" / "result.json").read_text()), serial_result)
    assert _ledger_status(ledger) == {"ok": 10}


def big_result(item: float) -> bytes:
    """Sleeps ``item`` seconds, then returns 150 MB: a result whose transfer takes a while."""
    time.sleep(item)
    return b"\0" * 150_000_000


@pytest.mark.slow
def test_scheduler_killed_during_a_transfer_is_a_cluster_error_within_the_timeout(processes):
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes.append(start_scheduler(port))
    processes.append(start_worker(address))
    with DaskExecutor(address=address, timeout_s=5, result_timeout_s=20) as executor:
        handle = executor.submit(big_result, 0.5)
        # kill the scheduler the moment the task is done, while its result is on its way to the driver
        killer = threading.Thread(target=lambda: (_wait_finished(handle.future), stop(processes[0])))
        killer.start()
        t0 = time.monotonic()
        with pytest.raises(ClusterError, match="dask"):
            executor.wait_first([handle], timeout=30)
            list(executor.map_unordered(big_result, [0.0]))  # the transfer won the race: the next call fails
        assert time.monotonic() - t0 < 25
        killer.join(timeout=30)


def _wait_finished(future, timeout_s: float = 30.0) -> None:
    deadline = time.monotonic() + timeout_s
    while future.status != "finished" and time.monotonic() < deadline:
        time.sleep(0.01)


@pytest.mark.slow
def test_a_worker_without_suspid_is_named_exit_2(tmp_path, processes):
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    processes.append(start_scheduler(port))
    processes += [start_worker(address), start_worker(address, without_suspid=True)]
    workers = wait_for_workers(address, 2)
    config = _config(tmp_path, "run", plugin="dask", options={"address": address, "n_workers": 2, "timeout_s": 10})
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    for command in ("validate", "run"):
        proc = cli(command, str(path), *(["--quiet"] if command == "run" else []))
        _, stderr = proc.communicate(timeout=120)
        lines = _error_lines(stderr)
        assert proc.returncode == 2 and len(lines) == 1, (command, stderr)
        named = [w for w in workers if w in lines[0]]
        assert len(named) == 1 and "cannot run suspid" in lines[0] and "ModuleNotFoundError" in lines[0], lines
    assert not (tmp_path / "run" / "ledger.sqlite").exists()  # stopped before the run directory


def test_no_progress_for_result_timeout_is_a_cluster_error():
    with DaskExecutor(n_workers=1, processes=False, result_timeout_s=1.0, timeout_s=30) as executor:
        t0 = time.monotonic()
        with pytest.raises(ClusterError, match=r"no task finished for result_timeout_s=1 s"):
            list(executor.map_unordered(time.sleep, [5.0]))
        assert time.monotonic() - t0 < 4


def test_task_function_crosses_to_each_worker_once():
    """A large task function is left with the scheduler once per executor, not once per call or task."""
    payload = Heavy(np.arange(1_000_000, dtype=float))  # 8 MB
    with DaskExecutor(n_workers=1, processes=False, timeout_s=30) as executor:
        for _ in range(3):
            assert sorted(dict(executor.map_unordered(payload, [1, 2, 3])).values()) == [1.0, 2.0, 3.0]
        assert len(executor.published_) == 1  # one copy with the scheduler, for three calls
        stored = executor.client_.get_metadata(["suspid", "executor-fn", executor.session_])
        assert sum(len(v) for v in stored.values()) > 8e6 and len(stored) == 1


class Heavy:
    """A task function holding a large array (as a simulation task holds the track)."""

    def __init__(self, data: np.ndarray):
        self.data = data

    def __call__(self, item: int) -> float:
        return float(item) + float(self.data[0])


def test_a_task_cancelled_by_the_cluster_is_a_cluster_error_not_a_shorter_list():
    """A scheduler restarted on the same port forgets every task: that must never read as fewer results."""
    with DaskExecutor(n_workers=1, processes=False, timeout_s=30) as executor:
        results = executor.map_unordered(time.sleep, [0.0, 3.0])
        assert next(results)[0] == 0
        from distributed import Future

        # what a restarted scheduler does to the tasks it never heard of
        executor.client_.cancel([Future(key, executor.client_) for key in list(executor.client_.futures)])
        with pytest.raises(ClusterError, match="task 1 was cancelled by the cluster without a result"):
            next(results)


def test_validate_reaches_the_scheduler(tmp_path):
    """``suspid validate`` connects as a run would: an unreachable scheduler is a config error naming it."""
    from suspid.errors import ConfigError

    config = _config(tmp_path, "run", plugin="dask", options={"address": "tcp://127.0.0.1:9", "timeout_s": 1})
    config["simulator"]["plugin"] = "exudyn-train"
    with pytest.raises(ConfigError, match=r"cannot connect to the dask scheduler at tcp://127\.0\.0\.1:9"):
        suspid.validate(config)
    config["executor"]["options"] = {"n_workers": 2}  # a LocalCluster: nothing to reach, nothing started
    assert suspid.validate(config).config.executor.plugin == "dask"


# -- a wrong address: not a dask scheduler, or not an address ------------------------------------
class _StatusLine(socketserver.BaseRequestHandler):
    """A service that answers every connection with an HTTP status line (what dask read as a length)."""

    def handle(self):
        self.request.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")


@pytest.fixture
def not_dask():
    """Two services on loopback that are not dask schedulers: an HTTP server (silent until it gets a
    request line) and one that answers with an HTTP status line at once; their ``tcp://`` addresses."""
    servers = [http.server.ThreadingHTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler),
               socketserver.ThreadingTCPServer(("127.0.0.1", 0), _StatusLine)]
    for s in servers:
        s.daemon_threads = True
        threading.Thread(target=s.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True).start()
    yield {kind: f"tcp://127.0.0.1:{s.server_address[1]}" for kind, s in zip(("silent", "status"), servers)}
    for s in servers:
        s.shutdown()
        s.server_close()


@pytest.mark.parametrize("command", ["validate", "run"])
@pytest.mark.parametrize("service, words", [
    ("silent", "is not a dask scheduler: it accepted the connection but sent no dask handshake within timeout_s=2"),
    ("status", "is not a dask scheduler: it answered 'HTTP/1.1 400 Bad Request', not the dask protocol"),
    ("sched:notaport", "'sched:notaport' (from executor.options.address) is not a dask scheduler address"),
    ("tcp://127.0.0.1", "'tcp://127.0.0.1' (from executor.options.address) is not a dask scheduler address"),
], ids=["http-server", "status-line", "port-not-a-number", "no-port"])
def test_an_address_that_is_not_a_dask_scheduler_is_one_line_exit_2_within_the_timeout(
        tmp_path, capsys, not_dask, command, service, words):
    """``suspid validate`` and ``suspid run`` (the command line, in this process): one line naming the
    address and the key, exit 2, within timeout_s (2 s) and not "out of memory" or "a bug in the plugin";
    nothing written in the run directory."""
    from suspid.cli import main

    address = not_dask.get(service, service)
    config = _config(tmp_path, "run", plugin="dask", options={"address": address, "timeout_s": 2})
    config["simulator"]["plugin"] = "exudyn-train"
    path = tmp_path / "wrong-address.yaml"
    path.write_text(yaml.safe_dump(config))
    t0 = time.monotonic()
    with pytest.raises(SystemExit) as exited:
        main([command, str(path), "--quiet"] if command == "run" else [command, str(path)])
    elapsed = time.monotonic() - t0
    err = capsys.readouterr().err
    assert exited.value.code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: key 'executor.options.address': "), err
    assert address in lines[0] and words in lines[0], lines[0]
    assert elapsed < 2 + 5, elapsed   # the timeout, and a margin for a loaded machine
    assert not (tmp_path / "run" / "result.json").exists()
