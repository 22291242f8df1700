"""The ``serial`` executor: every task in the calling process, one after the other (the default)."""

from __future__ import annotations

from typing import Any, Callable, Iterator, Sequence

from suspid import hookimpl
from suspid.interfaces import Executor
from suspid.options import Section


class SerialOptions(Section):
    """The serial executor takes no options (any key is a mistake)."""


class SerialExecutor(Executor):
    """Runs tasks in order in this process; an exception is yielded, not raised."""

    name = "serial"
    Options = SerialOptions

    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        for i, item in enumerate(items):
            try:
                result = fn(item)
            except Exception as exc:  # reported to the caller with its index
                result = exc
            yield i, result


@hookimpl
def suspid_register_executors(register):
    register(SerialExecutor)
