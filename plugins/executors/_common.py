"""What the out-of-process executors (``processes``, ``dask``) share: option parsing and the lost-worker error."""

from __future__ import annotations

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
