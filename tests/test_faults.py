"""Faults from outside: Ctrl-C on the real command, a full disk, inputs that are too big to parse.

Each ends with one line and the documented exit code, and nothing written before is lost.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from suspid.config import read_yaml
from suspid.errors import ConfigError

CONFIG = {"name": "faults", "seed": 2,
          "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0}},
          "parameters": {"k_sec_z": {}, "c_sec_z": {}},
          "data": {"track": {"n_segments": 6, "length_m": 1000.0}, "w_ref": {"k_sec_z": 380.0e3}},
          "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 40},
          "design": {"n_initial": 10}, "ego": {"max_iter": 3}, "identifiability": {"n_redraws": 6}}


def _write(tmp_path: Path, **changes) -> Path:
    cfg = json.loads(json.dumps(CONFIG)) | changes
    path = tmp_path / "faults.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return path


def _suspid(*args: str, preexec=None, timeout: float = 300) -> subprocess.CompletedProcess:
    env = dict(os.environ, SUSPID_DISABLE_PLUGIN_AUTOLOAD="1")
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True, env=env,
                          timeout=timeout, preexec_fn=preexec)


def _evaluations(ledger: Path) -> int:
    from conftest import count_evaluations

    return count_evaluations(ledger)


def test_ctrl_c_on_the_command_exits_130_keeps_the_ledger_and_resumes(tmp_path):
    """A real SIGINT to ``suspid run`` during the design: exit 130, the resume hint, no traceback."""
    # 60 segments: each simulation takes long enough that the signal lands in the design even on a loaded machine
    path = _write(tmp_path, design={"n_initial": 40}, ego={"max_iter": 2},
                  data={"track": {"n_segments": 60, "length_m": 1000.0}, "w_ref": {"k_sec_z": 380.0e3}})
    env = dict(os.environ, SUSPID_DISABLE_PLUGIN_AUTOLOAD="1")
    from conftest import interruptible

    proc = subprocess.Popen([sys.executable, "-m", "suspid", "run", str(path), "--quiet"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=interruptible)
    ledger = tmp_path / "runs" / "faults" / "ledger.sqlite"
    deadline = time.monotonic() + 240
    while _evaluations(ledger) < 3 and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.2)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, (out, err)
    assert "interrupted" in err and "run the same command to resume" in err and "Traceback" not in err, err
    kept = _evaluations(ledger)
    assert kept >= 3
    assert f"{kept} finished simulations are kept in {ledger}" in err, err   # the count the user can resume from
    again = _suspid("run", str(path), "--quiet")
    assert again.returncode == 0, again.stderr
    result = json.loads((tmp_path / "runs" / "faults" / "result.json").read_text())
    assert result["n_simulator_calls_this_session"] <= result["n_simulator_calls"] - kept


def _limit_file_size(limit: int):
    def preexec():
        import resource

        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a too-large write fails with EFBIG instead of a kill
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return preexec


def test_a_full_disk_leaves_the_previous_results_intact(tmp_path):
    """A finished run, then the same command with files limited to 4 KB (a full disk for anything larger):
    one line, exit 2, and result.json, report.md and the noise model are still the first run's, byte for byte."""
    path = _write(tmp_path)
    first = _suspid("run", str(path), "--quiet")
    assert first.returncode == 0, first.stderr
    run_dir = tmp_path / "runs" / "faults"
    kept = {name: (run_dir / name).read_bytes() for name in ("result.json", "report.md", "noise_model.npz",
                                                              "config.yaml")}
    again = _suspid("run", str(path), "--quiet", "--set", "ego.max_iter=4", preexec=_limit_file_size(4096))
    assert again.returncode == 2, (again.stdout, again.stderr)
    lines = again.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in again.stderr, again.stderr
    for name, content in kept.items():
        if name != "config.yaml":  # the new config is written first (small), the outputs never half-written
            assert (run_dir / name).read_bytes() == content, name
    assert not [p for p in run_dir.iterdir() if p.name.endswith(".tmp")]  # no temporary file left behind


@pytest.mark.parametrize("text, words", [
    ("a: &a [1, 2, 3, 4, 5, 6, 7, 8, 9]\n" + "".join(
        f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]\n" for i in range(8)),
     "expands to more than"),
    ("a: " + "[" * 20000 + "]" * 20000 + "\n", "nested deeper than"),
    ("a:\n" + "".join("  " * i + f"k{i}:\n" for i in range(1, 200)) + "  " * 200 + "x: 1\n", "nested deeper than"),
])
def test_hostile_yaml_is_refused_fast(tmp_path, text, words):
    path = tmp_path / "hostile.yaml"
    path.write_text(text)
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match=words):
        read_yaml(path)
    assert time.perf_counter() - t0 < 1.0


def test_a_byte_order_mark_is_accepted(tmp_path):
    path = tmp_path / "bom.yaml"
    path.write_bytes(b"\xef\xbb\xbf" + yaml.safe_dump(CONFIG).encode())
    data, _ = read_yaml(path)
    assert data["name"] == "faults"
