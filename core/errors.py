"""Exceptions for user-facing errors.

Every error a user can cause by a config, a data file or a plugin choice is
one of these. The command line prints ``str(error)`` as one line and exits
with code 2; no traceback unless ``--debug``.
"""

from __future__ import annotations


class SuspidError(Exception):
    """Base class of suspid's user-facing errors (exit code 2 in the CLI)."""

    exit_code = 2


class ConfigError(SuspidError):
    """A config file, a key in it or a ``--set`` override is invalid.

    The message names the file, the key path (``simulator.options.step``),
    the YAML line where known, and what was expected.

    A value that came from a command-line option rather than from the file (``--set key=value``,
    ``--param name=value``) is named by that option instead (``option``): the file has no line for it.
    """

    def __init__(self, message: str, *, file: str | None = None, key: str | None = None,
                 line: int | None = None, option: str | None = None):
        self.file, self.key, self.line, self.detail, self.option = file, key, line, message, option
        where = []
        if option:
            where.append(option)
        else:
            if file:
                where.append(f"{file}" + (f":{line}" if line else ""))
            if key:
                where.append(f"key '{key}'")
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class PluginError(SuspidError):
    """A plugin failed to load, registered a duplicate name, or was not found."""


class UnknownPluginError(PluginError):
    """A config names a plugin that is not registered."""


class DataError(SuspidError):
    """A measurement or track file is malformed; the message names the file."""


class SimulatorError(SuspidError):
    """A simulator run failed (external program, invalid output, unstable model)."""


class ClusterError(SuspidError):
    """The cluster that runs the simulations failed the run, not the simulations.

    A lost connection to the scheduler, a task the cluster dropped without a
    result, no progress within the executor's result timeout, or workers that
    cannot run suspid's tasks (the message names them). Nothing is recorded
    as a failed simulation: the same command, once the cluster is back,
    simulates the points that were running.
    """


class PluginBugError(PluginError):
    """A plugin raised an exception that is not one of suspid's: a bug in the plugin (exit code 1).

    The message names the plugin and its distribution, so the user knows whom to tell.
    """

    exit_code = 1


class DataWarning(UserWarning):
    """Data that are possible but unusual (an error in strict mode), or impossible ones the user accepted
    (``data.accept``); see :mod:`suspid.data.plausibility`."""


class LedgerError(SuspidError):
    """A run ledger cannot be used: not an SQLite database, damaged, another schema, or not writable.

    The message names the file and the remedy.
    """


class LedgerWarning(UserWarning):
    """A damaged run ledger was moved aside (``--fresh``) and an empty one started."""


class RunDirError(SuspidError):
    """A run directory is in use by another process, or holds the run of another config."""
