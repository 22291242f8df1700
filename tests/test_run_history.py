"""Run history: runs of one config name into one run directory keep their own results (suspid.infra.history)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import suspid
from suspid.infra.history import run_id_of
from suspid.infra.ledger import Ledger

CONFIG = {"name": "history", "seed": 2,
          "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0}},
          "parameters": {"k_sec_z": {}, "c_sec_z": {}},
          "data": {"track": {"n_segments": 6, "length_m": 1000.0}, "w_ref": {"k_sec_z": 380.0e3}},
          "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 40},
          "design": {"n_initial": 10}, "ego": {"max_iter": 3}, "identifiability": {"n_redraws": 6}}

OUTPUTS = ("result.json", "report.md", "config.yaml", "noise_model.npz", "figure1_spectra.png")


def _files(folder: Path) -> dict[str, bytes]:
    return {name: (folder / name).read_bytes() for name in OUTPUTS}


def _loop_rows(ledger: Path, run: str) -> list[float | None]:
    """J of the trials of one run in the ledger (``trials`` or ``history/<id>/trials``)."""
    led = Ledger(ledger)
    try:
        return [r["J"] for r in led.trials(run)]
    finally:
        led.close()


def test_two_seeds_into_one_folder_both_keep_their_results_and_each_resumes(tmp_path):
    """The same config with seed 2, then seed 3, into one run directory: each run's result.json, config.yaml,
    noise model and figures stay in history/<run id>/ byte for byte, the top holds the latest, the ledger
    keeps each run's records apart; running seed 2 again resumes it (no simulation) and makes it the latest."""
    run_dir = tmp_path / "run"
    a_cfg = {**CONFIG, "output": {"dir": str(run_dir)}}
    b_cfg = {**a_cfg, "seed": 3}
    a = suspid.identify(a_cfg)
    a_id, a_files = a.result["run_id"], _files(run_dir)
    assert a_id == run_id_of(suspid.load_config(a_cfg).model_dump(mode="json", exclude={"source_file"}))
    assert _files(run_dir / "history" / a_id) == a_files
    b = suspid.identify(b_cfg)
    b_id = b.result["run_id"]
    assert b_id != a_id and b.run_dir == run_dir
    assert _files(run_dir / "history" / a_id) == a_files          # the first run's results are all kept
    b_files = _files(run_dir / "history" / b_id)
    assert _files(run_dir) == b_files and b_files["result.json"] != a_files["result.json"]
    assert "seed: 3" in b_files["config.yaml"].decode() and "seed: 2" in a_files["config.yaml"].decode()
    assert json.loads((run_dir / "latest.json").read_text())["run_id"] == b_id
    assert json.loads(b_files["result.json"])["w_opt"] == b.w_opt != a.w_opt
    # the ledger: the latest run's records under their usual names, the other's apart, none mixed
    ledger = run_dir / "ledger.sqlite"
    assert _loop_rows(ledger, "trials") == b.result["anytime"]["J"]
    assert _loop_rows(ledger, f"history/{a_id}/trials") == a.result["anytime"]["J"]
    again = suspid.identify(a_cfg)
    assert again.result["n_simulator_calls_this_session"] == 0 and again.w_opt == a.w_opt
    assert again.result["run_id"] == a_id and json.loads((run_dir / "result.json").read_text())["w_opt"] == a.w_opt
    assert _files(run_dir / "history" / b_id) == b_files
    assert _loop_rows(ledger, "trials") == a.result["anytime"]["J"]
    assert _loop_rows(ledger, f"history/{b_id}/trials") == b.result["anytime"]["J"]
    # a run directory written before the history (its outputs at the top, no latest.json): kept on the next run
    legacy, a_files = tmp_path / "legacy", _files(run_dir / "history" / a_id)   # as the resume wrote them again
    legacy.mkdir()
    for name in [*OUTPUTS, "ledger.sqlite", "figure2_parameters.png", "convergence.png"]:
        shutil.copy2(run_dir / "history" / a_id / name if name != "ledger.sqlite" else run_dir / name, legacy / name)
    c = suspid.identify({**b_cfg, "output": {"dir": str(legacy)}})
    assert c.result["n_simulator_calls_this_session"] == 0   # seed 3's evaluations came with the ledger
    assert _files(legacy / "history" / a_id) == a_files and _files(legacy)["result.json"] != a_files["result.json"]
