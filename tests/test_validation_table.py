"""One validation pass: every section and every plugin's options, the same mistake worded the same way.

For every config section (and every built-in plugin's ``options``) an unknown
key and a value of the wrong type go through ``suspid validate`` and
``suspid run``: each is exit code 2, one line on stderr naming the file, the
YAML line, the key path and what was expected, and ``run`` touches nothing:
no run directory, so no simulation.
"""

from __future__ import annotations

import copy
import re
from pathlib import Path

import pytest
import yaml

from suspid.cli import main

BASE = {
    "name": "table",
    "seed": 3,
    "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0}},
    "parameters": {"k_sec_z": {}, "c_sec_z": {}},
    "data": {"source": "experiment", "track": {"n_segments": 4, "length_m": 1000.0},
             "w_ref": {"k_sec_z": 400.0e3}, "reference": {"model_error_db": 1.0}, "measurement": {}},
    "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 40},
    "noise": {},
    "objective": {"plugin": "overlap", "options": {}},
    "surrogate": {"plugin": "gpy-kriging", "options": {}},
    "design": {"n_initial": 6},
    "ego": {"max_iter": 2, "refine": {"enabled": False}},
    "executor": {"plugin": "serial", "options": {}},
    "optimizer": {"plugin": "ego", "options": {}},
    "identifiability": {},
    "output": {},
    "diagnose": {},
}

STUDY = {"variants": [{"name": "a", "set": {}}]}
MONITOR = {"acceptable": {"c_sec_z": [1.0e4, None]},
           "scenario": {"parameter": "c_sec_z", "loss": 0.2, "dates": ["2026-01-01", "2026-02-01"]}}

# (section path, a field of it, a value of the wrong type, the plugin the section needs)
SECTIONS = [
    ((), "seed", "three", None),
    (("simulator",), "plugin", [1], None),
    (("simulator", "options"), "fs_hz", "fast", None),
    (("parameters", "k_sec_z"), "lower", "low", None),
    (("data",), "source", 3, None),
    (("data", "track"), "n_segments", "many", None),
    (("data", "reference"), "sensor_noise_rms", "loud", None),
    (("data", "measurement"), "simulator_options", 3, None),
    (("spectra",), "f_max_hz", "high", None),
    (("noise",), "path", [1], None),
    (("objective",), "weights", "equal", None),
    (("objective", "options"), "min_bandwidth_db", "wide", None),
    (("surrogate", "options"), "kernel", 3, None),
    (("design",), "n_initial", "many", None),
    (("ego",), "max_iter", "many", None),
    (("ego", "refine"), "enabled", "sometimes", None),
    (("optimizer",), "budget", "many", None),
    (("optimizer", "options"), "sigma0", "big", "cma-es"),
    (("optimizer", "options"), "simplex", "wide", "nelder-mead"),
    (("optimizer", "options"), "tol", "small", "ego"),
    (("executor", "options"), "workers", "many", "processes"),
    (("executor", "options"), "n_workers", "many", "dask"),
    (("identifiability",), "n_redraws", "many", None),
    (("output",), "figure_channel", [1], None),
    (("study",), "seeds", "all", None),
    (("monitor",), "acceptable", 3, None),
    (("monitor", "scenario"), "loss", "most", None),
    (("diagnose",), "alpha", "small", None),
]
PLUGIN_OPTIONS = [  # every built-in plugin's options: (section, plugin)
    ("objective", "likelihood"), ("objective", "overlap"), ("objective", "mean-spectrum"),
    ("objective", "wasserstein"), ("surrogate", "gpy-kriging"), ("surrogate", "sklearn-gp"),
    ("executor", "serial"), ("executor", "processes"), ("executor", "dask"), ("simulator", "exudyn-train"),
    ("optimizer", "ego"), ("optimizer", "random"), ("optimizer", "lhs-only"), ("optimizer", "nelder-mead"),
    ("optimizer", "cma-es"), ("optimizer", "skopt-gp"), ("optimizer", "gauss-newton"),
]

LINE = re.compile(r"^error: (?P<file>\S+\.yaml):(?P<line>\d+), key '(?P<key>[^']+)': (?P<what>.+)$")


def _config(section: tuple, key: str, value, plugin: str | None) -> dict:
    cfg = yaml.safe_load(yaml.safe_dump(BASE))
    cfg["study"], cfg["monitor"] = copy.deepcopy(STUDY), copy.deepcopy(MONITOR)
    if plugin is not None:
        cfg[section[0]]["plugin"] = plugin
    node = cfg
    for part in section:
        node = node.setdefault(part, {})
    node[key] = value
    return cfg


def _cases():
    for section, field, wrong, plugin in SECTIONS:
        path = ".".join(section)
        yield pytest.param(section, "colour", "red", plugin, "unknown", id=f"{path or 'top'}-unknown")
        yield pytest.param(section, field, wrong, plugin, "type", id=f"{path or 'top'}.{field}-type")
    for kind, plugin in PLUGIN_OPTIONS:
        yield pytest.param((kind, "options"), "colour", "red", plugin, "unknown", id=f"{plugin}-options-unknown")


def _cli(capsys, *args: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_:
        main(list(args))
    out, err = capsys.readouterr()
    return exit_.value.code, out, err


@pytest.mark.parametrize("section, key, value, plugin, kind", list(_cases()))
def test_every_section_reports_the_same_way_before_any_simulation(tmp_path, capsys, section, key, value,
                                                                   plugin, kind):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(_config(section, key, value, plugin), sort_keys=False))
    expected_key = ".".join([*section, key])
    for command in ("validate", "run"):
        code, out, err = _cli(capsys, command, str(path))
        assert code == 2, (command, out, err)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in err, err
        m = LINE.match(lines[0])
        assert m, lines[0]
        assert Path(m["file"]) == path and int(m["line"]) >= 1
        assert m["key"] == expected_key, lines[0]
        if kind == "unknown":
            assert re.match(r"unknown key; expected (one of: \w+|no keys here)", m["what"]), lines[0]
        else:
            assert re.search(r"(should be|Input should|valid|expected)", m["what"]), lines[0]
            assert "(got " in m["what"] or "Input should be a valid" in m["what"], lines[0]
        assert not (tmp_path / "runs").exists(), f"{command} touched the run directory"


def test_the_good_base_config_is_valid(tmp_path, capsys):
    cfg = yaml.safe_load(yaml.safe_dump(BASE))
    cfg["study"], cfg["monitor"] = copy.deepcopy(STUDY), copy.deepcopy(MONITOR)
    path = tmp_path / "good.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    code, out, err = _cli(capsys, "validate", str(path))
    assert code == 0, err
    assert "valid" in out


@pytest.mark.parametrize("mutate, key, words", [
    (lambda c: c["executor"].update(plugin="dsk"), "executor.plugin", "not available"),
    (lambda c: c["optimizer"].update(plugin="simplex"), "optimizer.plugin", "not available"),
    (lambda c: c["output"].update(figure_channel="roof"), "output.figure_channel", "unknown channel 'roof'"),
    (lambda c: c["objective"].update(weights=[1.0, 2.0]), "objective.weights", "weights"),
    (lambda c: c["diagnose"].update(effects=["bending"]), "diagnose.effects.0", "unknown effect 'bending'"),
    (lambda c: c["monitor"]["acceptable"].update(k_prim_z=[1.0, 2.0]), "monitor.acceptable.k_prim_z",
     "not an identified parameter"),
    (lambda c: c["study"]["variants"].append({"name": "b", "set": {"ego.max_itr": 3}}), "ego.max_itr",
     "unknown key"),
    (lambda c: c["data"]["measurement"].update(simulator_options={"fs_hz": -1}),
     "data.measurement.simulator_options.fs_hz", "greater than"),
    (lambda c: c["data"]["reference"].update(simulator_options={"colour": 1}),
     "data.reference.simulator_options.colour", "unknown key"),
])
def test_cross_section_checks_are_in_validate_too(tmp_path, capsys, mutate, key, words):
    """What run would reject from the config alone, validate rejects first (executor, channels, weights, ...)."""
    cfg = yaml.safe_load(yaml.safe_dump(BASE))
    cfg["study"], cfg["monitor"] = copy.deepcopy(STUDY), copy.deepcopy(MONITOR)
    mutate(cfg)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    for command in ("validate", "run"):
        code, out, err = _cli(capsys, command, str(path))
        assert code == 2, (command, out, err)
        assert len(err.strip().splitlines()) == 1 and f"key '{key}'" in err and words in err, err
        assert not (tmp_path / "runs").exists()


def _measured_files(tmp_path: Path, fs: float = 50.0, scale: float = 1.0) -> dict:
    """Four measured segments (random records of the simulator's channels at ``fs`` Hz, 0.3 ``scale`` m/s^2 rms,
    their track), in a folder of ``tmp_path`` named after ``fs``: enough for validate."""
    import numpy as np

    from suspid.data.files import write_accelerations_csv, write_track
    from suspid.data.track import synthetic_segments
    from suspid.interfaces import Response
    from suspid.registry import get

    tmp_path = tmp_path / f"fs{fs:g}"
    segs = synthetic_segments({"n_segments": 4, "length_m": 600.0, "dx_m": 0.25, "speed_kmh": 300.0, "seed": 4})
    write_track(segs, tmp_path / "track")
    channels = get("simulator", "exudyn-train")(solver="frequency", fs_hz=50.0).channels()
    rng = np.random.default_rng(0)
    for s in segs:
        a = 0.3 * scale * rng.standard_normal((len(channels), int(round(s.duration() * fs))))
        write_accelerations_csv(Response(tuple(channels), fs, a, s.name), tmp_path / "acc" / f"{s.name}.csv")
    return {"source": "measured", "measurements": str(tmp_path / "acc"), "track_file": str(tmp_path / "track")}


def _measured(cfg: dict, data: dict, **extra) -> None:
    cfg["data"] = dict(data) | extra
    cfg.pop("monitor", None)


def _refused_alike(capsys, path: Path) -> str:
    """``validate`` and ``run`` of ``path`` both exit 2 with the same one line, before any run directory; that line."""
    lines = {}
    for command in ("validate", "run"):
        code, out, err = _cli(capsys, command, str(path))
        lines[command] = err.strip().splitlines()
        assert code == 2 and len(lines[command]) == 1 and "Traceback" not in err, (command, out, err)
        assert not (path.parent / "runs").exists(), f"{command} touched the run directory"
    assert lines["validate"] == lines["run"]
    return lines["run"][0]


# what run refuses from the config and the data alone: (mutation of the base config, key, words)
RUN_REFUSES = {
    "measured_data_without_noise_model": (lambda c, d: _measured(c, d), "noise", "need the noise model"),
    "one_segment_for_the_noise_model": (lambda c, d: c["data"]["track"].update(n_segments=1),
                                        "data.track.n_segments", "at least 2 segments"),
    "w_ref_with_measured_data": (lambda c, d: (_measured(c, d, w_ref={"k_sec_z": 4.0e5}), c["noise"].update(
        reference={"measurements": d["measurements"], "track_file": d["track_file"]})),
                                 "data.w_ref", "w_ref belongs to numerical experiments"),
    "empty_study_seeds": (lambda c, d: c["study"].update(seeds=[]), "study.seeds", "at least 1 item"),
}


@pytest.mark.parametrize("name", sorted(RUN_REFUSES))
def test_validate_refuses_what_run_refuses_with_the_same_line(tmp_path, capsys, name):
    mutate, key, words = RUN_REFUSES[name]
    cfg = yaml.safe_load(yaml.safe_dump(BASE))
    cfg["study"], cfg["monitor"] = copy.deepcopy(STUDY), copy.deepcopy(MONITOR)
    mutate(cfg, _measured_files(tmp_path))
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    line = _refused_alike(capsys, path)
    assert f"key '{key}'" in line and words in line, line


def _with_reference(cfg: dict, data: dict, reference: dict) -> None:
    _measured(cfg, data)
    cfg["noise"]["reference"] = {"measurements": reference["measurements"], "track_file": reference["track_file"]}


# messages that named neither the file nor the key to change: (mutation, fragments of the one line)
NAMED = {
    "reference_date_sampled_below_the_grids_nyquist": (
        lambda c, tmp: _with_reference(c, _measured_files(tmp), _measured_files(tmp, fs=16.0)),
        ["fs16/acc/seg-001.csv: the reference date's record 'seg-001': the grid reaches",
         "above the Nyquist frequency fs/2 = 8 Hz"]),
    "segment_too_short_for_the_grid": (
        lambda c, tmp: (_with_reference(c, *[_measured_files(tmp)] * 2),
                        c["spectra"].update(f_min_hz=0.1, n_freqs=80, spacing="log")),
        ["fs50/acc/seg-001.csv: the measurement date's record 'seg-001' is too short for the frequency grid"]),
    "negative_seed_in_study_seeds": (lambda c, tmp: c["study"].update(seeds=[1, -2]),
                                     ["key 'study.seeds.1': Input should be greater than or equal to 0 (got -2)"]),
}


@pytest.mark.parametrize("name", sorted(NAMED))
def test_data_and_study_errors_name_their_file_or_key(tmp_path, capsys, name):
    mutate, fragments = NAMED[name]
    cfg = yaml.safe_load(yaml.safe_dump(BASE))
    cfg["study"], cfg["monitor"] = copy.deepcopy(STUDY), copy.deepcopy(MONITOR)
    mutate(cfg, tmp_path)
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    line = _refused_alike(capsys, path)
    assert all(f in line for f in fragments), line


def test_impossible_measured_data_are_refused_by_validate_and_run_unless_accepted(tmp_path, capsys):
    """Records in mm/s^2 read as m/s^2 ran to a result with a warning; now exit 2 and one line naming the file,
    the channel and the limit, in validate and run alike, until data.accept names the check."""
    cfg = yaml.safe_load(yaml.safe_dump(BASE))
    cfg["study"] = copy.deepcopy(STUDY)
    _with_reference(cfg, _measured_files(tmp_path, scale=1000.0), _measured_files(tmp_path, fs=40.0))
    path = tmp_path / "mm.yaml"
    path.write_text(yaml.safe_dump(cfg, sort_keys=False))
    line = _refused_alike(capsys, path)
    assert line.startswith(f"error: {tmp_path / 'fs50' / 'acc' / 'seg-001.csv'}: segment 'seg-001': channel "
                           "'carbody_front_vertical' vibrates with"), line
    assert "beyond a carbody of a train in service (at most 20 m/s^2)" in line, line
    assert "add implausible_amplitude to data.accept" in line, line
    code, out, err = _cli(capsys, "validate", str(path), "--set", "data.accept=[implausible_amplitude]")
    assert code == 0 and "valid" in out, err
    assert "accepted: implausible_amplitude in data.accept" in err
    code, out, err = _cli(capsys, "validate", str(path), "--set", "data.accept=[dead_chanel]")
    assert code == 2 and "--set data.accept=[dead_chanel], key 'data.accept.0': " in err and "implausible_amplitude" in err, err
