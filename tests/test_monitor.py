"""Maintenance monitoring across dates: config, status rules, the degradation scenario, the CLI."""

from __future__ import annotations

import csv
import datetime as dt
import json
from pathlib import Path

import numpy as np
import pytest

import suspid

from conftest import run_cli

BASE = """\
name: mon
seed: 5
simulator: {plugin: exudyn-train, options: {solver: frequency}}
parameters:
  k_sec_z: {}
  c_sec_z: {}
data:
  source: experiment
  track: {spectrum: german-low, n_segments: 24, length_m: 800.0, speed_kmh: 300.0}
  measurement: {errors: noise-model}   # eq. 10: the monitoring logic is tested, not the measurement process
spectra: {f_min_hz: 0.4, f_max_hz: 20.0, n_freqs: 100}
design: {n_initial: 8}
ego: {max_iter: 10}
"""

ACCEPTABLE = """\
  acceptable:                       # [0.75, 1.25] x nominal
    c_sec_z: [15.0e3, 25.0e3]
    k_sec_z: [262.5e3, 437.5e3]
"""

SCENARIO = "monitor:\n" + ACCEPTABLE + """\
  scenario: {parameter: c_sec_z, loss: 0.4, n_dates: 6, start: 2026-01-15, interval_days: 30}
"""

CAMPAIGNS = "monitor:\n" + ACCEPTABLE + """\
  reference: {noise_model: ref.npz}
  campaigns:
    - {date: 2026-01-15, data: {source: measured, measurements: m1, track_file: t1}}
    - {date: 2026-03-01, data: {source: measured, measurements: m2, track_file: t2}}
"""


def _write(tmp_path: Path, monitor: str, base: str = BASE, name: str = "mon.yaml") -> Path:
    path = tmp_path / name
    path.write_text(base + monitor)
    return path


def _plan(path: Path, overrides: list[str] = (), noise_model: Path = Path("/nm.npz")):
    from suspid.config import load_config
    from suspid.workflows.monitor import monitor_dates, monitor_options

    config = load_config(path, list(overrides))
    opts = monitor_options(config)
    return config, opts, monitor_dates(path, list(overrides), config, opts, noise_model)


# -- status rules -------------------------------------------------------------------------------
@pytest.mark.parametrize("interval, domain, identifiable, expected", [
    ((16e3, 18e3), (15e3, 25e3), True, "ok"),
    ((15e3, 25e3), (15e3, 25e3), True, "ok"),                 # edges belong to the domain
    ((14e3, 16e3), (15e3, 25e3), True, "warning"),            # overlaps the lower edge
    ((24e3, 26e3), (15e3, 25e3), True, "warning"),
    ((10e3, 30e3), (15e3, 25e3), True, "warning"),            # wider than the domain
    ((12e3, 14.9e3), (15e3, 25e3), True, "out-of-domain"),
    ((26e3, 27e3), (15e3, 25e3), True, "out-of-domain"),
    ((26e3, 27e3), (None, 25e3), True, "out-of-domain"),      # open lower side
    ((1e3, 2e3), (None, 25e3), True, "ok"),
    ((12e3, 14e3), (15e3, 25e3), False, "not-identifiable"),  # never flagged from a value it does not have
    ((12e3, 14e3), None, True, "unmonitored"),
])
def test_status_of(interval, domain, identifiable, expected):
    from suspid.workflows.monitor import status_of

    assert status_of(interval, domain, identifiable) == expected


def _result(values: dict, intervals: dict, identifiable: dict, w_ref: dict | None = None) -> dict:
    r = {"parameters": list(values), "units": {n: "u" for n in values}, "w_opt": values,
         "interval": intervals, "identifiable": identifiable}
    if w_ref is not None:
        r["w_ref"] = w_ref
    return r


def test_alerts_first_out_of_domain_date_and_not_identifiable_never_flagged(tmp_path):
    from suspid.workflows.monitor import MonitorOptions, write_monitor

    opts = MonitorOptions.model_validate({"acceptable": {"a": [1.0, 2.0], "b": [1.0, 2.0]},
                                          "scenario": {"parameter": "a", "n_dates": 4, "start": "2026-01-01"}})
    days = [dt.date(2026, 1, 1) + dt.timedelta(days=30 * i) for i in range(4)]
    # a: ok, warning, out, out -> alert on the third date; b: out of domain but not identifiable, then ok
    results = [
        _result({"a": 1.5, "b": 0.2}, {"a": [1.4, 1.6], "b": [0.1, 0.3]}, {"a": True, "b": False}, {"a": 1.5, "b": 1.5}),
        _result({"a": 1.05, "b": 0.2}, {"a": [0.9, 1.2], "b": [0.1, 0.3]}, {"a": True, "b": False}, {"a": 1.1, "b": 1.5}),
        _result({"a": 0.8, "b": 1.5}, {"a": [0.7, 0.9], "b": [1.4, 1.6]}, {"a": True, "b": True}, {"a": 0.8, "b": 1.5}),
        _result({"a": 0.6, "b": 1.5}, {"a": [0.5, 0.7], "b": [1.4, 1.6]}, {"a": False, "b": True}, {"a": 0.6, "b": 1.5}),
    ]
    summary = write_monitor(tmp_path, "t", list(zip(days, results)), opts, Path("ref.npz"))
    assert summary["alerts"] == {"a": "2026-03-02"}
    assert summary["first_warnings"] == {"a": "2026-01-31"}
    with open(tmp_path / "monitor.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["date"], r["parameter"], r["status"]) for r in rows if r["parameter"] == "b"] == [
        ("2026-01-01", "b", "not-identifiable"), ("2026-01-31", "b", "not-identifiable"),
        ("2026-03-02", "b", "ok"), ("2026-04-01", "b", "ok")]
    assert {"date", "parameter", "value", "interval_low", "interval_high", "identifiable", "status"} <= set(rows[0])
    md = (tmp_path / "monitor.md").read_text()
    assert "`a` out of its acceptable domain" in md and "2026-03-02" in md and "`b` out" not in md
    assert (tmp_path / "monitor_a.png").stat().st_size > 0 and (tmp_path / "monitor_b.png").exists()
    assert json.loads((tmp_path / "monitor.json").read_text())["alerts"] == {"a": "2026-03-02"}


# -- the plan: one config per date --------------------------------------------------------------
def test_scenario_plan_degrades_one_parameter_with_own_tracks_and_the_reference_noise(tmp_path):
    from suspid.config import build_simulator

    config, _, plans = _plan(_write(tmp_path, SCENARIO), noise_model=tmp_path / "ref.npz")
    nominal = {p.name: p.nominal for p in build_simulator(config).parameters()}
    assert [p.date.isoformat() for p in plans] == ["2026-01-15", "2026-02-14", "2026-03-16", "2026-04-15",
                                                   "2026-05-15", "2026-06-14"]
    assert [p.loss for p in plans] == pytest.approx([0.0, 0.08, 0.16, 0.24, 0.32, 0.40])
    for p in plans:
        cfg = p.config
        assert cfg.data.w_ref == pytest.approx({"k_sec_z": nominal["k_sec_z"],
                                                "c_sec_z": nominal["c_sec_z"] * (1 - p.loss)})
        assert cfg.noise.path == tmp_path / "ref.npz"  # never identified again at a date
        assert cfg.output.dir == tmp_path / "runs" / "mon" / "dates" / p.date.isoformat()
        assert cfg.monitor is None and cfg.design == config.design
    seeds = {p.config.data.track.seed for p in plans}
    assert len(seeds) == len(plans)  # every date its own track realisations
    _, _, again = _plan(_write(tmp_path, SCENARIO), noise_model=tmp_path / "ref.npz")
    assert [p.config.data.track.seed for p in again] == [p.config.data.track.seed for p in plans]


def test_scenario_explicit_dates_lose_linearly_in_time(tmp_path):
    monitor = "monitor:\n" + ACCEPTABLE + "  scenario: {parameter: c_sec_z, loss: 0.3, dates: [2026-01-01, 2026-01-11, 2026-01-31]}\n"
    _, _, plans = _plan(_write(tmp_path, monitor))
    assert [p.loss for p in plans] == pytest.approx([0.0, 0.1, 0.3])


def test_campaigns_plan_merges_data_overrides_and_resolves_paths(tmp_path):
    for d in ("m1", "m2", "t1", "t2"):
        (tmp_path / d).mkdir()
    (tmp_path / "ref.npz").write_bytes(b"")
    _, opts, plans = _plan(_write(tmp_path, CAMPAIGNS), noise_model=tmp_path / "ref.npz")
    assert opts.reference.noise_model == tmp_path / "ref.npz"
    assert [p.date for p in plans] == [dt.date(2026, 1, 15), dt.date(2026, 3, 1)]
    for p, i in zip(plans, (1, 2)):
        data = p.config.data
        assert data.source == "measured"
        assert data.measurements == tmp_path / f"m{i}" and data.track_file == tmp_path / f"t{i}"
        assert data.track.n_segments == 24 and "seed" not in data.track.model_fields_set  # merged key by key


ERRORS = [
    ("monitor:\n" + ACCEPTABLE + "  campaigns: [{date: 2026-01-15}, {date: 15/01/2026}]\n",
     "monitor.campaigns.1.date", "date"),
    ("monitor:\n" + ACCEPTABLE + "  campaigns: [{date: 2026-02-15}, {date: 2026-01-15}]\n",
     "monitor.campaigns.1.date", "dates must increase"),
    ("monitor:\n  acceptable: {k_prim_z: [1, 2]}\n  scenario: {parameter: c_sec_z, n_dates: 3, start: 2026-01-01}\n",
     "monitor.acceptable.k_prim_z", "not an identified parameter"),
    ("monitor:\n  acceptable: {c_sec_z: [25.0e3, 15.0e3]}\n  scenario: {parameter: c_sec_z, n_dates: 3, start: 2026-01-01}\n",
     "monitor.acceptable.c_sec_z", "must be below"),
    ("monitor:\n  acceptable: {c_sec_z: [1.0]}\n  scenario: {parameter: c_sec_z, n_dates: 3, start: 2026-01-01}\n",
     "monitor.acceptable.c_sec_z", ""),
    (SCENARIO + "  campaigns: [{date: 2026-01-15}]\n", "monitor", "either 'campaigns'"),
    ("monitor:\n  scenario: {parameter: k_prim_z, n_dates: 3, start: 2026-01-01}\n",
     "monitor.scenario.parameter", "not an identified parameter"),
    ("monitor:\n  scenario: {parameter: c_sec_z, loss: 0.7, n_dates: 3, start: 2026-01-01}\n",
     "monitor.scenario.loss", "outside its identification bounds"),
    ("monitor:\n  scenario: {parameter: c_sec_z, n_dates: 3}\n", "monitor.scenario.start", "needs a 'start'"),
    ("monitor:\n  scenario: {parameter: c_sec_z, n_dates: 3, start: 2026-01-01, every: 3}\n",
     "monitor.scenario.every", "unknown key"),
    ("monitor:\n  reference: {noise_model: nowhere.npz}\n  scenario: {parameter: c_sec_z, n_dates: 3, start: 2026-01-01}\n",
     "monitor.reference.noise_model", "file not found"),
    (CAMPAIGNS.replace("  reference: {noise_model: ref.npz}\n", ""), "monitor.reference.noise_model",
     "measured data need the noise model"),
    (CAMPAIGNS.replace("measurements: m2", "measurements: nowhere"), "monitor.campaigns.1.data.measurements",
     "file not found"),
    (CAMPAIGNS.replace("track_file: t2}", "track_file: t2, speed: 3}"), "monitor.campaigns.1.data.speed",
     "unknown key"),
]


@pytest.mark.parametrize("monitor, key, message", ERRORS, ids=[e[1] + ":" + e[2][:20] for e in ERRORS])
def test_config_errors_name_the_key(tmp_path, monitor, key, message):
    from suspid.errors import ConfigError

    for d in ("m1", "m2", "t1", "t2"):
        (tmp_path / d).mkdir()
    (tmp_path / "ref.npz").write_bytes(b"")
    path = _write(tmp_path, monitor)
    with pytest.raises(ConfigError) as info:
        _plan(path)
    assert info.value.key.startswith(key), str(info.value)
    assert message in info.value.detail and info.value.file == str(path)


def test_cli_one_line_error(tmp_path):
    res = run_cli("monitor", str(_write(tmp_path, "")))
    assert res.returncode == 2
    assert res.stderr.strip().count("\n") == 0 and "'monitor'" in res.stderr and "no 'monitor:' section" in res.stderr


# -- the degradation scenario, end to end ---------------------------------------------------------
def test_scenario_flags_the_degrading_parameter_at_the_right_date_and_nothing_else(tmp_path):
    """c_sec_z loses 0, 8, 16, 24, 32, 40 %; its acceptable domain starts at -25 %: the first date with the
    true value outside is the fifth (32 %). The alert must come within one date of it; k_sec_z stays nominal."""
    from suspid.method.noise import NoiseModel
    from suspid.infra.threads import single_blas_thread

    path = _write(tmp_path, SCENARIO)
    with single_blas_thread():  # the Kriging fits of tiny matrices: 2x faster on a busy 2-core machine
        result = suspid.monitor(path)
    out = result.monitor_dir
    summary = json.loads((out / "monitor.json").read_text())
    assert summary == result.summary and result.alerts == summary["alerts"]
    expected = 4  # index of 2026-05-15
    assert set(summary["alerts"]) == {"c_sec_z"}, summary["alerts"]
    assert abs(summary["dates"].index(summary["alerts"]["c_sec_z"]) - expected) <= 1, summary["rows"]
    assert all(r["status"] in ("ok", "warning") for r in summary["rows"] if r["parameter"] == "k_sec_z")
    c_status = [r["status"] for r in summary["rows"] if r["parameter"] == "c_sec_z"]
    assert c_status[0] == "ok", summary["rows"]
    # outputs: table, report with the alert, one plot per parameter
    with open(out / "monitor.csv") as fh:
        assert len(list(csv.DictReader(fh))) == 12
    assert "**`c_sec_z` out of its acceptable domain" in (out / "monitor.md").read_text()
    assert (out / "monitor_c_sec_z.png").stat().st_size > 10_000 and (out / "monitor_k_sec_z.png").exists()
    # the reference noise model, identified once, is the one every date used
    ref = NoiseModel.load(out / "reference" / "noise_model.npz")
    for d in summary["dates"]:
        used = NoiseModel.load(out / "dates" / d / "noise_model.npz")
        np.testing.assert_array_equal(used.mean_, ref.mean_)
        assert json.loads((out / "dates" / d / "result.json").read_text())["w_ref"]["k_sec_z"] == 350e3   # the nominal value



def test_interrupted_monitor_resumes_from_the_dates_ledgers(tmp_path, monkeypatch):
    from suspid.workflows import driver
    from suspid.infra.threads import single_blas_thread

    monitor = "monitor:\n  scenario: {parameter: c_sec_z, dates: [2026-01-01, 2026-03-01]}\n"
    small = BASE.replace("n_segments: 24", "n_segments: 8").replace("n_initial: 8", "n_initial: 6") \
        .replace("  k_sec_z: {}\n", "")
    path = _write(tmp_path, monitor, small.replace("max_iter: 10", "max_iter: 2"))
    real = driver.evaluate_many

    def interrupted(problem, ledger, X_si, executor, on_done=lambda i, ev, reused: None, **kwargs):
        if problem.config.name.endswith("2026-03-01"):  # Ctrl-C after 3 design points of the second date
            real(problem, ledger, X_si[:3], executor, on_done, **kwargs)
            raise KeyboardInterrupt
        return real(problem, ledger, X_si, executor, on_done, **kwargs)

    monkeypatch.setattr(driver, "evaluate_many", interrupted)
    with single_blas_thread(), pytest.raises(KeyboardInterrupt):
        suspid.monitor(path)
    out = tmp_path / "runs" / "mon"
    assert not (out / "monitor.json").exists() and not (out / "dates" / "2026-03-01" / "result.json").exists()
    monkeypatch.setattr(driver, "evaluate_many", real)
    with single_blas_thread():
        suspid.monitor(path)
    results = {d: json.loads((out / "dates" / d / "result.json").read_text()) for d in ("2026-01-01", "2026-03-01")}
    assert results["2026-01-01"]["n_simulator_calls_this_session"] == 0  # finished date: all from its ledger
    second = results["2026-03-01"]
    assert second["n_simulator_calls_this_session"] == second["n_simulator_calls"] - 3  # continued where it stopped
    assert json.loads((out / "monitor.json").read_text())["dates"] == list(results)
