"""Shared fixtures.

Entry-point autoloading of third-party plugins is off for the whole suite
(``SUSPID_DISABLE_PLUGIN_AUTOLOAD=1``): only suspid's own entry points load,
so plugins a user has installed cannot leak into our tests. Tests about
discovery turn it back on in a subprocess of their own.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

os.environ["SUSPID_DISABLE_PLUGIN_AUTOLOAD"] = "1"
# the suite's matrices are small: BLAS threads only contend on a 2-core runner (set before numpy loads)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
for _var in ("SUSPID_STRICT_PLUGINS", "SUSPID_DISABLE_PLUGINS"):
    os.environ.pop(_var, None)

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE_SRC = ROOT / "examples" / "plugin-template" / "src"


@pytest.fixture(autouse=True)
def _fresh_registry():
    """Every test starts and ends with a registry built from the environment."""
    from suspid import registry

    registry.reset()
    yield
    registry.reset()


@pytest.fixture
def quarter_car():
    """Register the template's quarter-car simulator in code (not through an entry point)."""
    from suspid import registry

    sys.path.insert(0, str(TEMPLATE_SRC))
    try:
        import suspid_quartercar

        registry.add_plugin(suspid_quartercar, "quarter-car")
        yield suspid_quartercar.QuarterCar
    finally:
        sys.path.remove(str(TEMPLATE_SRC))


def run_cli(*args: str, env: dict | None = None, cwd: Path | None = None):
    """Run ``python -m suspid`` in a subprocess; returns CompletedProcess."""
    import subprocess

    full_env = dict(os.environ)
    full_env.update(env or {})
    return subprocess.run([sys.executable, "-m", "suspid", *args], capture_output=True, text=True,
                          env=full_env, cwd=cwd, timeout=300)


def count_evaluations(ledger_path: Path) -> int:
    """Successful evaluations in a run ledger (0 while it does not exist or is locked), read-only."""
    from suspid.infra.ledger import count_finished

    return count_finished(ledger_path) or 0


def interruptible() -> None:
    """``preexec_fn`` for a subprocess the test sends SIGINT to: the default disposition of SIGINT.

    A shell without job control starts background commands (``pytest ... &``) with SIGINT
    ignored, and children inherit that, so Ctrl-C tests would pass or fail with the way
    pytest was started.
    """
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def small_config(tmp_path: Path, **extra) -> dict:
    """A small identification config (2 parameters, 6 segments, m0 = 6, m1 = 2) writing to ``tmp_path / "run"``;
    ``extra`` replaces top-level sections."""
    cfg = {"name": "typed", "seed": 5,
           "simulator": {"plugin": "exudyn-train", "options": {"solver": "frequency", "fs_hz": 50.0}},
           "parameters": {"k_sec_z": {}, "c_sec_z": {}},
           "data": {"track": {"n_segments": 6, "length_m": 1000.0}, "w_ref": {"k_sec_z": 380.0e3}},
           "spectra": {"f_min_hz": 0.5, "f_max_hz": 10.0, "n_freqs": 40},
           "design": {"n_initial": 6}, "ego": {"max_iter": 2}, "identifiability": {"n_redraws": 6},
           "output": {"dir": str(tmp_path / "run")}}
    return cfg | extra
