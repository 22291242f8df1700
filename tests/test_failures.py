"""Failures inside a run: a simulation that fails does not end the run, and a rerun does not repeat it."""

from __future__ import annotations

import hashlib
import json
import types

import pytest

import suspid
from suspid import hookimpl, registry
from suspid.errors import PluginBugError, SimulatorError
from suspid.plugins.simulators.exudyn_train import ExudynTrain


def _fails(w: dict) -> bool:
    """About one point in seven fails, decided by the point itself (the same on every run)."""
    digest = hashlib.sha256(json.dumps({k: round(v, 6) for k, v in sorted(w.items())}).encode()).digest()
    return digest[0] % 7 == 0


class FlakyTrain(ExudynTrain):
    """The built-in train, but about one parameter vector in seven fails like a diverging solver."""

    name = "flaky-train"
    calls: list[dict] = []

    def simulate(self, w, segments):
        FlakyTrain.calls.append(dict(w))
        if w and _fails(w):
            raise SimulatorError(f"solver diverged at {sorted(w)}")
        return super().simulate(w, segments)


class BuggyTrain(ExudynTrain):
    name = "buggy-train"

    def simulate(self, w, segments):
        if w:
            raise ZeroDivisionError("division by zero in the wheel-rail contact")
        return super().simulate(w, segments)


@pytest.fixture
def flaky():
    plugin = types.SimpleNamespace(suspid_register_simulators=hookimpl(
        lambda register: (register(FlakyTrain), register(BuggyTrain))))
    registry.add_plugin(plugin, "flaky")
    FlakyTrain.calls = []
    yield
    registry.reset()


def _config(tmp_path, plugin="flaky-train") -> dict:
    return {"name": "flaky", "seed": 4,
            "simulator": {"plugin": plugin, "options": {"solver": "frequency", "fs_hz": 50.0}},
            "parameters": {"k_sec_z": {}, "c_sec_z": {}},
            "data": {"track": {"n_segments": 6, "length_m": 1000.0}, "w_ref": {"k_sec_z": 380.0e3}},
            "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 40},
            "design": {"n_initial": 14}, "ego": {"max_iter": 8, "tol": 1e-9},
            "identifiability": {"n_redraws": 6}, "output": {"dir": str(tmp_path / "run")}}


def test_failed_points_are_listed_and_not_simulated_again(tmp_path, flaky):
    cfg = _config(tmp_path)
    first = suspid.identify(cfg)
    failed = first.result["failed_points"]
    assert failed, "the flaky simulator should have failed at some design or EGO point"
    assert all(_fails(p["w"]) and "solver diverged" in p["error"] for p in failed)
    assert not _fails(first.w_opt)  # a failed point is never w_opt
    assert first.n_iterations >= 1
    report = (tmp_path / "run" / "report.md").read_text()
    assert "## Failed simulations" in report
    n_calls = len(FlakyTrain.calls)

    again = suspid.identify(cfg)
    assert len(FlakyTrain.calls) == n_calls, "a rerun simulated again"
    assert again.to_dict()["failed_points"] == failed
    assert again.w_opt == first.w_opt and again.J_max == first.J_max

    retried = suspid.identify(cfg, retry_failed=True)
    retried_points = FlakyTrain.calls[n_calls:]
    assert retried_points and all(_fails(w) for w in retried_points)  # only the failed ones are tried again
    assert retried.w_opt == first.w_opt


def test_a_plugin_bug_names_the_plugin_and_exits_1(tmp_path, flaky, capsys):
    from suspid.cli import main

    with pytest.raises(PluginBugError, match="simulator plugin 'buggy-train'.*ZeroDivisionError"):
        suspid.identify(_config(tmp_path, "buggy-train"))
    path = tmp_path / "buggy.yaml"
    import yaml

    cfg = _config(tmp_path, "buggy-train")
    cfg["output"]["dir"] = str(tmp_path / "run2")
    path.write_text(yaml.safe_dump(cfg))
    with pytest.raises(SystemExit) as exit_:
        main(["run", str(path), "--quiet"])
    err = capsys.readouterr().err
    assert exit_.value.code == 1 and len(err.strip().splitlines()) == 1, err
    assert "buggy-train" in err and "ZeroDivisionError" in err and "Traceback" not in err


def test_another_optimizer_tolerates_failed_points_and_counts_them_against_the_budget(tmp_path, flaky):
    """cma-es through the same failure handling: failed points listed, never w_opt, the budget spent."""
    cfg = _config(tmp_path) | {"optimizer": {"plugin": "cma-es", "budget": 30}}
    r = suspid.identify(cfg)
    failed = r.result["failed_points"]
    assert failed and all(_fails(p["w"]) and "solver diverged" in p["error"] for p in failed)
    assert not _fails(r.w_opt)
    J = r.result["anytime"]["J"]
    in_search = [p for p in failed if p["phase"] == "cma-es"]          # the others: interval points
    assert in_search and all(p["phase"] in ("cma-es", "intervals") for p in failed)
    assert len(J) == 30 and sum(v is None for v in J) == len(in_search)
    assert r.n_simulator_calls == 30 - len(in_search)


class ThreeChannelTrain(ExudynTrain):
    """Says it has the train's ten channels, returns three of them."""

    name = "three-channel-train"

    def simulate(self, w, segments):
        return [type(r)(r.channels[:3], r.fs, r.accelerations[:3], r.segment) for r in super().simulate(w, segments)]


def test_a_plugin_returning_other_channels_than_it_lists_is_named(tmp_path):
    """It was "record 'seg-001' has channels [...]" or a shape error further on, without the plugin's name."""
    plugin = types.SimpleNamespace(suspid_register_simulators=hookimpl(lambda register: register(ThreeChannelTrain)))
    registry.add_plugin(plugin, "three")
    cfg = _config(tmp_path, "three-channel-train") | {"data": {"track": {"n_segments": 2, "length_m": 1000.0},
                                                               "reference": {"n_segments": 4}}}
    with pytest.raises(PluginBugError) as err:
        suspid.identify(cfg)
    msg = str(err.value)
    assert "simulator plugin 'three-channel-train'" in msg and "returned 3 channels" in msg, msg
    assert "its channels() lists 10" in msg and "\n" not in msg
