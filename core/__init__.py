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

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version as _version

# Only the markers are imported eagerly: a plugin's ``from suspid import
# hookimpl`` costs pluggy, not the workflows (numpy, scipy, GPy). The API is
# loaded on first use of one of its names (PEP 562).
from suspid.hookspecs import PROJECT_NAME, hookimpl, hookspec

try:
    __version__ = _version(PROJECT_NAME)
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

_LAZY = {name: "suspid.api" for name in ("Validation", "diagnose", "identify", "ingest", "load_config", "modes",
                                          "monitor", "segments", "simulate", "stability", "study", "validate",
                                          "indicators", "fleet_import", "fleet_demo", "dashboard", "parameters",
                                          "ParameterInfo")}
_LAZY["IdentificationResult"] = "suspid.workflows.identify"
_LAZY |= {"StudyResult": "suspid.workflows.study", "MonitorResult": "suspid.workflows.monitor",
          "DiagnosisResult": "suspid.workflows.diagnose"}

__all__ = ["PROJECT_NAME", "hookimpl", "hookspec", "__version__", *_LAZY]


def __getattr__(name: str):
    """The API's names, imported when first asked for (``suspid.identify``)."""
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'suspid' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
