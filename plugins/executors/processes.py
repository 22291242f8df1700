"""The ``processes`` executor: a pool of worker processes on this machine.

Select it with ``executor: {plugin: processes, options: {workers: 8}}``.
Built on :class:`concurrent.futures.ProcessPoolExecutor`; the pool is started
in ``__enter__`` and shut down in ``__exit__``, and serves every
``map_unordered`` call in between.

Start method: **spawn**, on every platform. ``fork`` would copy the driver
with whatever its threads hold at that instant (a dask client's event loop,
the ledger's SQLite connection, BLAS thread pools, the vampire adapter's run
threads): a lock taken by another thread stays taken for ever in the child,
and SQLite forbids using a connection across ``fork``. ``forkserver`` avoids
that too but does not exist on Windows; ``spawn`` is the one start method of
every operating system, so the behaviour the tests check on Linux is the one
users get on Windows and macOS. Its cost, each worker importing numpy and
suspid afresh (about a second), is paid once per pool, not per task. As with
any spawn-based pool, a script that uses this executor must keep its top-level
code under ``if __name__ == "__main__":`` (the ``suspid`` command does).

Every worker is started in ``__enter__`` (and in each new pool), not on
demand: see :meth:`ProcessExecutor._new_pool` for the CPython race this avoids.

A dead worker. When one worker process dies (a simulator crashing its
process, the out-of-memory killer), ``ProcessPoolExecutor`` marks the whole
pool broken and every task in flight fails with ``BrokenProcessPool``, not
only the dead worker's: the pool cannot tell which task killed it. So this
executor starts a new pool and runs again only the tasks that were in flight
(finished results are kept); tasks not yet started were never submitted, as
at most ``workers`` tasks are in flight at a time. Every loss counts against
each task in flight. A task lost more than ``max_retries`` times is given up
(a :class:`~suspid.plugins.executors._common.WorkerLostError` naming its index
is yielded) only if it was the one task in flight when its worker died last;
otherwise it may be an innocent neighbour of the culprit, and it is run once
more on its own to find out. Telling culprit from neighbours this way costs a
few tasks run one at a time, and only when some task kills its worker again
and again.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections import Counter, deque
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, ClassVar, Iterator, Sequence

from pydantic import BaseModel, ConfigDict, Field

from suspid import hookimpl
from suspid.errors import PluginError
from suspid.interfaces import Executor, TaskHandle

from ._common import WorkerLostError, executor_options

START_METHOD = "spawn"
"""The multiprocessing start method of the pool (see the module docstring for why)."""


def default_workers() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one, else ``os.cpu_count()``).

    The affinity mask is what ``taskset``, batch schedulers and many
    containers restrict; ``os.cpu_count()`` would count the whole machine.
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows
        return max(1, os.cpu_count() or 1)


class ProcessOptions(BaseModel):
    """Options of the ``processes`` executor (``executor.options``)."""

    model_config = ConfigDict(extra="forbid")

    workers: int = Field(default_factory=default_workers, ge=1,
                         description="worker processes, i.e. tasks at once; default: the CPUs this process may use")
    max_retries: int = Field(default=2, ge=0,
                             description="how many times a task lost to a dead worker process is run again")


class ProcessExecutor(Executor):
    """Tasks on a local pool of ``workers`` spawned processes; see the module docstring.

    ``fn``, the items and the results must be picklable; ``fn`` must be
    importable by reference (a module-level function or an instance of a
    module-level class), since workers are fresh interpreters.
    """

    name: ClassVar[str] = "processes"
    Options: ClassVar[type] = ProcessOptions

    pool_: ProcessPoolExecutor | None = None
    opts_: ProcessOptions | None = None

    def _options(self) -> ProcessOptions:
        return self.opts_ if self.opts_ is not None else executor_options(ProcessOptions, self.options)

    @property
    def n_workers(self) -> int:
        """The number of worker processes (``workers``)."""
        return self._options().workers

    def __enter__(self) -> "ProcessExecutor":
        if self.pool_ is not None:
            raise RuntimeError("processes executor: already entered (one `with` block at a time)")
        self.opts_ = self._options()
        self.pool_ = self._new_pool()
        return self

    def __exit__(self, exc_type: Any, *exc: Any) -> None:
        pool, self.pool_ = self.pool_, None
        if pool is None:
            return
        if exc_type is not None:  # leaving on an error: do not wait for long simulator runs to end
            _terminate_workers(pool)
        pool.shutdown(wait=True, cancel_futures=True)

    def _new_pool(self) -> ProcessPoolExecutor:
        """A pool with every worker process started and watched.

        Workers are started at once with one quick task each. Left to start on
        demand, a worker spawned while the pool's manager thread is already
        waiting is not among the processes it watches (CPython 3.11), so its
        death goes unnoticed until some other task finishes, possibly much
        later; our tests caught exactly that. Started here, before any real
        task, every worker is watched from the first real task on.

        :raises PluginError: when the workers cannot start.
        """
        pool = ProcessPoolExecutor(max_workers=self.opts_.workers,
                                   mp_context=multiprocessing.get_context(START_METHOD))
        try:
            for started in [pool.submit(os.getpid) for _ in range(self.opts_.workers)]:
                started.result()
        except BrokenProcessPool as exc:
            pool.shutdown(wait=True)
            raise PluginError(f"processes executor: the worker processes could not start ({exc})") from exc
        return pool

    def _rebuild(self) -> None:
        """Replace a broken pool by a new one (the broken one has already ended its workers)."""
        self.pool_.shutdown(wait=True)
        self.pool_ = self._new_pool()

    def _submit(self, fn: Callable[[Any], Any], item: Any) -> Future:
        try:
            return self.pool_.submit(fn, item)
        except BrokenProcessPool:  # a worker died while idle, between two tasks
            self._rebuild()
            return self.pool_.submit(fn, item)

    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """Apply ``fn`` to every item in the pool; yield ``(index, result or exception)`` as tasks finish.

        A task's own exception is yielded, not retried. Tasks lost to a dead
        worker are run again (module docstring); one lost for good yields a
        ``WorkerLostError``. Closing the iterator early cancels the tasks not
        yet started; those running finish in the background.

        :raises RuntimeError: outside a ``with`` block.
        """
        if self.pool_ is None:
            raise RuntimeError("processes executor: map_unordered needs the executor entered (`with executor:`)")
        return self._run(fn, list(items))

    def _run(self, fn: Callable[[Any], Any], items: list[Any]) -> Iterator[tuple[int, Any]]:
        opts = self.opts_
        todo = deque(range(len(items)))  # run beside others
        alone: deque[int] = deque()  # lost too often beside others: run on their own
        lost: Counter[int] = Counter()
        running: dict[Future, int] = {}
        try:
            while todo or alone or running:
                if alone:
                    if not running:
                        i = alone.popleft()
                        running[self._submit(fn, items[i])] = i
                else:
                    while todo and len(running) < opts.workers:
                        i = todo.popleft()
                        running[self._submit(fn, items[i])] = i
                done, _ = wait(running, return_when=FIRST_COMPLETED)
                if any(isinstance(f.exception(), BrokenProcessPool) for f in done):
                    done, _ = wait(running)  # a broken pool fails every task in flight; collect them all
                broken = []
                for fut in done:
                    i = running.pop(fut)
                    exc = fut.exception()
                    if isinstance(exc, BrokenProcessPool):
                        broken.append((i, exc))
                    else:
                        yield i, exc if exc is not None else fut.result()
                if not broken:
                    continue
                self._rebuild()
                retry = []
                for i, exc in sorted(broken, key=lambda b: b[0]):
                    lost[i] += 1
                    if lost[i] <= opts.max_retries:
                        retry.append(i)
                    elif len(broken) > 1:
                        alone.append(i)
                    else:
                        error = WorkerLostError(
                            f"processes executor: task {i} was lost {lost[i]} times because the worker process "
                            f"running it died (gave up after max_retries={opts.max_retries})")
                        error.__cause__ = exc
                        yield i, error
                todo.extendleft(reversed(retry))  # lost tasks go first
        finally:
            for fut in running:
                fut.cancel()


    def submit(self, fn: Callable[[Any], Any], item: Any) -> TaskHandle:
        """Start ``fn(item)`` in the pool; see :meth:`suspid.interfaces.Executor.submit`.

        :raises RuntimeError: outside a ``with`` block.
        """
        if self.pool_ is None:
            raise RuntimeError("processes executor: submit needs the executor entered (`with executor:`)")
        return TaskHandle(fn, item, future=self._submit(fn, item))

    def wait_first(self, handles: Sequence[TaskHandle], timeout: float | None = None
                   ) -> list[tuple[TaskHandle, Any]]:
        """The finished ones of ``handles`` (see :meth:`suspid.interfaces.Executor.wait_first`).

        A task lost to a dead worker is submitted again to a new pool, up to
        ``max_retries`` times, then returned as a ``WorkerLostError`` (no
        search for the culprit among the tasks in flight, unlike ``map_unordered``).
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            ready = [(h, h.outcome) for h in handles if h.done]
            running = {h.future: h for h in handles if not h.done}
            if ready or not running:
                return ready
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            done, _ = wait(running, timeout=left, return_when=FIRST_COMPLETED)
            if not done:
                return []
            if any(isinstance(f.exception(), BrokenProcessPool) for f in done):
                done, _ = wait(running)  # a broken pool fails every task in flight
                self._resubmit_lost([running[f] for f in done if isinstance(f.exception(), BrokenProcessPool)])
            for fut in done:
                h = running[fut]
                if not h.done and h.future is fut:  # neither submitted again nor given up
                    h.done, h.outcome = True, fut.exception() or fut.result()

    def _resubmit_lost(self, lost: list[TaskHandle]) -> None:
        """Tasks whose worker died: into a new pool, or given up after ``max_retries``."""
        self._rebuild()
        for h in lost:
            h.lost += 1
            if h.lost <= self.opts_.max_retries:
                h.future = self.pool_.submit(h.fn, h.item)
            else:
                h.done, h.outcome = True, WorkerLostError(
                    f"processes executor: a task was lost {h.lost} times because the worker process running "
                    f"it died (gave up after max_retries={self.opts_.max_retries})")


def _terminate_workers(pool: ProcessPoolExecutor) -> None:
    """End the pool's worker processes now (SIGTERM), whatever they are running.

    ``ProcessPoolExecutor`` has a public ``terminate_workers`` from Python 3.14
    on; before that the processes are only reachable through ``_processes``.
    """
    terminate = getattr(pool, "terminate_workers", None)
    if terminate is not None:
        terminate()
        return
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        if process.is_alive():
            process.terminate()


@hookimpl
def suspid_register_executors(register):
    register(ProcessExecutor)
