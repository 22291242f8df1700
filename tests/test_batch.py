"""Batch EGO and parallel executors inside a run."""

from __future__ import annotations

import json

import numpy as np
import pytest

from suspid.optimize.ego import EGOOptions, run_ego
from suspid.optimize.testfunctions import branin

BRANIN_BOX = [[-5.0, 10.0], [0.0, 15.0]]
BRANIN_MIN = 0.397887


def _neg_branin(x):
    return -float(branin(np.asarray(x)))


def test_batch_one_is_the_sequential_loop():
    a = run_ego(_neg_branin, BRANIN_BOX, ego=EGOOptions(max_iter=4, seed=3))
    b = run_ego(_neg_branin, BRANIN_BOX, ego=EGOOptions(max_iter=4, seed=3, batch=1),
                func_batch=lambda X: pytest.fail("batch = 1 must not call func_batch"))
    assert np.array_equal(a.X, b.X) and np.array_equal(a.y, b.y)


@pytest.mark.parametrize("k", [2, 4])
def test_batches_are_evaluated_together(k):
    sizes = []

    def func_batch(X):
        sizes.append(len(X))
        return [_neg_branin(x) for x in X]

    res = run_ego(_neg_branin, BRANIN_BOX, ego=EGOOptions(max_iter=8, seed=1, batch=k, tol=0.0),
                  func_batch=func_batch)
    assert res.n_iterations == 8 and sum(sizes) == 8  # the m1 cap holds across batches
    assert sizes[0] == k and all(s <= k for s in sizes)
    assert np.all((res.X_unit >= 0) & (res.X_unit <= 1))
    # distinct points within a batch (the believer moves the next choice away)
    X = res.X_unit[res.n_initial:]
    assert np.min(np.linalg.norm(X[:, None] - X[None], axis=-1)[np.triu_indices(len(X), 1)]) > 1e-6


SMALL = """\
name: par
seed: 4
simulator: {plugin: exudyn-train, options: {solver: frequency}}
parameters: {k_sec_z: {}, c_sec_z: {}}
data:
  source: experiment
  track: {spectrum: german-low, n_segments: 6, length_m: 600.0, speed_kmh: 300.0}
  w_ref: {k_sec_z: 330.0e3, c_sec_z: 27.0e3}
spectra: {f_min_hz: 0.4, f_max_hz: 20.0, n_freqs: 80}
design: {n_initial: 6}
ego: {max_iter: 4, batch: 2}
"""


@pytest.mark.parametrize("executor", ["processes", "dask"])
def test_parallel_executor_gives_the_serial_J_values(tmp_path, executor):
    from suspid.config import load_config
    from suspid.infra.ledger import Ledger
    from suspid.workflows.identify import run

    cfg = tmp_path / "par.yaml"
    cfg.write_text(SMALL)
    results = {}
    for name, options in (("serial", "{}"), (executor, "{n_workers: 2}" if executor == "dask" else "{workers: 2}")):
        c = load_config(cfg, [f"executor.plugin={name}", f"executor.options={options}",
                              f"output.dir={tmp_path / name}"])
        out = run(c, progress=False, log=lambda s: None)
        evs = {json.dumps(e.w, sort_keys=True): e.J for e in Ledger(out.run_dir / "ledger.sqlite").evaluations()}
        results[name] = (evs, out.result)
    serial, parallel = results["serial"], results[executor]
    assert serial[0] == parallel[0]  # the same points and exactly the same J values
    assert serial[1]["w_opt"] == parallel[1]["w_opt"]
    assert serial[1]["n_simulator_calls"] == 6 + serial[1]["n_iterations"]
