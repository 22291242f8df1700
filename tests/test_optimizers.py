"""Optimisers as plugins: the conformance check, known maxima, ask with pending points, and identify runs."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from conftest import run_cli
from suspid import registry
from suspid.optimize.design import DesignOptions
from suspid.optimize.testfunctions import FUNCTIONS
from suspid.testing import check_optimizer

BUILT_INS = ["ego", "random", "lhs-only", "nelder-mead", "cma-es", "skopt-gp"]


@pytest.mark.parametrize("name", BUILT_INS)
def test_every_built_in_passes_the_conformance_check(name):
    check_optimizer(registry.get("optimizer", name))


def test_the_example_optimizer_of_the_docs_passes_the_check():
    import re

    text = (Path(__file__).resolve().parents[1] / "docs" / "methods.md").read_text(encoding="utf-8")
    example = next(b for b in re.findall(r"```python\n(.*?)```", text, re.S) if "class CoordinateSearch" in b)
    namespace: dict = {}
    exec(compile(example, "docs/methods.md", "exec"), namespace)
    check_optimizer(namespace["CoordinateSearch"])


def test_skopt_gp_without_scikit_optimize_is_one_line(monkeypatch):
    import suspid
    from suspid.errors import ConfigError
    from suspid.plugins.optimizers import skopt_gp

    monkeypatch.setattr(skopt_gp, "skopt", None)
    with pytest.raises(ConfigError, match=r"optimizer.options.*needs scikit-optimize: pip install") as err:
        suspid.load_config({"optimizer": {"plugin": "skopt-gp"}})
    assert "\n" not in str(err.value)


def _maximise(name: str, f, budget: int, seed: int = 0):
    opt = registry.get("optimizer", name)(f.bounds, budget=budget, seed=seed,
                                          design=DesignOptions(n_initial=6, seed=seed))
    while not opt.done:
        X = opt.ask()
        opt.tell(X, [-float(f.func(x)) for x in X])
    return opt.result()


# (optimiser, budget, tolerance on J = -Branin): the model-based ones need few evaluations, random search many
BRANIN = [("ego", 30, 0.05), ("skopt-gp", 30, 0.05), ("nelder-mead", 80, 0.01), ("cma-es", 120, 0.02),
          ("random", 300, 0.5), ("lhs-only", 300, 0.5)]


@pytest.mark.parametrize("name,budget,tol", BRANIN)
def test_each_built_in_finds_the_maximum_of_negative_branin(name, budget, tol):
    f = FUNCTIONS["branin"]  # minimum 0.397887 at three points, one of them (pi, 2.275)
    res = _maximise(name, f, budget)
    assert res.n_evaluations <= budget
    assert -res.y_opt - f.f_min < tol, (name, -res.y_opt)
    assert res.y_opt == pytest.approx(-float(f.func(res.x_opt)))


def test_ego_ask_with_pending_points_proposes_elsewhere_and_takes_them_in_any_order():
    """An asynchronous driver: two points out at once, each asked beside the other, told in reverse."""
    f = FUNCTIONS["branin"]
    opt = registry.get("optimizer", "ego")(f.bounds, budget=16, seed=1, design=DesignOptions(n_initial=6, seed=1))
    X0 = opt.ask()
    opt.tell(X0, [-float(f.func(x)) for x in X0])
    a = opt.ask()
    b = opt.ask(pending=a)
    assert a.shape == b.shape == (1, 2)
    span = f.bounds[:, 1] - f.bounds[:, 0]
    assert np.max(np.abs(a - b) / span) > 1e-3  # the believer moved the second point away from the first
    c = opt.ask(pending=np.vstack([a, b]))  # a third worker
    assert c.shape == (1, 2) and min(np.max(np.abs(c - p) / span) for p in (a[0], b[0])) > 1e-3
    opt.tell(c, [-float(f.func(c[0]))])
    opt.tell(b, [-float(f.func(b[0]))])
    opt.tell(a, [-float(f.func(a[0]))])
    n = 9
    while not opt.done:
        X = opt.ask()
        opt.tell(X, [-float(f.func(x)) for x in X])
        n += len(X)
    res = opt.result()
    assert res.n_evaluations == n <= 16
    assert res.details.n_evaluations == n  # every point, the pending ones included, is in EGO's data
    with pytest.raises(Exception, match=r"not one that ask\(\) returned"):
        opt.tell(a, [0.0])


def test_ask_beside_is_deterministic():
    f = FUNCTIONS["branin"]

    def second_point():
        opt = registry.get("optimizer", "ego")(f.bounds, budget=16, seed=4, design=DesignOptions(n_initial=6, seed=4))
        X0 = opt.ask()
        opt.tell(X0, [-float(f.func(x)) for x in X0])
        return opt.ask(pending=opt.ask())

    assert np.array_equal(second_point(), second_point())


# -- identify with another optimiser ---------------------------------------------------------
TINY = """\
name: tiny
seed: 5
simulator: {{plugin: exudyn-train, options: {{solver: frequency}}}}
parameters:
  k_sec_z: {{}}
  c_sec_z: {{}}
data:
  source: experiment
  track: {{spectrum: german-low, n_segments: 8, length_m: 800.0, speed_kmh: 300.0}}
  w_ref: {{k_sec_z: 330.0e3, c_sec_z: 27.0e3}}
spectra: {{f_min_hz: 0.4, f_max_hz: 20.0, n_freqs: 60}}
objective: {{plugin: likelihood}}
design: {{n_initial: 6}}
identifiability: {{n_redraws: 6}}
optimizer: {{plugin: {plugin}, budget: {budget}}}
"""


def _write(tmp_path: Path, plugin: str, budget: int, name: str = "tiny.yaml") -> Path:
    cfg = tmp_path / name
    cfg.write_text(TINY.format(plugin=plugin, budget=budget))
    return cfg


@pytest.mark.parametrize("plugin", ["random", "cma-es"])
def test_identify_with_another_optimizer_spends_the_budget_and_analyses(tmp_path, plugin):
    import suspid
    from suspid.infra.ledger import Ledger

    r = suspid.identify(_write(tmp_path, plugin, 24))
    saved = json.loads((r.run_dir / "result.json").read_text())
    assert saved["optimizer"] == plugin and saved["budget"] == 24
    assert saved["n_simulator_calls"] == 24 and saved["stop_reason"] == "budget"
    assert saved["n_iterations"] == 24 - saved["n_initial"]
    assert set(saved["identifiable"]) == {"k_sec_z", "c_sec_z"} and set(saved["interval"]) == set(saved["identifiable"])
    for n, (lo, hi) in saved["interval"].items():
        assert lo <= saved["w_opt"][n] <= hi
    # the anytime history: J and w of each evaluation in order, its best is J_max and w_opt
    J = saved["anytime"]["J"]
    assert len(J) == 24 and max(J) == saved["J_max"]
    best = saved["anytime"]["w_normalized"][int(np.argmax(J))]
    assert best == pytest.approx(list(saved["w_opt_normalized"].values()), abs=1e-12)
    rows = Ledger(r.run_dir / "ledger.sqlite").trials()   # one row per trial, J joined from its evaluation
    assert [row["J"] for row in rows] == J and [row["id"] for row in rows] == list(range(24))
    assert "report.md" in {p.name for p in r.run_dir.iterdir()}


def test_invalid_optimizer_option_is_one_line_and_exit_2(tmp_path):
    cfg = _write(tmp_path, "cma-es", 24)
    cfg.write_text(cfg.read_text().replace("budget: 24}", "budget: 24, options: {sigma_zero: 0.2}}"))
    res = run_cli("run", str(cfg), "--quiet")
    assert res.returncode == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "optimizer.options.sigma_zero" in lines[0], res.stderr
    assert not (tmp_path / "runs").exists()
    res = run_cli("validate", str(cfg), "--set", "optimizer.options={sigma0: big}")
    assert res.returncode == 2 and "optimizer.options.sigma0" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    res = run_cli("validate", str(cfg), "--set", "optimizer.plugin=simplex")
    assert res.returncode == 2 and "optimizer 'simplex' is not available" in res.stderr and "nelder-mead" in res.stderr


def test_ego_options_in_the_optimizer_section_are_the_ego_section(tmp_path):
    import suspid

    cfg = suspid.load_config(_write(tmp_path, "ego", 40), ["optimizer.options={max_iter: 3, refine: {enabled: true}}"])
    assert cfg.ego.max_iter == 3 and cfg.ego.refine.enabled
    assert cfg.optimizer.options["max_iter"] == 3 and cfg.optimizer.options["seed"] == cfg.ego.seed
    plain = suspid.load_config(_write(tmp_path, "ego", 40))
    assert plain.optimizer.options == plain.ego.model_dump()


def _evaluations(ledger_path: Path) -> int:
    from conftest import count_evaluations

    return count_evaluations(ledger_path)


def test_sigkill_during_cma_es_then_resume_gives_the_same_result(tmp_path):
    """A killed run re-run retraces the optimiser's steps and reads the evaluations from the ledger."""
    budget = 60
    cfg = _write(tmp_path, "cma-es", budget)
    proc = subprocess.Popen([sys.executable, "-m", "suspid", "run", str(cfg), "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    ledger = tmp_path / "runs" / "tiny" / "ledger.sqlite"
    deadline = time.time() + 240
    while _evaluations(ledger) < 15 and time.time() < deadline and proc.poll() is None:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    killed_at = _evaluations(ledger)
    assert 15 <= killed_at < budget, killed_at  # killed inside the search
    res = run_cli("run", str(cfg), "--quiet")
    assert res.returncode == 0, res.stderr
    resumed = json.loads((tmp_path / "runs" / "tiny" / "result.json").read_text())
    assert resumed["n_simulator_calls_this_session"] == budget - killed_at
    res = run_cli("run", str(cfg), "--quiet", "--set", f"output.dir={tmp_path / 'clean'}")
    assert res.returncode == 0, res.stderr
    clean = json.loads((tmp_path / "clean" / "result.json").read_text())
    for key in ("w_opt", "J_max", "n_simulator_calls", "interval", "identifiable", "errors_percent", "anytime"):
        assert resumed[key] == clean[key], key


def test_the_methods_study_config_is_valid_with_equal_budgets():
    from suspid.config import load_config, optimizer_budget
    from suspid.workflows.study import study_variants

    path = Path(__file__).resolve().parents[1] / "configs" / "methods.yaml"
    config = load_config(path)
    runs = study_variants(path, [], config)
    assert len(runs) == 8 * 5
    assert {run.config.optimizer.plugin for run in runs} == {"ego", "random", "nelder-mead", "cma-es", "skopt-gp"}
    assert {run.config.objective.plugin for run in runs} == {"overlap", "likelihood", "mean-spectrum"}
    assert {optimizer_budget(run.config, 7) for run in runs} == {300}
    refined = [run.config for run in runs if run.variant == "ego-refine"]
    assert len(refined) == 5 and all(
        cfg.ego.refine.enabled and cfg.design.n_initial + cfg.ego.max_iter + cfg.ego.refine.max_iter == 300
        for cfg in refined)
