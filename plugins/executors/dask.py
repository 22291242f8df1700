"""The ``dask`` executor: tasks on a dask.distributed cluster.

Select it with ``executor: {plugin: dask, options: {...}}``. The scheduler is,
in this order: the option ``address``, the environment variable
``SUSPID_DASK_SCHEDULER``, the environment variable ``DASK_SCHEDULER_ADDRESS``;
with none of them a :class:`distributed.LocalCluster` of ``n_workers``
processes is started on this machine for the ``with`` block and closed after
it. A cluster given by address is only connected to, never closed. How to
run on a real cluster: ``docs/dask.md``.

Each ``map_unordered`` call pickles ``fn`` once and leaves it with the
scheduler (``client.set_metadata``) for the length of the call; each worker
fetches it there on its first task of the call and keeps it. So a large
callable (one holding the track data, say) crosses the network once per
worker, not once per task, and a worker started after a death fetches it
again. ``fn`` is deliberately not a dask dependency of the tasks (scattered
or computed): dask places a task on a worker holding its dependencies, which
would pile every task on one worker. Then one task per item is submitted with
``client.submit(..., pure=False)`` under a key holding the item's index, and
results come back as they finish (``distributed.as_completed``).

A dead worker: the scheduler reschedules the tasks it was running on other
workers; a task whose workers died more than ``allowed-failures`` times
(dask's ``distributed.scheduler.allowed-failures``, default 3; the option
``allowed_failures`` for a LocalCluster) is given up, and a
:class:`~suspid.plugins.executors._common.WorkerLostError` naming its index is
yielded. A task's own exception is yielded too, after ``retries`` more tries.

``distributed`` is imported only when the executor is entered, so listing
plugins does not pay for importing dask.
"""

from __future__ import annotations

import logging
import os
import threading
import uuid
from collections import OrderedDict
from typing import Any, Callable, ClassVar, Iterator, Sequence

from pydantic import BaseModel, ConfigDict, Field, PositiveFloat

from suspid import hookimpl
from suspid.errors import ConfigError, PluginError
from suspid.interfaces import Executor

from ._common import WorkerLostError, executor_options
from .processes import default_workers

log = logging.getLogger(__name__)

ADDRESS_ENV_VARS = ("SUSPID_DASK_SCHEDULER", "DASK_SCHEDULER_ADDRESS")
"""Environment variables read, in this order, when the option ``address`` is not set."""

INSTALL_HINT = "pip install 'suspid[dask]'"


class DaskOptions(BaseModel):
    """Options of the ``dask`` executor (``executor.options``)."""

    model_config = ConfigDict(extra="forbid")

    address: str | None = Field(
        default=None, min_length=1,
        description="scheduler address (tcp://host:8786); default: $SUSPID_DASK_SCHEDULER, "
                    "$DASK_SCHEDULER_ADDRESS, else a LocalCluster")
    n_workers: int | None = Field(
        default=None, ge=1,
        description="LocalCluster: worker processes (default: CPUs / threads_per_worker); "
                    "with an address: wait until this many workers are connected (default 1)")
    threads_per_worker: int = Field(
        default=1, ge=1, description="LocalCluster only: threads per worker (1: the simulator is CPU-bound)")
    processes: bool = Field(default=True, description="LocalCluster only: workers in processes (false: threads)")
    retries: int = Field(default=0, ge=0,
                         description="tries more for a task that raises (client.submit retries=); "
                                     "worker deaths are allowed_failures' business")
    allowed_failures: int | None = Field(
        default=None, ge=0,
        description="LocalCluster only: worker deaths a task may suffer before it is given up "
                    "(dask's distributed.scheduler.allowed-failures, default 3); "
                    "an existing scheduler has its own setting")
    resources: dict[str, PositiveFloat] = Field(
        default_factory=dict,
        description="abstract resources each task holds, e.g. {vampire: 1} with workers started "
                    "with --resources vampire=1 (licence seats)")
    timeout_s: PositiveFloat = Field(default=60.0, description="wait for the scheduler and the workers, s")


def scheduler_address(options: DaskOptions) -> tuple[str | None, str]:
    """The scheduler to connect to and where that came from.

    :returns: ``(address, source)``: the address, or ``None`` for a new
        LocalCluster, and ``"executor.options.address"``, the environment
        variable's name or ``"LocalCluster"``.
    """
    if options.address:
        return options.address, "executor.options.address"
    for var in ADDRESS_ENV_VARS:
        value = os.environ.get(var, "").strip()
        if value:
            return value, var
    return None, "LocalCluster"


def _import_distributed():
    try:
        import distributed
    except ImportError as exc:
        raise PluginError(f"the dask executor needs dask.distributed, which is not installed "
                          f"({exc}); {INSTALL_HINT}") from None
    return distributed


_FN_CACHE: OrderedDict[str, Callable[[Any], Any]] = OrderedDict()
"""In each worker process: token of a ``map_unordered`` call -> its ``fn``, the latest few calls."""

_FN_CACHE_SIZE = 4
_FN_LOCK = threading.Lock()


def _fn_metadata_key(token: str) -> list[str]:
    return ["suspid", "executor-fn", token]


def _call(token: str, item: Any) -> Any:
    """One task on a worker: ``fn(item)``, with ``fn`` fetched from the scheduler once per worker and call."""
    with _FN_LOCK:  # workers with several threads
        fn = _FN_CACHE.get(token)
        if fn is None:
            import cloudpickle  # a dependency of distributed
            from distributed import get_client

            payload = get_client().get_metadata(_fn_metadata_key(token), None)
            if payload is None:
                raise RuntimeError(f"dask executor: the scheduler no longer holds the task function of call {token}")
            fn = _FN_CACHE[token] = cloudpickle.loads(payload)
            while len(_FN_CACHE) > _FN_CACHE_SIZE:
                _FN_CACHE.popitem(last=False)
    return fn(item)


def _label(fn: Callable[[Any], Any]) -> str:
    """A short name for ``fn`` in task keys (shown on the dashboard)."""
    name = getattr(fn, "__name__", None) or type(fn).__name__
    return "".join(c if c.isalnum() or c in "_-" else "_" for c in name)[:40]


class DaskExecutor(Executor):
    """Tasks on a dask.distributed cluster (a LocalCluster by default); see the module docstring.

    ``fn``, the items and the results must be picklable (cloudpickle), and
    every worker must be able to import what they refer to: suspid, the
    plugins in use and their dependencies, in the driver's versions.
    """

    name: ClassVar[str] = "dask"
    Options: ClassVar[type] = DaskOptions

    opts_: DaskOptions | None = None
    client_: Any = None
    cluster_: Any = None  # only a LocalCluster we started ourselves; closed in __exit__

    def _options(self) -> DaskOptions:
        return self.opts_ if self.opts_ is not None else executor_options(DaskOptions, self.options)

    @property
    def n_workers(self) -> int:
        """Tasks the cluster runs at once: its threads, fewer where ``resources`` are scarcer.

        Inside the ``with`` block this asks the scheduler (workers may come and
        go); outside it, the configured ``n_workers`` (or 1).
        """
        if self.client_ is None:
            return self._options().n_workers or 1
        return max(self._slots(), 1)

    def _slots(self) -> int:
        """Σ over the connected workers of min(threads, ⌊resource held / resource needed⌋)."""
        slots = 0
        for worker in self.client_.scheduler_info(n_workers=-1)["workers"].values():
            n = int(worker.get("nthreads", 1))
            for resource, need in self.opts_.resources.items():
                n = min(n, int(worker.get("resources", {}).get(resource, 0) // need))
            slots += n
        return slots

    @property
    def dashboard_link(self) -> str | None:
        """The dask dashboard's URL inside the ``with`` block (``None`` when not available)."""
        if self.client_ is None:
            return None
        try:
            return self.client_.dashboard_link
        except Exception:  # no dashboard (bokeh missing, or the scheduler has none)
            return None

    def __enter__(self) -> "DaskExecutor":
        if self.client_ is not None:
            raise RuntimeError("dask executor: already entered (one `with` block at a time)")
        opts = self.opts_ = self._options()
        distributed = _import_distributed()
        address, source = scheduler_address(opts)
        try:
            if address is None:
                self._start_local_cluster(distributed, opts)
            else:
                self._connect(distributed, opts, address, source)
        except BaseException:
            self._close()
            raise
        log.info("dask executor: %s, %d task slots, dashboard %s", address or "LocalCluster",
                 self.n_workers, self.dashboard_link)
        return self

    def _start_local_cluster(self, distributed: Any, opts: DaskOptions) -> None:
        n_workers = opts.n_workers or max(1, default_workers() // opts.threads_per_worker)
        scheduler_kwargs = {}
        if opts.allowed_failures is not None:
            scheduler_kwargs["allowed_failures"] = opts.allowed_failures
        worker_resources = {"resources": dict(opts.resources)} if opts.resources else {}
        self.cluster_ = distributed.LocalCluster(
            n_workers=n_workers, threads_per_worker=opts.threads_per_worker, processes=opts.processes,
            dashboard_address=":0",  # a free port: never collides with another run's dashboard
            scheduler_kwargs=scheduler_kwargs, **worker_resources)
        self.client_ = distributed.Client(self.cluster_, timeout=opts.timeout_s)
        self.client_.wait_for_workers(n_workers, timeout=opts.timeout_s)

    def _connect(self, distributed: Any, opts: DaskOptions, address: str, source: str) -> None:
        key = "executor.options.address" if source == "executor.options.address" else None
        if opts.allowed_failures is not None:
            raise ConfigError("allowed_failures applies to a LocalCluster only; for the scheduler at "
                              f"{address} (from {source}) set distributed.scheduler.allowed-failures "
                              "in that scheduler's dask config", key="executor.options.allowed_failures")
        try:
            self.client_ = distributed.Client(address, timeout=opts.timeout_s)
        except (OSError, TimeoutError) as exc:
            raise ConfigError(f"cannot connect to the dask scheduler at {address} (from {source}) "
                              f"within timeout_s={opts.timeout_s:g}: {exc}", key=key) from None
        wanted = opts.n_workers or 1
        try:
            self.client_.wait_for_workers(wanted, timeout=opts.timeout_s)
        except (OSError, TimeoutError):
            have = len(self.client_.scheduler_info(n_workers=-1)["workers"])
            raise ConfigError(f"the dask scheduler at {address} has {have} worker(s) after "
                              f"timeout_s={opts.timeout_s:g}, {wanted} wanted; start workers with "
                              f"`dask worker {address}`", key="executor.options.n_workers") from None
        if opts.resources and self._slots() == 0:  # tasks would wait for ever
            needs = " ".join(f"{r}={v:g}" for r, v in opts.resources.items())
            raise ConfigError(f"no worker of the dask scheduler at {address} holds the resources {needs} "
                              f"a task needs; start workers with `dask worker {address} --resources "
                              f"\"{needs}\"`", key="executor.options.resources")

    def __exit__(self, *exc: Any) -> None:
        self._close()

    def _close(self) -> None:
        client, cluster = self.client_, self.cluster_
        self.client_ = self.cluster_ = None
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()

    def map_unordered(self, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
        """Apply ``fn`` to every item on the cluster; yield ``(index, result or exception)`` as tasks finish.

        A task's own exception is yielded after ``retries`` more tries; a task
        whose workers kept dying yields a ``WorkerLostError``. Closing the
        iterator early cancels the tasks not finished yet.

        :raises RuntimeError: outside a ``with`` block.
        """
        if self.client_ is None:
            raise RuntimeError("dask executor: map_unordered needs the executor entered (`with executor:`)")
        return self._run(self.client_, fn, list(items))

    def _run(self, client: Any, fn: Callable[[Any], Any], items: list[Any]) -> Iterator[tuple[int, Any]]:
        if not items:
            return
        import cloudpickle
        from distributed import as_completed

        opts = self.opts_
        token, label = uuid.uuid4().hex[:12], _label(fn)
        client.set_metadata(_fn_metadata_key(token), cloudpickle.dumps(fn))
        pending = {}
        try:
            for i, item in enumerate(items):
                future = client.submit(_call, token, item, key=f"suspid-{label}-{i}-{token}", pure=False,
                                       retries=opts.retries or None, resources=dict(opts.resources) or None)
                pending[future] = i
            for future, result in as_completed(list(pending), with_results=True, raise_errors=False):
                i = pending.pop(future)
                outcome = _outcome(i, future, result)
                # let the cluster forget the result now: a result still held when its worker dies is recomputed
                future.release()
                del future, result
                yield i, outcome
        finally:
            if pending:
                client.cancel(list(pending))
            client.set_metadata(_fn_metadata_key(token), None)  # the scheduler lets go of fn


def _outcome(i: int, future: Any, result: Any) -> Any:
    """What ``map_unordered`` yields for task ``i``: its result, its exception, or a WorkerLostError.

    With ``raise_errors=False``, ``as_completed`` gives an erred task's
    ``(type, exception, traceback)`` and a cancelled task's CancelledError.
    """
    from distributed.scheduler import KilledWorker

    if future.status == "error":
        _, exc, tb = result
        exc = exc.with_traceback(tb)
        if isinstance(exc, KilledWorker):
            error = WorkerLostError(f"dask executor: task {i} was given up because the workers running it "
                                    f"kept dying ({exc})")
            error.__cause__ = exc
            return error
        return exc
    if future.cancelled():
        error = WorkerLostError(f"dask executor: task {i} was cancelled by the cluster ({result!r}); "
                                f"was the scheduler restarted or the connection lost?")
        error.__cause__ = result if isinstance(result, BaseException) else None
        return error
    return result


@hookimpl
def suspid_register_executors(register):
    register(DaskExecutor)
