"""Asynchronous EGO (``ego.asynchronous``): one point in flight per worker, reproducible and resumable.

Real runs of the exudyn train (frequency solver, a few short segments) with the
real ``serial`` and ``processes`` executors; the dask LocalCluster case is in
``test_cluster.py``.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

import suspid
from suspid.errors import ConfigError

from conftest import count_evaluations, run_cli

M0, M1 = 6, 6
TINY = {"name": "tiny", "seed": 5,
        "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency"}},
        "parameters": {"k_sec_z": {}, "c_sec_z": {}, "c_sec_y": {}},
        "data": {"source": "experiment",
                 "track": {"spectrum": "german-low", "n_segments": 6, "length_m": 600.0, "speed_kmh": 300.0},
                 "w_ref": {"k_sec_z": 330.0e3, "c_sec_z": 27.0e3, "c_sec_y": 21.0e3}},
        "spectra": {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 60},
        "design": {"n_initial": M0},
        "ego": {"max_iter": M1, "tol": 0.0, "explore_tol": 0.0},  # every run makes M0 + M1 evaluations
        "identifiability": {"n_redraws": 6}}
PROCESSES = {"plugin": "processes", "options": {"workers": 2}}


def _config(out: Path, executor: dict | None = None, **ego) -> dict:
    return {**TINY, "ego": {**TINY["ego"], **ego}, "output": {"dir": str(out)},
            "executor": executor or {"plugin": "serial"}}


def _run(out: Path, executor: dict | None = None, **ego) -> dict:
    return suspid.identify(_config(out, executor, **ego)).to_dict()


def _same(a: dict, b: dict) -> None:
    for key in ("w_opt", "J_max", "anytime", "interval", "identifiable", "n_simulator_calls", "stop_reason"):
        assert a[key] == b[key], key


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The tiny run with the serial executor, and asynchronously with 2 processes (twice)."""
    tmp = tmp_path_factory.mktemp("async")
    return {"serial": _run(tmp / "serial"), "async": _run(tmp / "async", PROCESSES),
            "async-again": _run(tmp / "async-again", PROCESSES)}


def test_two_asynchronous_runs_give_the_same_result(runs):
    _same(runs["async"], runs["async-again"])
    assert runs["async"]["n_simulator_calls"] == M0 + M1


def test_asynchronous_ego_proposes_beside_the_point_in_flight(runs):
    """The design and EGO's first point (the paper's step on the design) are those of the serial run;
    the second point is chosen while the first is running, so it is another point."""
    serial, asynchronous = runs["serial"]["anytime"], runs["async"]["anytime"]
    assert asynchronous["w_normalized"][:M0 + 1] == serial["w_normalized"][:M0 + 1]
    assert asynchronous["J"][:M0 + 1] == serial["J"][:M0 + 1]
    second = np.array(asynchronous["w_normalized"][M0 + 1])
    assert np.max(np.abs(second - np.array(serial["w_normalized"][M0 + 1]))) > 1e-3
    assert np.max(np.abs(second - np.array(asynchronous["w_normalized"][M0]))) > 1e-3  # not the one in flight
    assert runs["async"]["J_max"] > max(asynchronous["J"][:M0])  # EGO improved on the design


def test_asynchronous_ego_stops_on_the_papers_ei_rule_reproducibly(tmp_path):
    """With the paper's stop (EI < eps) instead of a fixed m1: a point whose EI is below eps beside the
    points in flight is not asked; with none in flight, the paper's step stops the loop."""
    ego = {"tol": 1e-2, "explore_tol": 1e-4, "max_iter": 20}
    a, b = (_run(tmp_path / name, PROCESSES, **ego) for name in ("a", "b"))
    _same(a, b)
    assert a["stop_reason"] == "ei_below_tol" and M0 < a["n_simulator_calls"] < M0 + 20


def test_serial_and_synchronous_processes_run_the_papers_loop(tmp_path, runs):
    """``asynchronous: false`` with 2 workers, and any single worker, is the paper's loop: the serial result."""
    _same(_run(tmp_path / "sync", PROCESSES, asynchronous=False), runs["serial"])
    _same(_run(tmp_path / "one", {"plugin": "processes", "options": {"workers": 1}}, asynchronous=True),
          runs["serial"])


def test_the_refinement_continues_after_asynchronous_ego(tmp_path, runs):
    """After the asynchronous EGO phase (the same points as without a refinement), the trust-region
    steps, one at a time (each starts from the best point so far), through the same executor."""
    out = _run(tmp_path / "refine", PROCESSES, refine={"enabled": True, "max_iter": 3})
    assert out["anytime"]["w_normalized"][:M0 + M1] == runs["async"]["anytime"]["w_normalized"]
    n_refine = out["n_refine_iterations"]
    assert 1 <= n_refine <= 3 and out["n_simulator_calls"] == M0 + M1 + n_refine


def test_sigkill_mid_ego_then_rerun_gives_the_uninterrupted_result(tmp_path, runs):
    out = tmp_path / "run"
    path = tmp_path / "tiny.yaml"
    path.write_text(yaml.safe_dump(_config(out, PROCESSES), sort_keys=False))
    ledger = out / "ledger.sqlite"
    proc = subprocess.Popen([sys.executable, "-m", "suspid", "run", str(path), "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    deadline = time.time() + 240
    while count_evaluations(ledger) < M0 + 2 and time.time() < deadline and proc.poll() is None:
        time.sleep(0.01)
    os.killpg(proc.pid, signal.SIGKILL)  # the driver and its worker processes
    proc.wait(timeout=30)
    killed_at = count_evaluations(ledger)
    assert M0 + 2 <= killed_at < M0 + M1, killed_at  # killed inside asynchronous EGO
    res = run_cli("run", str(path), "--quiet")
    assert res.returncode == 0, res.stderr
    resumed = json.loads((out / "result.json").read_text())
    assert resumed["n_simulator_calls_this_session"] == M0 + M1 - killed_at
    _same(resumed, runs["async"])


@pytest.mark.parametrize("ego,expected", [
    ({"asynchronous": True, "batch": 2}, "asynchronous EGO proposes one point at a time; with batch = 2"),
    ({"asynchronous": "sometimes"}, "Input should be 'auto', True or False"),
])
def test_invalid_asynchronous_option_is_one_line(tmp_path, ego, expected):
    with pytest.raises(ConfigError) as info:
        suspid.validate(_config(tmp_path, PROCESSES, **ego))
    message = str(info.value)
    assert "key 'ego.asynchronous'" in message and expected in message and "\n" not in message, message
