"""`suspid study`: variants of one config, Table 1 / Figure 2 analogues."""

from __future__ import annotations

import csv

from conftest import run_cli

STUDY = """\
name: st
seed: 5
simulator: {plugin: exudyn-train, options: {solver: frequency}}
parameters: {k_sec_z: {}, c_sec_z: {}}
data:
  source: experiment
  track: {spectrum: german-low, n_segments: 6, length_m: 600.0, speed_kmh: 300.0}
  w_ref: {k_sec_z: 330.0e3, c_sec_z: 27.0e3}
spectra: {f_min_hz: 0.4, f_max_hz: 20.0, n_freqs: 80}
design: {n_initial: 6}
ego: {max_iter: 3}
study:
  variants:
    - {name: likelihood, set: {objective.plugin: likelihood}}
    - {name: overlap, set: {objective.plugin: overlap}}
    - {name: refined, set: {objective.plugin: overlap, ego.refine: {enabled: true, max_iter: 3}}}
"""


def test_study_runs_both_objectives_from_one_design(tmp_path):
    from suspid.infra.ledger import Ledger

    cfg = tmp_path / "study.yaml"
    cfg.write_text(STUDY)
    res = run_cli("study", str(cfg), "--quiet")
    assert res.returncode == 0, res.stderr
    out = tmp_path / "runs" / "st"
    rows = list(csv.DictReader(open(out / "study_runs.csv")))
    assert [r["run"] for r in rows] == ["likelihood", "overlap", "refined"]
    assert [r["variant"] for r in csv.DictReader(open(out / "study.csv"))] == ["likelihood", "overlap", "refined"]
    assert {r["objective"] for r in rows} == {"likelihood", "overlap"}
    for r in rows:
        assert float(r["error_k_sec_z"]) >= 0 and r["identifiable_c_sec_z"] in ("True", "False")
    text = (out / "study.md").read_text()
    assert "| likelihood |" in text and "| overlap |" in text and (out / "study_parameters.png").exists()
    # the refined variant is the overlap run continued: one row where the paper's loop stopped, one after
    overlap, refined = rows[1], rows[2]
    assert overlap["paper_loop_n_iterations"] == "" and refined["paper_loop_n_iterations"] == overlap["n_iterations"]
    assert refined["paper_loop_error_k_sec_z"] == overlap["error_k_sec_z"]
    assert int(refined["n_simulator_calls"]) == int(overlap["n_simulator_calls"]) + 3
    assert "| refined: paper's loop |" in text and "| refined: + refinement |" in text
    designs = [[t for t in Ledger(out / "variants" / v / "ledger.sqlite").trials() if t["phase"] == "initial"]
               for v in ("likelihood", "overlap")]
    assert [d["w"] for d in designs[0]] == [d["w"] for d in designs[1]]  # the same initial design


def test_config_without_study_section_is_a_one_line_error(tmp_path):
    cfg = tmp_path / "plain.yaml"
    cfg.write_text(STUDY.split("study:")[0])
    res = run_cli("study", str(cfg))
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "no 'study:' section" in res.stderr
