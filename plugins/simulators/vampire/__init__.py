"""The ``vampire`` simulator plugin: Vampire Pro as a black box through files.

Vampire's vehicle, run and result formats are not public, so the user brings a
working Vampire project as a template directory with ``{{ placeholders }}``,
the command line that runs it, and an ASCII export of the results. See
``docs/vampire.md``.

Modules: :mod:`.options` (the options model), :mod:`.templates` (strict
rendering, safe paths), :mod:`.trackfile` (6-field track irregularity file),
:mod:`.runner` (process tree under control), :mod:`.export` (ASCII results),
:mod:`.profiles` (``.whe``/``.rai`` wheel and rail profiles, a utility),
:mod:`.simulator` (the :class:`VampireSimulator` class).
"""

from suspid import hookimpl

from .options import Options
from .simulator import VampireSimulator

__all__ = ["Options", "VampireSimulator"]


@hookimpl
def suspid_register_simulators(register):
    """Register :class:`VampireSimulator` as ``vampire``."""
    register(VampireSimulator)
