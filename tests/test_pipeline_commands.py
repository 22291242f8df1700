"""Commands for pipelines: ``suspid indicators --out`` writes files a script reads back, ``suspid parameters``
lists a simulator's parameters with unit, nominal value and bounds, and every command's help names its
options' values in words (``KEY=VALUE``, ``DIR``), not Python types (``<list[str]>``, ``<bool>``)."""

from __future__ import annotations

import csv
import json
import re

import pytest
import yaml

from suspid.cli import _command, main
from suspid.indicators.standard import instability_limit
from suspid.plugins.simulators.exudyn_train import ExudynTrain

from conftest import ROOT

INDICATORS = {"name": "ind", "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency"}},
              "parameters": {"c_sec_z": {}},
              "data": {"source": "experiment", "track": {"n_segments": 2, "length_m": 800.0}},
              "spectra": {"f_min_hz": 0.4, "f_max_hz": 20.0, "n_freqs": 60},
              "fleet": {"date": "2026-02-01", "hunting_hz": 5.0}}


def _cli(capsys, *args: str) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as exit_:
        main(list(args))
    out, err = capsys.readouterr()
    return exit_.value.code, out, err


def test_indicators_out_writes_json_and_csv_with_the_date_the_limit_inputs_and_the_comfort_levels(tmp_path, capsys):
    path = tmp_path / "ind.yaml"
    path.write_text(yaml.safe_dump(INDICATORS))
    code, out, err = _cli(capsys, "indicators", str(path), "--out", str(tmp_path / "out"))
    assert code == 0, err
    data = json.loads((tmp_path / "out" / "indicators.json").read_text())
    mass = next(p.nominal for p in ExudynTrain().parameters() if p.name == "m_bogie")
    assert data["date"] == "2026-02-01" and data["date_source"] == "fleet.date"
    assert data["bogie_mass_kg"] == mass and data["hunting_hz"] == 5.0
    rows = list(csv.DictReader((tmp_path / "out" / "indicators.csv").open()))
    assert len(rows) == len(data["indicators"]) == 6              # 2 segments and the run, 2 indicators each
    assert {r["date"] for r in rows} == {"2026-02-01"} and {r["segment"] for r in rows} == {"seg-001", "seg-002", "run"}
    for r in rows:
        if r["indicator"] == "en14363-instability":
            assert float(r["bogie_mass_kg"]) == mass and float(r["f0_hz"]) == 5.0 and r["hunting_hz_source"] == "given"
            assert float(r["alarm_level"]) == pytest.approx(instability_limit(mass))
            assert float(r["warning_level"]) == pytest.approx(0.8 * instability_limit(mass))
        else:
            assert r["indicator"] == "en12299-comfort"
            assert (float(r["warning_level"]), float(r["alarm_level"])) == (2.0, 4.0)   # N_MV's levels, not "-"
        assert r["verdict"] in ("ok", "warning", "alarm") and float(r["value"]) > 0
    assert "2 / 4" in out and f"m_b = {mass:g} kg" in out and "indicators.csv" in out


def test_parameters_lists_the_quickstart_parameters_with_units_nominal_and_bounds(capsys):
    config = ROOT / "configs" / "quickstart.yaml"
    code, out, err = _cli(capsys, "parameters", str(config))
    assert code == 0, err
    known = {p.name: p for p in ExudynTrain().parameters()}
    identified = yaml.safe_load(config.read_text())["parameters"]
    lines = {line.split()[0]: line for line in out.splitlines()[2:] if line.strip() and not line.startswith(" ")}
    assert set(known) <= set(lines)
    for name in identified:
        p, line = known[name], lines[name]
        assert f" {p.unit} " in line and f" {p.nominal:.6g} " in line, line
        assert f" {p.lower:.6g} to {p.upper:.6g} " in line and line.rstrip().endswith(f"{p.lower:.6g} to {p.upper:.6g}")
        assert "4 at bogie1/bogie2, left/right" in line or "8 at bogie1/bogie2" in line, line
    assert lines["m_car"].rstrip().endswith(" -")                  # not identified by the quickstart
    code, out, err = _cli(capsys, "parameters", str(config), "--identified", "--json")
    rows = json.loads(out)
    assert sorted(r["name"] for r in rows) == sorted(identified)
    for r in rows:
        p = known[r["name"]]
        assert (r["unit"], r["nominal"], r["lower"], r["upper"]) == (p.unit, p.nominal, p.lower, p.upper)
        assert r["identified"] == [p.lower, p.upper] and r["description"] == p.description and r["elements"]


def test_parameters_without_a_config_lists_a_simulator_and_refuses_an_unknown_one(capsys):
    code, out, err = _cli(capsys, "parameters", "--simulator", "exudyn-train", "--json")
    assert code == 0 and {r["name"] for r in json.loads(out)} == {p.name for p in ExudynTrain().parameters()}
    code, out, err = _cli(capsys, "parameters", "--simulator", "exudyn-trane")
    assert (code, err.strip()) == (2, "error: --simulator exudyn-trane: simulator 'exudyn-trane' is not available (the "
                                      "plugin may not be installed); available simulators: exudyn-train, vampire")


def _commands(cmd, path=()):
    yield path, cmd
    for name, sub in getattr(cmd, "commands", {}).items():
        yield from _commands(sub, (*path, name))


def test_every_help_names_values_in_words(capsys):
    seen = 0
    for path, _ in _commands(_command()):
        code, out, err = _cli(capsys, *path, "--help")
        assert code == 0, (path, err)
        assert not re.search(r"<(list|bool|path|int|float|str|text)\b", out, re.I), (path, out)
        seen += 1
    assert seen > 15
    code, out, err = _cli(capsys, "run", "--help")
    assert re.search(r"^\s+--set KEY=VALUE\s", out, re.M) and re.search(r"^\s+--fresh\s+Start over", out, re.M)
    assert out.startswith("Usage: suspid run [OPTIONS] CONFIG\n")
    code, out, err = _cli(capsys, "simulate", "--help")
    assert re.search(r"--param NAME=VALUE", out) and re.search(r"--out DIR", out)
