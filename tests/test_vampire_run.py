"""`suspid run` through the vampire adapter with the test double."""

from __future__ import annotations

from conftest import ROOT


def test_identifies_the_double_parameters(tmp_path):
    from suspid.config import load_config
    from suspid.workflows.identify import run

    cfg = load_config(ROOT / "configs" / "vampire-double.yaml",
                      [f"output.dir={tmp_path / 'run'}", f"simulator.options.work_root={tmp_path / 'work'}"])
    r = run(cfg, progress=False, log=lambda s: None).result
    for name in ("k_sec_z", "c_sec_z"):
        assert r["identifiable"][name], r["non_identifiable_reasons"]
        assert r["errors_percent"][name] < 5.0, r["errors_percent"]
    assert r["n_simulator_calls"] == r["n_initial"] + r["n_iterations"]
