"""A third-party plugin package, installed for real, is discovered with no change to the core."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from conftest import ROOT, run_cli

TEMPLATE = ROOT / "examples" / "plugin-template"
CONFIG = """\
name: qc
simulator: {plugin: quarter-car, options: {fs_hz: 100}}
parameters: {k_secondary: {}, c_secondary: {}}
"""


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """The template built and installed by pip into a folder of its own (a real dist-info)."""
    target = tmp_path_factory.mktemp("site")
    res = subprocess.run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation",
                          "--target", str(target), str(TEMPLATE)], capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    assert list(target.glob("suspid_quartercar-*.dist-info"))
    return target


def _env(site: Path | None) -> dict:
    env = {"SUSPID_DISABLE_PLUGIN_AUTOLOAD": ""}
    if site is not None:
        env["PYTHONPATH"] = str(site)
    return env


def test_installed_template_is_listed_and_selectable(installed, tmp_path):
    res = run_cli("plugins", env=_env(installed))
    assert res.returncode == 0, res.stderr
    row = [ln for ln in res.stdout.splitlines() if "quarter-car" in ln]
    assert row and "suspid-quartercar" in row[0] and "0.1.0" in row[0] and "simulator" in row[0]
    cfg = tmp_path / "qc.yaml"
    cfg.write_text(CONFIG)
    res = run_cli("validate", str(cfg), env=_env(installed))
    assert res.returncode == 0, res.stderr


def test_without_the_package_the_config_fails_in_one_line(tmp_path):
    cfg = tmp_path / "qc.yaml"
    cfg.write_text(CONFIG)
    res = run_cli("validate", str(cfg), env=_env(None))
    lines = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert "simulator 'quarter-car' is not available (the plugin may not be installed)" in lines[0]
    assert "available simulators: exudyn-train, vampire" in lines[0] and "key 'simulator.plugin'" in lines[0]


def test_template_passes_the_conformance_kit(quarter_car):
    from suspid.testing import check_simulator

    check_simulator(quarter_car, {"fs_hz": 100})
