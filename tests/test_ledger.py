"""The SQLite run ledger: durability under SIGKILL, reuse, concurrent writers."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

from suspid.infra.ledger import Evaluation, Ledger, evaluation_key, stable_hash


def test_key_depends_on_all_three_parts():
    sim = {"plugin": "quarter-car", "options": {"fs_hz": 100.0}}
    k = evaluation_key(sim, {"a": 1.0, "b": 2.0}, "data1")
    assert k == evaluation_key(sim, {"b": 2.0, "a": 1.0}, "data1")  # order of names does not matter
    assert k != evaluation_key(sim, {"a": 1.0, "b": 2.0000001}, "data1")
    assert k != evaluation_key(sim, {"a": 1.0, "b": 2.0}, "data2")
    assert k != evaluation_key({"plugin": "quarter-car", "options": {"fs_hz": 50.0}}, {"a": 1.0, "b": 2.0}, "data1")
    assert stable_hash(np.float64(0.1)) == stable_hash(0.1)


def test_put_get_and_arrays(tmp_path):
    led = Ledger(tmp_path / "ledger.sqlite")
    ev = Evaluation("k1", {"a": 1.5}, J=-3.25, psi=[-3.0, -3.5], wall_time_s=0.1)
    led.put(ev)
    got = led.get("k1")
    assert got.J == -3.25 and got.psi == [-3.0, -3.5] and got.w == {"a": 1.5} and got.ok
    led.put(Evaluation("k2", {"a": 2.0}, None, None, status="failed", error="SimulatorError: boom"))
    assert led.count() == 1 and led.count(None) == 2
    arr = np.arange(12.0).reshape(3, 4)
    led.put_array("y_ref", arr)
    assert np.array_equal(led.get_array("y_ref"), arr)
    led.put_iteration("ego", 0, {"x": [0.5], "EI": 1e-3})
    assert led.iterations("ego") == [{"x": [0.5], "EI": 0.001}]
    led.clear()
    assert led.count(None) == 0 and led.get_array("y_ref") is None


WRITER = textwrap.dedent("""
    import sys, time
    from suspid.infra.ledger import Ledger, Evaluation, evaluation_key
    led = Ledger(sys.argv[1])
    computed = 0
    for i in range(int(sys.argv[2])):
        key = evaluation_key({"plugin": "t"}, {"x": float(i)}, "d")
        if led.get(key) is not None:
            continue                      # reused, not recomputed
        time.sleep(0.02)                  # the expensive part
        led.put(Evaluation(key, {"x": float(i)}, J=float(i) ** 0.5, psi=[float(i)]))
        computed += 1
        print(i, flush=True)
    print("computed", computed, flush=True)
""")


def test_sigkill_during_writes_loses_nothing_committed(tmp_path):
    path = tmp_path / "ledger.sqlite"
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    proc = subprocess.Popen([sys.executable, str(script), str(path), "200"], stdout=subprocess.PIPE, text=True)
    seen = []
    while len(seen) < 25:
        seen.append(int(proc.stdout.readline()))
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    led = Ledger(path)
    committed = {e.w["x"] for e in led.evaluations()}
    assert set(map(float, seen)) <= committed  # every evaluation reported as done survived
    n_before = len(committed)
    assert 25 <= n_before < 200
    for e in led.evaluations():
        assert e.J == e.w["x"] ** 0.5
    res = subprocess.run([sys.executable, str(script), str(path), "200"], capture_output=True, text=True,
                         timeout=120)
    assert res.stdout.strip().splitlines()[-1] == f"computed {200 - n_before}"  # the rest, no recomputation
    assert Ledger(path).count() == 200


def _hammer(args):
    path, start = args
    led = Ledger(path)
    for i in range(start, start + 40):
        led.put(Evaluation(f"k{i}", {"x": float(i)}, J=float(i), psi=[0.0], worker=str(os.getpid())))
        led.put_iteration("design", i, {"i": i})
    return os.getpid()


def test_concurrent_writers(tmp_path):
    path = str(tmp_path / "ledger.sqlite")
    Ledger(path).count()
    ctx = mp.get_context("spawn")
    with ctx.Pool(4) as pool:
        pids = pool.map(_hammer, [(path, 0), (path, 40), (path, 80), (path, 120)])
    led = Ledger(path)
    assert led.count() == 160 and len(led.iterations("design")) == 160
    assert len({e.worker for e in led.evaluations()}) == len(set(pids))


def test_a_ledger_written_by_the_previous_suspid_is_migrated_and_its_run_resumes_without_simulating(tmp_path):
    """tests/data/ledger_v1: a tiny run's ledger written by suspid before trials had ids (schema version 1,
    each (w, J) three times). Opening it migrates it to one trials row per trial; running the same config
    again simulates nothing and gives the result the old code wrote."""
    import json
    import shutil

    import yaml

    import suspid
    from suspid.infra.ledger import SCHEMA_VERSION, check_ledger_file, count_finished

    data = Path(__file__).parent / "data" / "ledger_v1"
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    shutil.copy(data / "ledger.sqlite", run_dir / "ledger.sqlite")
    config = yaml.safe_load((data / "config.yaml").read_text())
    config["output"] = {"dir": str(run_dir)}
    expected = json.loads((data / "expected.json").read_text())
    check_ledger_file(run_dir / "ledger.sqlite")   # validate's check accepts it and changes nothing
    assert count_finished(run_dir / "ledger.sqlite") == 8
    led = Ledger(run_dir / "ledger.sqlite")
    assert led.get_meta("schema_version") == str(SCHEMA_VERSION) == "2"
    runs = {run for run, _, _ in led.all_iterations()}
    assert "evaluations" not in runs and "design" not in runs and "trials" in runs
    trials = led.trials()
    assert [t["J"] for t in trials] == expected["anytime"]["J"] and all(t["key"] for t in trials)
    led.close()
    result = suspid.identify(config).to_dict()
    assert result["n_simulator_calls_this_session"] == 0
    for key in ("w_opt", "J_max", "n_simulator_calls", "anytime", "stop_reason"):
        assert result[key] == expected[key], key
    led = Ledger(run_dir / "ledger.sqlite")
    assert [t["J"] for t in led.trials()] == expected["anytime"]["J"]
    assert [t["phase"] for t in led.trials()][:5] == ["initial"] * 5
