"""Plugin discovery and registration (discovery, isolation, duplicates)."""

from __future__ import annotations

import types
from pathlib import Path

import pytest

from suspid import hookimpl, registry
from suspid.errors import PluginError, UnknownPluginError
from suspid.interfaces import Objective

from conftest import run_cli


class _Obj(Objective):
    name = "test-constant"

    def psi(self, y_mes, y_mod, freqs):
        return y_mes.mean(axis=(0, 2)) * 0


def _plugin(**hooks) -> types.SimpleNamespace:
    return types.SimpleNamespace(**{k: hookimpl(v) for k, v in hooks.items()})


def test_builtins_come_through_entry_points():
    rows, failures = registry.plugins()
    assert failures == []
    by_name = {(r.kind, r.name): r for r in rows}
    for kind, name in [("objective", "likelihood"), ("objective", "overlap"), ("surrogate", "gpy-kriging"),
                       ("simulator", "exudyn-train"), ("simulator", "vampire")]:
        assert by_name[(kind, name)].plugin.distribution == "suspid"


def test_register_in_code_and_get():
    registry.add_plugin(_plugin(suspid_register_objectives=lambda register: register(_Obj)), "mine")
    assert registry.get("objective", "test-constant") is _Obj
    assert "test-constant" in registry.names("objective")


def test_unknown_name_lists_available():
    with pytest.raises(UnknownPluginError) as err:
        registry.get("objective", "nope")
    msg = str(err.value)
    assert "objective 'nope' is not available" in msg and "may not be installed" in msg
    assert "likelihood" in msg and "overlap" in msg


def test_duplicate_name_names_both_providers():
    registry.add_plugin(_plugin(suspid_register_objectives=lambda register: register(_Obj)), "first")
    registry.add_plugin(_plugin(suspid_register_objectives=lambda register: register(_Obj)), "second")
    with pytest.raises(PluginError) as err:
        registry.names("objective")
    assert '"first"' in str(err.value) and '"second"' in str(err.value) and "twice" in str(err.value)


def test_misspelled_hook_is_rejected_by_check_pending():
    registry.add_plugin(_plugin(suspid_register_objective=lambda register: None), "typo")
    with pytest.warns(registry.PluginWarning, match='plugin "typo"'):
        registry.names("objective")
    assert [f.name for f in registry.registry().failures] == ["typo"]


def test_failing_hook_is_isolated():
    def bad(register):
        raise RuntimeError("kaboom")

    registry.add_plugin(_plugin(suspid_register_objectives=bad), "bad")
    with pytest.warns(registry.PluginWarning, match="kaboom"):
        assert "overlap" in registry.names("objective")


def test_unknown_kind():
    with pytest.raises(PluginError, match="unknown plugin kind"):
        registry.names("teapot")


# -- discovery of installed distributions (subprocesses with autoload on) ----------
def _fake_distribution(root: Path, name: str, entry: str, module_source: str) -> Path:
    """An installed distribution as importlib.metadata sees it: a dist-info folder and a module."""
    module = entry.split(" = ")[1]
    (root / f"{module}.py").write_text(module_source)
    info = root / f"{name.replace('-', '_')}-0.3.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.3\n")
    (info / "entry_points.txt").write_text(f"[suspid]\n{entry}\n")
    return root


@pytest.fixture
def broken_dist(tmp_path):
    return _fake_distribution(tmp_path, "suspid-broken", "broken = broken_plugin",
                              "raise ImportError('this plugin is broken on purpose')\n")


def _env(path: Path, **extra):
    return {"PYTHONPATH": str(path), "SUSPID_DISABLE_PLUGIN_AUTOLOAD": "", **extra}


def test_broken_plugin_warns_and_everything_else_works(broken_dist, tmp_path):
    res = run_cli("plugins", env=_env(broken_dist))
    assert res.returncode == 0, res.stderr
    assert 'Error importing plugin "broken" (distribution suspid-broken)' in res.stderr
    assert "overlap" in res.stdout and "broken" in res.stdout
    cfg = tmp_path / "c.yaml"
    cfg.write_text("name: ok\nsimulator: {plugin: exudyn-train}\nparameters: {c_yaw: {}}\n")
    res = run_cli("validate", str(cfg), env=_env(broken_dist))
    assert res.returncode == 0, res.stderr
    assert "broken" in res.stderr


def test_broken_plugin_is_an_error_in_strict_mode(broken_dist, tmp_path):
    for args in (["plugins"], ["validate", str(tmp_path / "missing.yaml")]):
        res = run_cli(*args, env=_env(broken_dist, SUSPID_STRICT_PLUGINS="1"))
        assert res.returncode == 2
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and '"broken"' in lines[0] and "suspid-broken" in lines[0]
        assert "Traceback" not in res.stderr


def test_disable_plugins_by_entry_point_name(broken_dist):
    res = run_cli("plugins", env=_env(broken_dist, SUSPID_STRICT_PLUGINS="1", SUSPID_DISABLE_PLUGINS="broken,overlap"))
    assert res.returncode == 0, res.stderr
    assert "broken" not in res.stdout and " overlap " not in res.stdout and "likelihood" in res.stdout


def test_autoload_off_ignores_third_party(broken_dist):
    res = run_cli("plugins", env={"PYTHONPATH": str(broken_dist), "SUSPID_DISABLE_PLUGIN_AUTOLOAD": "1",
                                  "SUSPID_STRICT_PLUGINS": "1"})
    assert res.returncode == 0 and "broken" not in res.stdout + res.stderr
