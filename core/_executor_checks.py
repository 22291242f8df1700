"""Conformance check for executor plugins: :func:`check_executor`, re-exported by ``suspid.testing``.

The task functions are module-level so that every executor can pickle them
by reference: a worker process or a dask worker imports this module to run
them, which works wherever suspid is installed.

``assert`` is right here: these are tests, not user-input validation.
"""

from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np
from pydantic import BaseModel, ValidationError

from suspid.interfaces import Executor


def square(x: Any) -> Any:
    """``x * x``: a number, or a numpy array element-wise."""
    return x * x


def fail_on_odd(x: int) -> int:
    """``x`` for even ``x``; odd ``x`` raises ``ValueError('task input <x> is odd')``."""
    if x % 2:
        raise ValueError(f"task input {x} is odd")
    return x


def sleep_then_square(item: tuple[float, Any]) -> Any:
    """Item ``(delay_s, x)``: sleep ``delay_s`` seconds, then return ``x * x``."""
    delay_s, x = item
    time.sleep(delay_s)
    return x * x


class DieOnce:
    """A task wrapper that ends its worker process once, for the item numbered ``victim``.

    Called with ``(number, value)``; returns ``fn(value)``, except that the
    first call for ``number == victim`` anywhere (the marker file does not
    exist yet) creates the marker and then ends its process with
    ``os._exit(1)``, as a segmentation fault would. The retry finds the marker
    and succeeds. Only for executors that run tasks in other processes: in the
    calling process it would end the caller.

    :param fn: the wrapped task, picklable.
    :param victim: the item number whose first run dies.
    :param marker: a path that must not exist yet, visible to every worker
        (a local temporary directory for a LocalCluster).
    :param delay_s: seconds the victim waits before dying, so that other tasks
        are in flight when it dies.
    """

    def __init__(self, fn: Callable[[Any], Any], victim: int, marker: str | os.PathLike, delay_s: float = 0.2):
        self.fn, self.victim, self.marker, self.delay_s = fn, victim, str(marker), delay_s

    def __call__(self, item: tuple[int, Any]) -> Any:
        number, value = item
        if number == self.victim and not os.path.exists(self.marker):
            try:
                with open(self.marker, "x"):
                    pass
            except FileExistsError:  # another attempt got here first: it is the one to die
                return self.fn(value)
            time.sleep(self.delay_s)
            os._exit(1)
        return self.fn(value)


def collect(executor: Executor, fn: Callable[[Any], Any], items: list[Any]) -> dict[int, Any]:
    """``{index: result or exception}`` of ``executor.map_unordered(fn, items)``, checking each index once."""
    out: dict[int, Any] = {}
    for pair in executor.map_unordered(fn, items):
        assert isinstance(pair, tuple) and len(pair) == 2, f"map_unordered must yield (index, result), got {pair!r}"
        index, result = pair
        assert isinstance(index, int) and 0 <= index < len(items), f"index {index!r} is not one of the items'"
        assert index not in out, f"index {index} was yielded twice"
        out[index] = result
    assert sorted(out) == list(range(len(items))), f"indices missing: {sorted(set(range(len(items))) - set(out))}"
    return out


def _build(cls: type, options: Mapping[str, Any] | None) -> Executor:
    assert isinstance(cls, type) and issubclass(cls, Executor), f"{cls!r} must subclass Executor"
    assert isinstance(getattr(cls, "name", None), str) and cls.name, f"{cls.__name__}.name must be a non-empty string"
    options = dict(options or {})
    model = getattr(cls, "Options", None)
    if model is not None:
        assert issubclass(model, BaseModel), f"{cls.__name__}.Options must be a pydantic model"
        try:
            model.model_validate({**options, "no_such_option_xyz": 1})
        except ValidationError:
            pass
        else:
            raise AssertionError(f"{cls.__name__}.Options must reject unknown keys (extra='forbid')")
        validated = model.model_validate(options)
        options = {k: getattr(validated, k) for k in model.model_fields}
    return cls(**options)


def check_executor(cls: type, options: Mapping[str, Any] | None = None, *, worker_death: bool = False) -> None:
    """Check an executor class against :class:`suspid.interfaces.Executor`.

    Checks: name and options (unknown keys rejected); the context manager
    returns the executor; ``n_workers`` is a positive int; every item's result
    comes back once under its index, whatever the completion order; numpy
    arrays come back intact; a task's exception is yielded with its index
    (type and message kept) and the other tasks still finish; no items yield
    nothing; several calls work within one ``with`` block.

    :param cls: the executor class.
    :param options: its options (as in ``executor.options``).
    :param worker_death: also check that a task whose worker process dies is
        run again and the call still gives every result. Only for executors
        that run tasks in other processes (never ``serial``: the dying task
        would end the caller).
    :raises AssertionError: saying which part of the contract is broken.
    """
    executor = _build(cls, options)
    with executor as entered:
        assert entered is executor, "__enter__ must return the executor itself"
        n = executor.n_workers
        assert isinstance(n, int) and n >= 1, f"n_workers must be a positive int, got {n!r}"

        assert collect(executor, square, []) == {}, "no items must yield nothing"

        values = list(range(12))
        got = collect(executor, square, values)
        assert got == {i: v * v for i, v in enumerate(values)}, f"wrong results: {got}"

        # later items finish first on a parallel executor: results must follow the index, not the order
        items = [(0.01 * (len(values) - i), v) for i, v in enumerate(values)]
        got = collect(executor, sleep_then_square, items)
        assert got == {i: v * v for i, v in enumerate(values)}, f"wrong results with out-of-order completion: {got}"

        arrays = [np.arange(5.0) * k for k in range(4)]
        got = collect(executor, square, arrays)
        for i, a in enumerate(arrays):
            assert isinstance(got[i], np.ndarray) and np.array_equal(got[i], a * a), f"array {i} came back as {got[i]!r}"

        got = collect(executor, fail_on_odd, values)
        for i, v in enumerate(values):
            if v % 2:
                assert isinstance(got[i], ValueError), f"task {i} raised ValueError; yielded {got[i]!r}"
                assert f"task input {v} is odd" in str(got[i]), f"task {i}: message lost: {got[i]}"
            else:
                assert got[i] == v, f"task {i}: expected {v}, got {got[i]!r}"

        if worker_death:
            with tempfile.TemporaryDirectory(prefix="suspid-check-executor-") as tmp:
                marker = Path(tmp) / "died"
                task = DieOnce(sleep_then_square, victim=3, marker=marker)
                items = [(i, (0.1, v)) for i, v in enumerate(values)]
                got = collect(executor, task, items)
                assert marker.exists(), "the victim task never ran"
                assert got == {i: v * v for i, v in enumerate(values)}, (
                    f"after a worker died, the results are not all there: {got}")
