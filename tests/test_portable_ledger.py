"""A run's ledger keys come from its inputs, so a run folder resumes on any machine without simulating.

"Another machine" is made here in two ways: the ledger's simulated arrays multiplied by (1 + 1e-12) (what
another processor's BLAS kernels and solvers make of the same spectra: the same to every digit that matters,
other last bits), and the resume run in a process whose OpenBLAS is told to take another processor's kernels
(``OPENBLAS_CORETYPE=Prescott``, an SSE3 kernel every x86_64 processor runs: its sums come out in other last
bits than the kernel this processor would pick, so the noise model, the paths b_i and the optimiser's proposals
differ there as they do on another machine).
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

import suspid
from suspid.infra.ledger import Ledger

DATA = Path(__file__).parent / "data"

TINY = {"name": "portable", "seed": 3,
        "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency"}},
        "parameters": {"k_sec_z": {}, "c_sec_z": {}},
        "data": {"source": "experiment",
                 "track": {"spectrum": "german-low", "n_segments": 4, "length_m": 400.0, "speed_kmh": 300.0},
                 "w_ref": {"k_sec_z": 330.0e3, "c_sec_z": 27.0e3}},
        "objective": {"weights": "reference"},
        "spectra": {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 40},
        "design": {"n_initial": 5},
        "ego": {"max_iter": 3, "tol": 0.0, "explore_tol": 0.0},
        "identifiability": {"n_redraws": 4}}

COMPARED = ("w_opt", "J_max", "n_simulator_calls", "stop_reason", "anytime", "interval", "interval_method",
            "identifiable", "errors_percent")
"""What a resumed run must give again: the identification read from the ledger and the intervals, the sandwich
and the identifiability verdict recomputed from the ledger's arrays."""

LAST_BITS = 2.0 ** -49
"""A perturbation of a few units in the last place of a double (4 ulp)."""

_RESUME = """
import json, sys, yaml, suspid
config = yaml.safe_load(open(sys.argv[1]))
config["output"] = {"dir": sys.argv[2]}
print(json.dumps(suspid.identify(config).to_dict()))
"""


def _close(a, b, rtol: float, path: str = "") -> list[str]:
    """Where two JSON values differ beyond ``rtol`` (floats) or at all (anything else)."""
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            return [f"{path}: keys {sorted(set(a) ^ set(b))}"]
        return [d for k in a for d in _close(a[k], b[k], rtol, f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: length {len(a)} != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _close(x, y, rtol, f"{path}[{i}]")]
    if isinstance(a, float) or isinstance(b, float):
        ok = a is not None and b is not None and np.isclose(a, b, rtol=rtol, atol=rtol)
        return [] if ok else [f"{path}: {a} != {b}"]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def _other_processor() -> dict[str, str]:
    if platform.machine() not in ("x86_64", "AMD64"):
        pytest.skip("OPENBLAS_CORETYPE=Prescott names an x86_64 kernel")
    return {**os.environ, "OPENBLAS_CORETYPE": "Prescott"}


def _resume_elsewhere(config: dict, run_dir: Path, tmp_path: Path) -> dict:
    """Resume ``config`` in ``run_dir`` in a process that takes another processor's BLAS kernels."""
    path = tmp_path / "resume.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    out = subprocess.run([sys.executable, "-c", _RESUME, str(path), str(run_dir)], capture_output=True, text=True,
                         env=_other_processor(), timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def _perturb(ledger_path: Path, factor: float) -> int:
    """Every floating-point array of the ledger (the simulated spectra of both dates and of every point)
    multiplied by ``factor``; returns how many."""
    led = Ledger(ledger_path)
    n = 0
    for (key,) in led._read("SELECT key FROM artifacts"):
        a = led.get_array(key)
        if a is not None and a.dtype.kind == "f" and not key.endswith(":freqs"):
            led.put_array(key, a * factor)
            n += 1
    led.close()
    return n


def _only(result: dict, keys) -> dict:
    return {k: result[k] for k in keys}


@pytest.fixture(scope="module")
def finished(tmp_path_factory) -> tuple[Path, dict]:
    run_dir = tmp_path_factory.mktemp("portable") / "run"
    result = suspid.identify({**TINY, "output": {"dir": str(run_dir)}}).to_dict()
    assert result["n_simulator_calls_this_session"] == result["n_simulator_calls"] > 0
    return run_dir, result


def test_a_run_folder_copied_elsewhere_with_its_arrays_perturbed_in_their_last_bits_resumes_without_simulating(
        finished, tmp_path):
    run_dir, before = finished
    moved = tmp_path / "elsewhere" / "run"
    shutil.copytree(run_dir, moved)
    assert _perturb(moved / "ledger.sqlite", 1.0 + LAST_BITS) >= 4   # both dates' spectra, the points' y_sim
    after = suspid.identify({**TINY, "output": {"dir": str(moved)}}).to_dict()
    assert after["n_simulator_calls_this_session"] == 0
    assert _close(_only(after, COMPARED), _only(before, COMPARED), 1e-9) == []


def test_arrays_off_by_one_part_in_1e12_resume_without_simulating_and_identify_the_same(finished, tmp_path):
    """y × (1 + 1e-12), about what two processors make of the same spectra (2e-9 dB on spectra of about -60 dB):
    nothing is simulated, and the identification and the intervals (second differences of J over the bootstrap
    of B) are the same to 1e-9."""
    run_dir, before = finished
    moved = tmp_path / "run"
    shutil.copytree(run_dir, moved)
    _perturb(moved / "ledger.sqlite", 1.0 + 1e-12)
    after = suspid.identify({**TINY, "output": {"dir": str(moved)}}).to_dict()
    assert after["n_simulator_calls_this_session"] == 0
    assert _close(_only(after, COMPARED), _only(before, COMPARED), 1e-9) == []


def test_the_same_folder_resumed_with_another_processors_kernels_simulates_nothing(finished, tmp_path):
    run_dir, before = finished
    moved = tmp_path / "run"
    shutil.copytree(run_dir, moved)
    after = _resume_elsewhere(TINY, moved, tmp_path)
    assert after["n_simulator_calls_this_session"] == 0
    assert _close(_only(after, COMPARED), _only(before, COMPARED), 1e-9) == []
    again = suspid.identify({**TINY, "output": {"dir": str(moved)}}).to_dict()   # back on this machine's kernels
    assert again["n_simulator_calls_this_session"] == 0
    assert _close(_only(again, COMPARED), _only(before, COMPARED), 1e-9) == []


def test_other_measured_data_are_not_taken_for_the_recorded_ones(finished, tmp_path):
    """The keys follow the inputs: another seed (other track, other noise) in the same folder simulates again,
    even though its initial design is the same; nothing of the first run is replayed into it."""
    run_dir, before = finished
    moved = tmp_path / "run"
    shutil.copytree(run_dir, moved)
    other = suspid.identify({**TINY, "data": {**TINY["data"], "track": {**TINY["data"]["track"], "seed": 99}},
                             "output": {"dir": str(moved)}}).to_dict()
    assert other["n_simulator_calls_this_session"] == other["n_simulator_calls"]
    assert other["J_max"] != before["J_max"]


@pytest.mark.parametrize("name", ["ledger_v1", "ledger_v2"])
def test_ledgers_written_before_input_identities_resume_without_simulating_on_another_processor(name, tmp_path):
    """tests/data/ledger_v1 (schema 1, before trials had ids) and ledger_v2 (written by suspid bb35277, the last
    release keyed by array digests, on another machine): resumed with another processor's kernels, the run
    reads every evaluation from the ledger and gives the result it wrote."""
    data = DATA / name
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    shutil.copy(data / "ledger.sqlite", run_dir / "ledger.sqlite")
    config = yaml.safe_load((data / "config.yaml").read_text())
    expected = json.loads((data / "expected.json").read_text())
    result = _resume_elsewhere(config, run_dir, tmp_path)
    assert result["n_simulator_calls_this_session"] == 0
    assert _close({k: result[k] for k in ("w_opt", "J_max", "n_simulator_calls", "stop_reason")},
                  {k: expected[k] for k in ("w_opt", "J_max", "n_simulator_calls", "stop_reason")}, 1e-9) == []
    assert result["anytime"]["J"] == expected["anytime"]["J"]   # read from the ledger: the recorded values
    led = Ledger(run_dir / "ledger.sqlite")
    assert all(r.get("identity") for r in led.iterations("trials"))   # the trials now carry the new keys
    led.close()
