"""What the out-of-process executors (``processes``, ``dask``) share: options, the lost-worker error, worker checks."""

from __future__ import annotations

import platform
from typing import Any, Mapping, TypeVar

from pydantic import BaseModel

from suspid.options import parse_options
from suspid.errors import SimulatorError

M = TypeVar("M", bound=BaseModel)


class WorkerLostError(SimulatorError):
    """A task could not finish because the worker process running it died, every time it was tried.

    Yielded by :meth:`~suspid.interfaces.Executor.map_unordered` in place of
    the task's result (never raised there), like a task's own exception. The
    message names the executor, the task index and how often it was lost.
    It subclasses :class:`~suspid.errors.SimulatorError` because for the run
    it is one more failed simulator call: the usual cause is a simulator that
    crashes its process (a segmentation fault, the out-of-memory killer).
    """


def executor_options(model: type[M], options: Mapping[str, Any]) -> M:
    """The executor's ``options`` validated as ``model``.

    :raises suspid.errors.ConfigError: naming ``executor.options.<field>``.
    """
    return parse_options(model, dict(options), "executor.options")


def worker_report() -> dict[str, Any]:
    """What a worker process runs: suspid's version, Python's (major.minor) and each plugin's version.

    Run in every worker when an executor connects to a cluster and compared
    with the driver's (:func:`report_differences`); a worker that cannot
    import suspid fails before calling it, since this function is pickled by
    reference to suspid.
    """
    import suspid
    from suspid import registry

    rows, _ = registry.plugins()
    return {"suspid": suspid.__version__, "python": ".".join(platform.python_version_tuple()[:2]),
            "plugins": {f"{r.kind} {r.name}": r.plugin.version or "" for r in rows}}


def report_differences(driver: Mapping[str, Any], worker: Mapping[str, Any]) -> list[str]:
    """How a worker's :func:`worker_report` differs from the driver's, one phrase each (empty: none).

    Plugins only one side has are not compared (the driver may hold plugins,
    readers say, that tasks never use; a task that needs a missing one fails
    at its import with the worker's address).
    """
    out = [f"{what} {worker[what]} (driver {driver[what]})" for what in ("suspid", "python")
           if worker.get(what) != driver.get(what)]
    theirs = worker.get("plugins", {})
    out += [f"plugin {name} {theirs[name] or 'unversioned'} (driver {version or 'unversioned'})"
            for name, version in sorted(driver.get("plugins", {}).items()) if name in theirs and theirs[name] != version]
    return out
