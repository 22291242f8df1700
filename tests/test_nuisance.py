"""The nuisance-parameter check: a w_opt that rests on an assumed model parameter is caught.

Known answer: both dates are simulated by suspid's own car with yaw dampers
whose series stiffness is 5 MN/m, while the model assumes the preset's 10 MN/m.
The measurement date has a 30 % weaker yaw damper. With the nuisance parameter
at its true value the model is the vehicle's, so the re-identification there
must land on the true c_yaw; the shift it reports is then the bias of the
nominal model.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from suspid import cli
from suspid.config import ConfigError, load_config
from suspid.data.files import write_accelerations_h5, write_track_h5
from suspid.data.track import synthetic_segments
from suspid.plugins.simulators.exudyn_train import ExudynTrain

VEHICLE = {"preset": "conventional-hs"}
OPTIONS = {"solver": "frequency", "fs_hz": 50.0, "vehicle": VEHICLE}
TRUE_K_YAW_S = 5.0e6


def _cli(*args: str) -> int:
    with pytest.raises(SystemExit) as exit_:
        cli.main(list(args))
    return exit_.value.code


def _write_date(folder: Path, w: dict[str, float], seed: int) -> None:
    segments = synthetic_segments({"n_segments": 8, "length_m": 600.0, "speed_kmh": 300.0, "seed": seed,
                                   "name_prefix": folder.name})
    responses = ExudynTrain(**OPTIONS).simulate(w | {"k_yaw_s": TRUE_K_YAW_S}, segments)
    folder.mkdir(parents=True)
    write_track_h5(segments, folder / "track.h5")
    write_accelerations_h5(responses, folder / "accelerations.h5")


@pytest.fixture(scope="module")
def dates(tmp_path_factory) -> tuple[Path, float]:
    out = tmp_path_factory.mktemp("nuisance")
    c_yaw0 = {p.name: p for p in ExudynTrain(**OPTIONS).parameters()}["c_yaw"].nominal
    _write_date(out / "reference", {}, seed=1)
    _write_date(out / "measurement", {"c_yaw": 0.7 * c_yaw0}, seed=2)
    return out, 0.7 * c_yaw0


def _config(out: Path, nuisance: dict, path: str = "config.yaml") -> Path:
    cfg = {"name": "nuisance", "seed": 5,
           "simulator": {"plugin": "exudyn-train", "options": OPTIONS},
           "parameters": {"c_yaw": {}},
           "data": {"source": "measured", "measurements": "measurement/accelerations.h5",
                    "track_file": "measurement/track.h5"},
           "noise": {"reference": {"measurements": "reference/accelerations.h5",
                                   "track_file": "reference/track.h5"}},
           "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 60},
           "design": {"n_initial": 6}, "ego": {"max_iter": 6},
           "identifiability": {"n_redraws": 6, "model_error": {
               "method": "full", "self_check": {"enabled": False}, "adequacy": {"enabled": False},
               "nuisance": {"parameters": nuisance, "max_evaluations": 16}}}}
    file = out / path
    file.write_text(yaml.safe_dump(cfg, sort_keys=False))
    return file


@pytest.mark.slow
def test_the_true_nuisance_value_recovers_the_truth_and_the_assumed_one_is_flagged(dates):
    """Without the calibration the full checks sweep the assumed range: an end at the true value recovers the
    truth, and the component is flagged (the shift there exceeds the threshold)."""
    out, c_yaw_true = dates
    cfg = _config(out, {"k_yaw_s": [TRUE_K_YAW_S, 20.0e6]})
    data = yaml.safe_load(cfg.read_text())
    data["identifiability"]["model_error"]["calibration"] = {"enabled": False}
    cfg.write_text(yaml.safe_dump(data, sort_keys=False))
    assert _cli("run", str(cfg), "--quiet") == 0
    result = json.loads((out / "runs" / "nuisance" / "result.json").read_text())
    lo, hi = result["bounds"]["c_yaw"]
    u_true = (c_yaw_true - lo) / (hi - lo)
    u_opt = result["w_opt_normalized"]["c_yaw"]
    rows = {row["value"]: row["c_yaw"] / 100 for row in result["model_error"]["nuisance"]["shifts_percent"]}
    assert set(rows) == {TRUE_K_YAW_S, 20.0e6}
    # with the series stiffness at its true value the re-identification lands on the truth ...
    assert abs(u_opt + rows[TRUE_K_YAW_S] - u_true) < 0.03, (u_opt, rows, u_true)
    # ... which the nominal model misses by more than the threshold: c_yaw is flagged, its interval widened (an
    # end of a uniform range is not within 2 standard deviations of its middle's shift: the interval is checked
    # with the calibration, below)
    assert abs(u_opt - u_true) > 0.05
    assert result["trustworthy"]["c_yaw"] is False
    assert "k_yaw_s" in result["untrustworthy_reasons"]["c_yaw"][0]
    lo_i, hi_i = result["interval_normalized"]["c_yaw"]
    slo, shi = (np.array(result["interval_sampling"]["c_yaw"]) - lo) / (hi - lo)
    assert hi_i - lo_i > shi - slo + 0.1
    assert "Model parameters: w_opt" in (out / "runs" / "nuisance" / "report.md").read_text()


@pytest.mark.slow
def test_the_full_checks_calibrate_the_mounts_and_correct_w_opt(dates):
    """The full checks on the known answer: the reference date calibrates the yaw dampers' mounts near their true
    5 MN/m, the re-identification with the calibrated model brings c_yaw to the truth, and the interval around the
    corrected value holds it (the linearised checks' test in tests/test_calibration.py, by simulation)."""
    out, c_yaw_true = dates
    cfg = _config(out, {"k_yaw_s": [2.0e6, 20.0e6]}, "calibrated.yaml")
    data = yaml.safe_load(cfg.read_text())
    data["name"] = "full-calibrated"
    cfg.write_text(yaml.safe_dump(data, sort_keys=False))
    assert _cli("run", str(cfg), "--quiet") == 0
    result = json.loads((out / "runs" / "full-calibrated" / "result.json").read_text())
    entry = result["calibration"]["parameters"]["k_yaw_s"]
    assert entry["status"] == "calibrated" and entry["interval"][0] <= TRUE_K_YAW_S <= entry["interval"][1], entry
    nu = result["model_error"]["nuisance"]
    assert nu["status"] == "done" and not nu["linearised"] and nu["parameters"]["k_yaw_s"]["calibrated"]
    lo, hi = result["bounds"]["c_yaw"]
    assert abs(result["w_opt"]["c_yaw"] - c_yaw_true) / (hi - lo) > 0.05      # the nominal model misses it
    assert abs(result["w_corrected"]["c_yaw"] - c_yaw_true) / (hi - lo) < 0.03, (result["w_corrected"], c_yaw_true)
    assert result["interval"]["c_yaw"][0] <= c_yaw_true <= result["interval"]["c_yaw"][1], result["interval"]
    assert result["model_error"]["budget"]["nuisance"] == nu["n_simulations"] > 0


@pytest.mark.parametrize("nuisance, expected", [
    ({"c_yaw": [1e5, 2e5]}, "'c_yaw' is identified"),
    ({"no_such": [1.0, 2.0]}, "unknown parameter 'no_such'"),
    ({"k_yaw_s": [2e7, 5e6]}, "expected low < high"),
])
def test_bad_nuisance_parameters_are_one_line_errors(dates, nuisance, expected):
    cfg = _config(dates[0], nuisance, "bad.yaml")
    with pytest.raises(ConfigError, match=expected) as err:
        load_config(cfg)
    assert "identifiability.model_error.nuisance.parameters" in str(err.value)
    assert np.char.count(str(err.value), "\n") == 0
