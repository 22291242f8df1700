"""Config validation: every mistake is one line naming file, key path and what was expected."""

from __future__ import annotations

from pathlib import Path

import pytest

from suspid.cli import main
from suspid.config import load_config
from suspid.options import ConfigPath, Section

GOOD = """\
name: qc
seed: 3
simulator:
  plugin: quarter-car
  options: {fs_hz: 80}
parameters:
  k_secondary: {lower: 0.25e6, upper: 0.7e6}
  c_secondary: {}
objective: {plugin: likelihood}
"""


def _validate(tmp_path: Path, capsys, text: str, *extra: str) -> tuple[int, str, str]:
    cfg = tmp_path / "run.yaml"
    cfg.write_text(text)
    with pytest.raises(SystemExit) as exit_:
        main(["validate", str(cfg), *extra])
    out, err = capsys.readouterr()
    return exit_.value.code, out, err


def test_good_config_validates(tmp_path, capsys, quarter_car):
    code, out, err = _validate(tmp_path, capsys, GOOD)
    assert code == 0, err
    assert "valid" in out
    cfg = load_config(tmp_path / "run.yaml")
    assert cfg.simulator.options == {"fs_hz": 80.0, "m_body_kg": 10_000.0, "m_wheel_kg": 2_000.0}
    assert cfg.parameters["k_secondary"].upper == 0.7e6
    assert cfg.run_dir() == tmp_path / "runs" / "qc"


def test_set_overrides_values(tmp_path, quarter_car):
    (tmp_path / "run.yaml").write_text(GOOD)
    cfg = load_config(tmp_path / "run.yaml", ["seed=11", "simulator.options.fs_hz=120", "output.dir=out"])
    assert cfg.seed == 11 and cfg.simulator.options["fs_hz"] == 120.0
    assert cfg.output.dir == tmp_path / "out"  # relative to the config file's folder


BAD = [
    # (what, yaml text, extra args, key path or None, expected words)
    ("yaml syntax", GOOD + "objective: {plugin: [\n", (), None, "YAML syntax error"),
    ("unknown key", GOOD + "simulater: {}\n", (), "simulater", "unknown key; expected one of"),
    ("wrong type", GOOD.replace("seed: 3", "seed: three"), (), "seed", "valid integer"),
    ("out of range", GOOD.replace("seed: 3", "seed: -4"), (), "seed", "greater than or equal to 0"),
    ("lower above upper", GOOD.replace("lower: 0.25e6, upper: 0.7e6", "lower: 0.7e6, upper: 0.25e6"), (),
     "parameters.k_secondary", "must be below upper bound"),
    ("missing data file", GOOD + "data: {source: measured, measurements: nowhere.h5}\n", (),
     "data.measurements", "file not found"),
    ("unknown plugin", GOOD.replace("plugin: quarter-car", "plugin: quarter-cart"), (), "simulator.plugin",
     "available simulators: exudyn-train, quarter-car, vampire"),
    ("unknown parameter", GOOD.replace("c_secondary: {}", "c_tertiary: {}"), (), "parameters.c_tertiary",
     "unknown parameter 'c_tertiary'"),
    ("bad --set path", GOOD, ("--set", "seed.value=3"), "seed.value", "is not a mapping"),
    ("bad --set syntax", GOOD, ("--set", "seed"), None, "expected key.path=value"),
    ("unknown plugin option", GOOD.replace("fs_hz: 80", "fs: 80"), (), "simulator.options.fs",
     "unknown key; expected one of: fs_hz, m_body_kg, m_wheel_kg"),
    ("plugin option type", GOOD.replace("fs_hz: 80", "fs_hz: fast"), (), "simulator.options.fs_hz",
     "valid number"),
    ("plugin option range", GOOD.replace("fs_hz: 80", "fs_hz: -80"), (), "simulator.options.fs_hz",
     "greater than 0"),
    ("not a mapping", "- a\n- b\n", (), None, "top level must be a mapping"),
    ("duplicate key", GOOD + "seed: 4\n", (), "seed", "duplicate key"),
    ("bad literal", GOOD + "data: {source: dreamt}\n", (), "data.source", "'experiment' or 'measured'"),
    ("w_ref outside", GOOD + "data: {w_ref: {k_secondary: 9.0e6}}\n", (), "data.w_ref.k_secondary",
     "outside the admissible interval"),
    ("unknown objective", GOOD.replace("plugin: likelihood", "plugin: chi2"), (), "objective.plugin",
     "available objectives: likelihood, mean-spectrum, overlap, wasserstein"),
    ("bad name", GOOD.replace("name: qc", "name: 'a b/c'"), (), "name", "match pattern"),
    # sections read by their own modules, checked before any simulation
    ("ego typo", GOOD + "ego: {max_iters: 3}\n", (), "ego.max_iters", "unknown key; expected one of: asynchronous, batch, explore"),
    ("refine range", GOOD, ("--set", "ego.refine.radius=2"), "ego.refine.radius", "less than or equal to 0.5 (got 2)"),
    ("bootstrap literal", GOOD + "identifiability: {bootstrap: pairs}\n", (), "identifiability.bootstrap",
     "'paired' or 'independent'"),
    ("design size", GOOD + "design: {n_initial: 1}\n", (), "design.n_initial", "greater than or equal to 2"),
    ("spectra band", GOOD + "spectra: {f_min_hz: -1}\n", (), "spectra.f_min_hz", "greater than 0"),
    ("track speed", GOOD + "data: {track: {speed_kmh: -5}}\n", (), "data.track.speed_kmh", "greater than 0"),
    ("noise floor literal", GOOD + "noise: {floor: loud}\n", (), "noise.floor", "'none', 'auto' or 'spec'"),
    ("noise floor spec", GOOD + "noise: {floor: spec}\n", (), "noise", "floor: spec needs sensor_noise_density"),
    ("noise density", GOOD + "noise: {floor: spec, sensor_noise_density: {roof: 1.0e-8}}\n", (),
     "noise.sensor_noise_density", "unknown: roof, missing: body_vertical, wheel_vertical"),
]


@pytest.mark.parametrize("what,text,extra,key,words", BAD, ids=[b[0] for b in BAD])
def test_malformed_config_is_one_line_exit_2(tmp_path, capsys, quarter_car, what, text, extra, key, words):
    code, out, err = _validate(tmp_path, capsys, text, *extra)
    lines = err.strip().splitlines()
    assert code == 2
    assert len(lines) == 1, err
    assert "Traceback" not in err
    if extra:   # a value given by --set is named by the option, not by a line of the file it is not in
        assert lines[0].startswith(f"error: {' '.join(extra)}: "), lines[0]
    else:
        assert str(tmp_path / "run.yaml") in lines[0]
        if key:
            assert f"key '{key}'" in lines[0]
    assert words in lines[0]


def test_yaml_error_and_key_errors_carry_line_numbers(tmp_path, capsys, quarter_car):
    _, _, err = _validate(tmp_path, capsys, GOOD.replace("seed: 3", "seed: -4"))
    assert "run.yaml:2," in err
    _, _, err = _validate(tmp_path, capsys, GOOD.replace("fs_hz: 80", "fs_hz: -80"))
    assert "run.yaml:5," in err


def test_missing_config_file(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["validate", str(tmp_path / "absent.yaml")])
    assert exit_.value.code == 2
    assert "absent.yaml: config file not found" in capsys.readouterr().err


def test_config_path_resolves_relative_to_config_folder(tmp_path):
    class Opts(Section):
        template_dir: ConfigPath

    opts = Opts.model_validate({"template_dir": "tpl"}, context={"base_dir": tmp_path})
    assert opts.template_dir == tmp_path / "tpl"


def test_debug_shows_traceback(tmp_path):
    from conftest import run_cli

    cfg = tmp_path / "x.yaml"
    cfg.write_text("seed: -1\n")
    res = run_cli("--debug", "validate", str(cfg))
    assert res.returncode != 0 and "Traceback" in res.stderr


@pytest.mark.parametrize("args, words", [
    (["no-such-command"], "No such command 'no-such-command'"),
    (["run", "--no-such-option", "x.yaml"], "No such option: --no-such-option"),
    (["run"], "Missing argument 'CONFIG'"),
])
def test_command_line_mistakes_are_usage_errors_with_exit_2(args, words):
    """A mistyped command, option or a missing argument: click's usage message and exit 2, never "internal error"."""
    from conftest import run_cli

    res = run_cli(*args)
    assert res.returncode == 2, (res.returncode, res.stderr)
    assert words in res.stderr and "internal error" not in res.stderr and "Traceback" not in res.stderr, res.stderr


def test_exponents_without_sign_or_dot_are_numbers(tmp_path):
    """YAML 1.1 reads 14.68e6 and 1e3 as strings; a config reads them as floats (YAML 1.2), a vehicle override
    written that way is accepted, and a word that only looks like one ('1e') stays a string."""
    from suspid.config import parse_yaml

    assert parse_yaml("a: 14.68e6\nb: 1e3\nc: -2.5E-3\nd: 1e\ne: 7") == {"a": 14.68e6, "b": 1000.0, "c": -2.5e-3,
                                                                       "d": "1e", "e": 7}
    cfg = tmp_path / "c.yaml"
    cfg.write_text("simulator: {plugin: exudyn-train, options: {vehicle: {preset: conventional-hs, k_prim_x: 14.68e6}}}\n"
                   "parameters: {k_sec_z: {lower: 2.3e5, upper: 5e5}}\n")
    config = load_config(cfg)
    assert config.parameters["k_sec_z"].lower == 2.3e5
    assert config.simulator.options["vehicle"]["k_prim_x"] == 14.68e6
