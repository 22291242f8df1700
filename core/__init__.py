"""suspid: identification of high-speed train suspension parameters from on-track accelerations.

The method is that of the paper "Inverse identification of mechanical
parameters of high-speed train suspensions submitted to random track
irregularities": spectra of accelerations (eq. 1-2), an additive Gaussian
noise model (eq. 3), a kernel density objective (eq. 5-8) maximised by EGO on
a Kriging metamodel (eq. 9); ``docs/method.md`` maps each equation to its module.

The Python API (:mod:`suspid.api`), what every command of the ``suspid``
command line does::

    import suspid
    r = suspid.identify("configs/quickstart.yaml")
    print(r.errors_percent)

Plugin authors import :data:`hookimpl` from here::

    from suspid import hookimpl

    @hookimpl
    def suspid_register_simulators(register):
        register(MySimulator)
"""

from importlib.metadata import PackageNotFoundError, version as _version

import pluggy

PROJECT_NAME = "suspid"
"""The pluggy project name; it builds both markers and names the entry-point group."""

hookspec = pluggy.HookspecMarker(PROJECT_NAME)
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)

try:
    __version__ = _version(PROJECT_NAME)
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

# The API comes last: its modules import the markers above.
from suspid.api import (Validation, dashboard, diagnose, fleet_demo, fleet_import, identify,  # noqa: E402
                        indicators, ingest, load_config, modes, monitor, segments, simulate, stability, study,
                        validate)
from suspid.workflows.identify import IdentificationResult  # noqa: E402

__all__ = ["PROJECT_NAME", "hookimpl", "hookspec", "__version__", "IdentificationResult", "Validation",
           "diagnose", "identify", "ingest", "load_config", "modes", "monitor", "segments", "simulate", "stability",
           "study", "validate", "indicators", "fleet_import", "fleet_demo", "dashboard"]
