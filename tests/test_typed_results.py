"""Typed results: the run's J is one object, and the result files are the serialisation of typed results."""

from __future__ import annotations

import json

import pytest

import suspid
from suspid.errors import ConfigError, DataError
from suspid.method import objective as objective_module

from conftest import small_config


@pytest.fixture(scope="module")
def identified(tmp_path_factory):
    """One small identification, counting the ObjectiveFunctions built while it runs: ``(result, y_mes of
    each ObjectiveFunction built, run folder)``."""
    tmp_path = tmp_path_factory.mktemp("typed")
    built = []
    original = objective_module.ObjectiveFunction.__init__

    def counting(self, objective, y_mes, *args, **kwargs):
        built.append(y_mes)
        original(self, objective, y_mes, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(objective_module.ObjectiveFunction, "__init__", counting)
        r = suspid.identify(small_config(tmp_path))
    return r, built, tmp_path / "run"


def test_the_run_builds_its_objective_function_once(identified):
    """Every evaluation of J (design, EGO, the intervals' ±h points, the report) goes through the problem's
    one ObjectiveFunction; the bootstrap replicates of the intervals, J on resampled data, build one each."""
    r, built, _ = identified
    own = [y for y in built if y is r.problem.y_mes]
    assert len(own) == 1
    assert r.n_simulator_calls >= 6
    assert len(built) == 1 + r.interval_method.n_redraws


def test_result_json_is_the_serialisation_of_the_typed_result(identified):
    """result.json is IdentificationResult.to_json(), versioned; it reads back to an equal typed result."""
    from suspid.workflows.results import Analysis, IntervalMethod

    r, _, run = identified
    saved = json.loads((run / "result.json").read_text())
    assert saved["schema_version"] == suspid.IdentificationResult.SCHEMA_VERSION == 1
    assert r.to_json() == saved
    loaded = suspid.IdentificationResult.load(run)
    assert loaded == r                                  # every typed field, nested records included
    assert isinstance(loaded.interval_method, IntervalMethod) and isinstance(r, Analysis)
    assert loaded.interval_method.n_redraws == 6
    assert loaded.intervals["k_sec_z"] == tuple(saved["interval"]["k_sec_z"])
    assert json.dumps(loaded.to_json()) == json.dumps(saved)   # the same keys in the same order
    c = {c.name: c for c in r.components}
    assert c["k_sec_z"].w_ref == 380.0e3 and c["k_sec_z"].interval == r.interval["k_sec_z"]
    assert c["c_sec_z"].error_percent == r.errors_percent["c_sec_z"]


def test_old_and_newer_result_files_load(identified):
    """A result.json written before schema_version (and before the verdict) loads, its unknown keys kept;
    one of a newer schema is refused with the remedy."""
    r, _, run = identified
    old = {k: v for k, v in r.to_json().items() if k not in ("schema_version", "nominal", "verdict", "anytime")}
    old["a_key_of_another_version"] = {"x": 1}
    loaded = suspid.IdentificationResult.from_dict(old, run)
    assert loaded.w_opt == r.w_opt and loaded.verdict == [] and loaded.anytime is None
    assert loaded.extra == {"a_key_of_another_version": {"x": 1}}
    assert loaded.to_json()["a_key_of_another_version"] == {"x": 1}
    with pytest.raises(DataError, match="upgrade suspid"):
        suspid.IdentificationResult.from_dict({**r.to_json(), "schema_version": 99}, run)
    newer = run.parent / "newer"
    newer.mkdir(exist_ok=True)
    (newer / "result.json").write_text(json.dumps({**r.to_json(), "schema_version": 99}))
    with pytest.raises(DataError, match=f"^{newer / 'result.json'}: .*schema_version 99 is newer"):
        suspid.IdentificationResult.load(newer)
    (newer / "study.json").write_text(json.dumps({"a": {**r.to_json(), "schema_version": 99}}))
    with pytest.raises(DataError, match=f"^{newer / 'study.json'}: "):
        suspid.StudyResult.load(newer)


STUDY = """\
name: st
seed: 3
simulator: {plugin: exudyn-train, options: {solver: frequency}}
parameters: {k_sec_z: {}, c_sec_z: {}}
data: {track: {n_segments: 6, length_m: 800.0}}
study:
  variants:
    - {name: a, set: {objective.plugin: likelihood, data.track.length_m: 900.0}}
    - {name: b, set: {design: {n_initial: 7}}}
  seeds: [1, 2]
"""


def test_derived_configs_are_typed_copies_equal_to_the_string_overrides(tmp_path):
    """A study's variants are the config with typed keys set (Config.with_), validated again: the same
    configs, seeds derived anew, as reloading the file with ``--set`` strings gave."""
    from suspid.config import load_config, override_arguments
    from suspid.workflows.study import study_variants

    path = tmp_path / "st.yaml"
    path.write_text(STUDY)
    config = load_config(path, ["ego.max_iter=3"])
    runs = study_variants(path, ["ego.max_iter=3"], config)
    assert [r.label for r in runs] == ["a-seed1", "b-seed1", "a-seed2", "b-seed2"]
    for r, v in zip(runs, [*config.study.variants] * 2):
        extra = {"output.dir": str(config.run_dir() / "variants" / r.label), "name": f"st-{r.label}",
                 "seed": r.seed}
        reloaded = load_config(path, ["ego.max_iter=3", *override_arguments(v.set), *override_arguments(extra)])
        assert r.config.model_dump() == reloaded.model_dump()
        assert r.config.source_file == reloaded.source_file
    assert runs[0].config.design.seed != runs[2].config.design.seed       # derived from each run's own seed
    assert runs[0].config.objective.plugin == "likelihood" and runs[1].config.design.n_initial == 7
    assert config.with_(seed=1).ego.max_iter == 3 and config.seed == 3    # a copy: the original unchanged
    with pytest.raises(ConfigError, match="design.n_initial"):
        config.with_({"design.n_initial": -1})


def test_study_and_monitor_files_are_their_results_serialisation(identified, tmp_path):
    """study.json and monitor.json read back to equal typed results; monitor.json is versioned and keeps
    its layout (rows in date order, the summary's keys)."""
    import datetime as dt

    from suspid.sections import MonitorOptions
    from suspid.workflows.monitor import MonitorResult, MonitorRow, write_monitor
    from suspid.workflows.study import StudyResult

    r, _, _ = identified
    study = StudyResult(tmp_path, {"a": r})
    (tmp_path / "study.json").write_text(json.dumps(study.to_json()))
    again = StudyResult.load(tmp_path)
    assert again.variants["a"].to_json() == r.to_json() and again.variants["a"].run_dir == tmp_path / "variants" / "a"

    opts = MonitorOptions.model_validate({"acceptable": {"c_sec_z": [15.0e3, 25.0e3]},
                                          "scenario": {"parameter": "c_sec_z", "loss": 0.4, "n_dates": 2,
                                                       "start": dt.date(2026, 1, 15)}})
    dated = [(dt.date(2026, 1, 15), r.to_json()), (dt.date(2026, 2, 14), r.to_json())]
    summary = write_monitor(tmp_path, "mon", dated, opts, tmp_path / "ref.npz", {"2026-01-15": 0.0,
                                                                                 "2026-02-14": 0.4})
    saved = json.loads((tmp_path / "monitor.json").read_text())
    assert saved == summary and saved["schema_version"] == MonitorResult.SCHEMA_VERSION
    assert list(saved)[:9] == ["name", "dates", "parameters", "reference_noise_model", "acceptable", "alerts",
                               "first_warnings", "scenario", "rows"]
    m = MonitorResult.from_json(saved, monitor_dir=tmp_path)
    assert m.to_json() == saved and m.summary == saved
    assert m.date_labels == ["2026-01-15", "2026-02-14"] and m.scenario.losses["2026-02-14"] == 0.4
    assert isinstance(m.rows[0], MonitorRow) and m.rows[0].parameter == "k_sec_z"
    assert m.rows[1].status == saved["rows"][1]["status"] and m.alerts == saved["alerts"]
    old = {k: v for k, v in saved.items() if k != "schema_version"}
    assert MonitorResult.from_json(old).rows == m.rows


def test_diagnosis_json_is_the_diagnosis_result_serialisation(tmp_path):
    """diagnosis.json is DiagnosisResult.to_json() (canonical: sorted keys), versioned; it reads back equal."""
    from suspid.sections import DiagnoseOptions
    from suspid.workflows.diagnose.result import (DiagnosisResult, DiagnosisStatistics, NamedEffect, SequenceRow,
                                                  joint_fit_text)

    opts = DiagnoseOptions()
    gap = {"share_flagged": 0.25, "integrated_db_hz": 3.5, "w": {"k_sec_z": 4.0e5}}
    d = DiagnosisResult(
        name="bending", config=str(tmp_path / "bending.yaml"), base_model="nominal",
        flagged=[{"channel": "carbody_middle_vertical", "f_low_hz": 8.0, "f_high_hz": 11.0, "sign": 1,
                  "magnitude_db": 2.5, "test": "mean", "z": 6.1, "q": 1e-6, "speed_kmh": 300.0}],
        ranking=[{"effect": "carbody-bending", "score": 12.0, "parameters": {"frequency_hz": 9.5}}],
        generic_bumps={}, local_model=None, coupling=None, named="carbody-bending",
        named_effects=["carbody-bending"], reason="named", named_parameters={"frequency_hz": 9.5},
        effects=[NamedEffect(name="carbody-bending", parameters={"frequency_hz": 9.5, "damping": 0.02})],
        steps=[{"step": 1, "named": "carbody-bending"}],
        sequence=[SequenceRow(step=1, named="carbody-bending", share_flagged_before=0.25, share_flagged_after=0.0,
                              integrated_db_hz_after=0.1)],
        unexplained=[], channel_gains=[], suspension=None, joint_fit=joint_fit_text(opts), gap_before=gap,
        gap_after=None, augmented_config=None,
        statistics=DiagnosisStatistics(n_cells=40, bands_hz=[[0.4, 0.8]], min_db=opts.min_db,
                                       noise_mean_by_speed={}, n_bootstrap=100, kappa_median=1.1,
                                       kappa_raw_median=None, bootstrap_null_rate_at_5pct=0.04, alpha=opts.alpha,
                                       penalty_per_parameter=7.0, margin=opts.margin,
                                       min_explained=opts.min_explained, max_new_flagged=opts.max_new_flagged),
        map_before=[], map_after=None, wall_time_s=1.5, ranking_time_s=0.5, out_dir=tmp_path)
    data = d.to_json()
    assert list(data) == sorted(data) and data["schema_version"] == 1
    assert data["statistics"]["fdr"] == "Benjamini-Yekutieli" and data["effects"][0]["name"] == "carbody-bending"
    (tmp_path / "diagnosis.json").write_text(json.dumps(data))
    loaded = DiagnosisResult.load(tmp_path)
    assert loaded == d and loaded.diagnosis == data and loaded.named_effects == ["carbody-bending"]
    old = {k: v for k, v in data.items() if k != "schema_version"}
    assert DiagnosisResult.from_json(old, out_dir=tmp_path) == d
    assert joint_fit_text(opts.model_copy(update={"reidentify": False})).startswith("none")


def test_the_augmented_model_is_a_typed_copy_and_its_file_reproduces_it(tmp_path):
    """The diagnosis's augmented config is the config with the effects set (not augmented.yaml read back), and
    the augmented.yaml written for the user loads to the same config: the same synthetic track (its seed still
    derived from the run seed) and the base run's noise model."""
    from suspid.config import load_config
    from suspid.workflows.diagnose.reidentify import augmented_config
    from suspid.workflows.problem import segments_digest, synthetic_track

    path = tmp_path / "st.yaml"
    path.write_text(STUDY.split("study:")[0])
    config = load_config(path)
    noise = tmp_path / "noise_model.npz"
    noise.write_bytes(b"")
    effects = [("carbody-bending", {"frequency_hz": 9.5, "damping": 0.02})]
    aug = augmented_config(config, effects, tmp_path / "out", noise, path=tmp_path / "out" / "augmented.yaml")
    read = load_config(tmp_path / "out" / "augmented.yaml")
    assert aug.model_dump() == read.model_dump() and aug.source_file == read.source_file
    assert aug.simulator.options["effects"][-1]["frequency_hz"] == 9.5 and aug.noise.path == noise
    assert aug.name == "st-augmented" and aug.output.dir == tmp_path / "out" / "after"
    track = segments_digest(synthetic_track(config, "measurement"))
    assert segments_digest(synthetic_track(aug, "measurement")) == track
    assert segments_digest(synthetic_track(read, "measurement")) == track
