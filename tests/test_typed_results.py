"""Typed results: the run's J is one object, and the result files are the serialisation of typed results."""

from __future__ import annotations

import json

import pytest

import suspid
from suspid.method import objective as objective_module


def small_config(tmp_path, **extra):
    cfg = {"name": "typed", "seed": 5,
           "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0}},
           "parameters": {"k_sec_z": {}, "c_sec_z": {}},
           "data": {"track": {"n_segments": 6, "length_m": 1000.0}, "w_ref": {"k_sec_z": 380.0e3}},
           "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 40},
           "design": {"n_initial": 6}, "ego": {"max_iter": 2}, "identifiability": {"n_redraws": 6},
           "output": {"dir": str(tmp_path / "run")}}
    return cfg | extra


def test_the_run_builds_its_objective_function_once(tmp_path, monkeypatch):
    """Every evaluation of J (design, EGO, the intervals' ±h points, the report) goes through the problem's
    one ObjectiveFunction; the bootstrap replicates of the intervals, J on resampled data, build one each."""
    built = []
    original = objective_module.ObjectiveFunction.__init__

    def counting(self, objective, y_mes, *args, **kwargs):
        built.append(y_mes)
        original(self, objective, y_mes, *args, **kwargs)

    monkeypatch.setattr(objective_module.ObjectiveFunction, "__init__", counting)
    r = suspid.identify(small_config(tmp_path))
    own = [y for y in built if y is r.problem.y_mes]
    assert len(own) == 1
    assert r.n_simulator_calls >= 6
    assert len(built) == 1 + r.result["interval_method"]["n_redraws"]
