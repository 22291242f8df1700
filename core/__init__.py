"""suspid: identification of high-speed train suspension parameters.

The method follows the paper in ``shared/reference/paper.txt``: spectra of
accelerations (eq. 1-2), an additive Gaussian noise model (eq. 3), a kernel
density objective (eq. 5-8) maximised by EGO on a Kriging metamodel (eq. 9).

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

__all__ = ["PROJECT_NAME", "hookimpl", "hookspec", "__version__"]
