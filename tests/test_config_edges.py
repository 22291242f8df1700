"""The config's edge cases, table-driven: each bad input is one exact line on stderr, exit code 2.

An empty or parameter-less config is refused; a mistake in ``--set`` or ``--param`` names the option,
not a line of the file it did not come from; an implausible speed in a config reads as the one the track
files give; a missing ``noise.path`` file has the file:line, key prefix of every other config error; the
config file is named by its absolute path however it was given.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import yaml

from suspid.cli import main
from suspid.data.files import read_track, write_track_csv
from suspid.errors import DataError
from suspid.interfaces import TrackSegment
from suspid.plugins.simulators.exudyn_train import ExudynTrain

CONFIG = {
    "name": "edges",
    "seed": 3,
    "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0}},
    "parameters": {"k_sec_z": {}, "c_sec_z": {}},
    "data": {"source": "experiment", "track": {"n_segments": 4, "length_m": 1000.0, "speed_kmh": 300.0}},
    "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 40},
    "design": {"n_initial": 6},
    "ego": {"max_iter": 2},
}

SPEED_3000 = ("speed 833.333 m/s (3000 km/h) is above any train's (160 m/s, the rail speed record being "
              "574.8 km/h): km/h instead of m/s? (if these values are right, add implausible_speed to data.accept)")
"""What a speed of 3000 km/h reads as, from a track file or from a config."""

KNOWN = ", ".join(sorted(p.name for p in ExudynTrain().parameters()))
TOP = ("data, design, diagnose, ego, executor, fleet, identifiability, limits, localisation, monitor, name, "
       "noise, objective, optimizer, output, parameters, seed, simulator, spectra, study, surrogate")


def _cli(capsys, *args: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_:
        main(list(args))
    out, err = capsys.readouterr()
    return exit_.value.code, out, err


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def _line(path: Path, key: str) -> int:
    """The 1-based line of the first ``key:`` in ``path``."""
    return next(i for i, line in enumerate(path.read_text().splitlines(), 1) if line.strip().startswith(key + ":"))


def _good(tmp_path: Path, **changes) -> Path:
    cfg = yaml.safe_load(yaml.safe_dump(CONFIG)) | changes
    return _write(tmp_path / "good.yaml", yaml.safe_dump(cfg, sort_keys=False))


# Each case: (id, a function of tmp_path giving (argv, expected stderr line)).
def _empty(tmp_path):
    f = _write(tmp_path / "empty.yaml", "")
    return ["validate", str(f)], (f"error: {f}: the config is empty (no sections); a config names at least the "
                                  f"parameters to identify under parameters: (`suspid parameters` lists a "
                                  f"simulator's)")


def _comments_only(tmp_path):
    f = _write(tmp_path / "comments.yaml", "# nothing but a comment\n\n")
    return ["run", str(f)], (f"error: {f}: the config is empty (no sections); a config names at least the "
                             f"parameters to identify under parameters: (`suspid parameters` lists a "
                             f"simulator's)")


def _no_parameters(tmp_path):
    cfg = {k: v for k, v in CONFIG.items() if k != "parameters"}
    f = _write(tmp_path / "nopar.yaml", yaml.safe_dump(cfg, sort_keys=False))
    return ["validate", str(f)], (f"error: {f}, key 'parameters': no parameters to identify; name them under "
                                  f"parameters: (bounds default to the simulator's; `suspid parameters {f}` lists "
                                  f"them)")


def _empty_parameters(tmp_path):
    cfg = CONFIG | {"parameters": {}}
    f = _write(tmp_path / "emptypar.yaml", yaml.safe_dump(cfg, sort_keys=False))
    return ["run", str(f)], (f"error: {f}:{_line(f, 'parameters')}, key 'parameters': no parameters to identify; "
                             f"name them under parameters: (bounds default to the simulator's; `suspid parameters "
                             f"{f}` lists them)")


def _param_unknown(tmp_path):
    f = _good(tmp_path)
    return ["simulate", str(f), "--param", "c_yawn=1"], (
        f"error: --param c_yawn=1: unknown parameter 'c_yawn' for simulator 'exudyn-train'; known: {KNOWN}")


def _param_not_a_number(tmp_path):
    f = _good(tmp_path)
    return ["simulate", str(f), "--param", "c_yaw=soft"], "error: --param c_yaw=soft: 'soft' is not a number"


def _param_no_value(tmp_path):
    f = _good(tmp_path)
    return ["simulate", str(f), "--param", "c_yaw"], "error: --param c_yaw: expected name=value"


def _set_not_an_integer(tmp_path):
    f = _good(tmp_path)
    return ["validate", str(f), "--set", "ego.max_iter=abc"], (
        "error: --set ego.max_iter=abc: Input should be a valid integer, unable to parse string as an integer "
        "(got 'abc')")


def _set_unknown_key(tmp_path):
    f = _good(tmp_path)
    return ["validate", str(f), "--set", "ego.max_itr=3"], (
        "error: --set ego.max_itr=3: unknown key; expected one of: asynchronous, batch, explore, explore_distance, "
        "explore_tol, max_iter, n_best, n_candidates, n_local, n_starts, refine, refit_final, search_maxiter, seed, "
        "tol")


def _set_unknown_section(tmp_path):
    f = _good(tmp_path)
    return ["run", str(f), "--set", "colour=red"], f"error: --set colour=red: unknown key; expected one of: {TOP}"


def _set_unknown_parameter(tmp_path):
    f = _good(tmp_path)
    return ["validate", str(f), "--set", "parameters.c_yawn={}"], (
        f"error: --set parameters.c_yawn={{}}: unknown parameter 'c_yawn' for simulator 'exudyn-train'; known: "
        f"{KNOWN} and element groups kind[tag,...] (see `suspid observability`)")


def _set_no_value(tmp_path):
    f = _good(tmp_path)
    return ["validate", str(f), "--set", "ego"], "error: --set ego: expected key.path=value"


def _speed_in_config(tmp_path):
    f = _good(tmp_path, data={"source": "experiment", "track": {"n_segments": 4, "length_m": 1000.0,
                                                                "speed_kmh": 3000.0}})
    return ["validate", str(f)], f"error: {f}:{_line(f, 'speed_kmh')}, key 'data.track.speed_kmh': {SPEED_3000}"


def _speed_in_set(tmp_path):
    f = _good(tmp_path)
    return ["run", str(f), "--set", "data.track.speed_kmh=3000"], (
        f"error: --set data.track.speed_kmh=3000: {SPEED_3000}")


def _speed_in_option(tmp_path):
    f = _good(tmp_path)
    return ["modes", str(f), "--speed-kmh", "3000"], f"error: --speed-kmh 3000: {SPEED_3000}"


def _noise_path_missing(tmp_path):
    cfg = CONFIG | {"noise": {"path": "nothere.npz"}}
    f = _write(tmp_path / "np.yaml", yaml.safe_dump(cfg, sort_keys=False))
    return ["validate", str(f)], (f"error: {f}:{_line(f, 'path')}, key 'noise.path': noise model file "
                                  f"{tmp_path / 'nothere.npz'} not found")


def _noise_path_missing_by_set(tmp_path):
    f = _good(tmp_path)
    return ["run", str(f), "--set", "noise.path=nothere.npz"], (
        f"error: --set noise.path=nothere.npz: noise model file {tmp_path / 'nothere.npz'} not found")


def _relative_config_path(tmp_path):
    cfg = CONFIG | {"ego": {"max_itr": 3}}
    f = _write(tmp_path / "rel.yaml", yaml.safe_dump(cfg, sort_keys=False))
    return ["validate", os.path.relpath(f)], (
        f"error: {f}:{_line(f, 'max_itr')}, key 'ego.max_itr': unknown key; expected one of: asynchronous, batch, "
        f"explore, explore_distance, explore_tol, max_iter, n_best, n_candidates, n_local, n_starts, refine, "
        f"refit_final, search_maxiter, seed, tol")


CASES = [_empty, _comments_only, _no_parameters, _empty_parameters, _param_unknown, _param_not_a_number,
         _param_no_value, _set_not_an_integer, _set_unknown_key, _set_unknown_section, _set_unknown_parameter,
         _set_no_value, _speed_in_config, _speed_in_set, _speed_in_option,
         _noise_path_missing, _noise_path_missing_by_set, _relative_config_path]


@pytest.mark.parametrize("case", CASES, ids=[c.__name__.strip("_") for c in CASES])
def test_each_edge_case_is_one_exact_line(tmp_path, capsys, case, monkeypatch):
    monkeypatch.chdir(tmp_path.parent)      # a relative path is relative to here
    argv, expected = case(tmp_path)
    code, out, err = _cli(capsys, *argv)
    assert (code, err.strip()) == (2, expected), err
    assert not (tmp_path / "runs").exists(), "the run directory was touched"


def test_a_track_file_at_3000_kmh_reads_as_the_config_does(tmp_path):
    """The reference of the speed cases: the message a track file gives, after its file and segment."""
    x = np.arange(0.0, 1000.0, 0.25)
    irr = 1e-3 * np.sin(2 * np.pi * x[None, :] / np.array([[7.0], [11.0], [13.0], [17.0]]))
    path = write_track_csv(TrackSegment("seg1", x, irr, 3000 / 3.6), tmp_path / "seg1.csv")
    with pytest.raises(DataError) as exc:
        read_track(path)
    assert str(exc.value) == f"{path}: segment 'seg1': {SPEED_3000}"


def test_the_good_config_is_valid(tmp_path, capsys):
    code, out, err = _cli(capsys, "validate", str(_good(tmp_path)))
    assert code == 0, err
